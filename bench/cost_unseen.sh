#!/usr/bin/env bash
# The job cost model against scenes no sweep drew (bench/unseen/*.json): each scene
# is priced with `collidoscope predict --json`, then run with the same flags, and
# the measured total time and peak host memory are set against the prediction:
# inside the 10-90 % range or not, and the median's ratio to the measure.
# Scenes named *_video also render (MP4, 320x180) unless VIDEO=0 (a build without
# the renderer). Prints a Markdown table for docs/gvm.md. Bounded: every scene runs
# under a time limit (LIMIT_S, default 600). MODEL=FILE prices with that job cost
# model instead of the committed one for the backend.
#
#   bash bench/cost_unseen.sh [BUILD_DIR] [BACKEND] [THREADS]
set -euo pipefail
build=${1:-build}
backend=${2:-cpu}
threads=${3:-2}
limit=${LIMIT_S:-600}
video=${VIDEO:-1}
bin="$build/app/collidoscope"
[ -x "$bin" ] || { echo "cost_unseen: no $bin (build first)"; exit 1; }
here=$(cd "$(dirname "$0")" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

echo "| scene | outside training | total p10 / p50 / p90 (s) | measured (s) | in range | p50 / measured | host p50 / p90 (MiB) | measured (MiB) |"
echo "|---|---|---|---|---|---|---|---|"
for scene in "$here"/unseen/*.json; do
  name=$(basename "$scene" .json)
  flags=(--backend "$backend" --threads "$threads")
  if [ "$video" = 1 ]; then
    case "$name" in *_video) flags+=(--video --formats mp4 --width 320 --height 180) ;; esac
  fi
  model=()
  [ -n "${MODEL:-}" ] && model=(--model "$MODEL")
  "$bin" predict "$scene" --json "${flags[@]}" "${model[@]}" > "$work/$name.predicted.json"
  if ! timeout "$limit" "$bin" run "$scene" --out "$work/$name" --force --quiet "${flags[@]}" \
      > "$work/$name.log" 2>&1; then
    echo "| $name | (the run failed or passed ${limit} s: $(tail -1 "$work/$name.log")) |"
    continue
  fi
  python3 - "$work/$name.predicted.json" "$work/$name/result.json" "$name" <<'EOF'
import json, sys
p = json.load(open(sys.argv[1]))
cost = json.load(open(sys.argv[2]))["cost"]
t, h = p["total_s"], p["peak_host_bytes"]
measured, host = cost["total_s"], cost["peak_host_bytes"]
mib = 1 << 20
inside = "yes" if t["p10"] <= measured <= t["p90"] else "no"
outside = "; ".join(r.split(" is ")[0] for r in p.get("outside_reasons", [])) or "no"
print(f"| {sys.argv[3]} | {outside} | {t['p10']:.2f} / {t['p50']:.2f} / {t['p90']:.2f} | "
      f"{measured:.2f} | {inside} | {t['p50'] / measured:.2f} | "
      f"{h['p50'] / mib:.0f} / {h['p90'] / mib:.0f} | {host / mib:.0f} |")
EOF
done
