#!/usr/bin/env bash
# The job cost model against scenes no sweep drew (bench/unseen/*.json): each scene
# is priced with `collidoscope predict --json`, then run with the same flags, and
# the measured total time and peak host memory are set against the prediction:
# inside the 10-90 % range or not, and the median's ratio to the measure (#12 asks
# for both: in range, and within a factor 1.33). Scenes named *_video also render
# (MP4, 320x180) unless VIDEO=0 (a build without the renderer). Prints a Markdown
# table for docs/gvm.md and a line per round: how many scenes passed both.
# ROUNDS=N (default 1) runs every scene N times, a round of all scenes after
# another, so that the rounds see the same hour of a machine whose pace moves.
# Bounded: every run has a time limit (LIMIT_S, default 600). MODEL=FILE prices with
# that job cost model instead of the committed one for the backend.
#
#   bash bench/cost_unseen.sh [BUILD_DIR] [BACKEND] [THREADS]
set -euo pipefail
build=${1:-build}
backend=${2:-cpu}
threads=${3:-2}
limit=${LIMIT_S:-600}
video=${VIDEO:-1}
rounds=${ROUNDS:-1}
bin="$build/app/collidoscope"
[ -x "$bin" ] || { echo "cost_unseen: no $bin (build first)"; exit 1; }
here=$(cd "$(dirname "$0")" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

model=()
[ -n "${MODEL:-}" ] && model=(--model "$MODEL")
flags_of() {  # the scene's flags for predict and run
  local name=$1
  flags=(--backend "$backend" --threads "$threads")
  if [ "$video" = 1 ]; then
    case "$name" in *_video) flags+=(--video --formats mp4 --width 320 --height 180) ;; esac
  fi
}
# Priced once: the model's answer does not change between rounds.
for scene in "$here"/unseen/*.json; do
  name=$(basename "$scene" .json)
  flags_of "$name"
  "$bin" predict "$scene" --json "${flags[@]}" "${model[@]}" > "$work/$name.predicted.json"
done
for round in $(seq 1 "$rounds"); do
  for scene in "$here"/unseen/*.json; do
    name=$(basename "$scene" .json)
    flags_of "$name"
    out="$work/$name.$round"
    if timeout "$limit" "$bin" run "$scene" --out "$out" --force --quiet "${flags[@]}" \
        > "$out.log" 2>&1; then
      cp "$out/result.json" "$out.result.json"
    else
      echo "the run failed or passed ${limit} s: $(tail -1 "$out.log")" > "$out.failed"
    fi
    rm -rf "$out"
  done
done
python3 - "$work" "$rounds" <<'EOF'
import glob, json, os, sys
work, rounds = sys.argv[1], int(sys.argv[2])
mib = 1 << 20
print("| scene | outside training | total p10 / p50 / p90 (s) | measured (s) | in range | p50 / measured | host p50 / p90 (MiB) | measured (MiB) |")
print("|---|---|---|---|---|---|---|---|")
passed = [0] * rounds
scenes = sorted(glob.glob(os.path.join(work, "*.predicted.json")))
for path in scenes:
    name = os.path.basename(path)[: -len(".predicted.json")]
    p = json.load(open(path))
    t, h = p["total_s"], p["peak_host_bytes"]
    outside = "; ".join(r.split(" is ")[0] for r in p.get("outside_reasons", [])) or "no"
    measured, inside, ratio, host = [], [], [], []
    for k in range(1, rounds + 1):
        base = os.path.join(work, f"{name}.{k}")
        if not os.path.exists(base + ".result.json"):
            measured.append("failed"), inside.append("no"), ratio.append("-"), host.append("-")
            continue
        cost = json.load(open(base + ".result.json"))["cost"]
        m = cost["total_s"]
        ok = t["p10"] <= m <= t["p90"]
        r = t["p50"] / m
        passed[k - 1] += ok and 1 / 1.33 <= r <= 1.33
        measured.append(f"{m:.2f}"), inside.append("yes" if ok else "no")
        ratio.append(f"{r:.2f}"), host.append(f"{cost['peak_host_bytes'] / mib:.0f}")
    print(f"| {name} | {outside} | {t['p10']:.2f} / {t['p50']:.2f} / {t['p90']:.2f} | "
          f"{', '.join(measured)} | {', '.join(inside)} | {', '.join(ratio)} | "
          f"{h['p50'] / mib:.0f} / {h['p90'] / mib:.0f} | {', '.join(host)} |")
print()
for k, n in enumerate(passed, 1):
    print(f"round {k}: {n} of {len(scenes)} in range and within 1.33x")
for f in sorted(glob.glob(os.path.join(work, "*.failed"))):
    print(os.path.basename(f)[: -len(".failed")] + ": " + open(f).read().strip())
EOF
