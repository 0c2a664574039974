#!/usr/bin/env bash
# The dynamics' time a step with each wall method on three small scenes: a fill
# of wall1 (no particle contacts: every particle looks the wall up each step), a
# pour onto a plate with holes (its faces cut into long slivers) and a fill of a
# cylinder with particle contacts (the wall's candidates then come from the
# neighbour lists). Prints a Markdown table for docs/benchmarks.md: ms per step
# (the job's simulate time over its steps), and the simulate seconds. Bounded:
# each run under LIMIT_S (default 300).
#
#   bash bench/dynamics_methods.sh [BUILD_DIR] [BACKEND] [THREADS] [METHODS]
set -euo pipefail
build=${1:-build}
backend=${2:-cpu}
threads=${3:-2}
methods=${4:-bin,bvh,gravity,circumcircle,midpoint4}
limit=${LIMIT_S:-300}
bin="$build/app/collidoscope"
[ -x "$bin" ] || { echo "dynamics_methods: no $bin (build first)"; exit 1; }
here=$(cd "$(dirname "$0")/.." && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

cat > "$work/wall1_fill.json" <<'EOF'
{"wall": "wall1", "particles": {"count": 1737, "radius": [1.37, 2.75]},
 "placement": {"kind": "fill"}, "duration": 0.03, "fps": 100}
EOF
cat > "$work/plate_pour.json" <<EOF
{"wall": {"file": "$here/tests/data/meshes/plate_holes_trimesh_binary_solid_header.stl"},
 "particles": {"count": 2000, "radius": 1.5},
 "placement": {"kind": "pour", "rate": 1000, "inlet": [101.6, 152.4, 17.2]},
 "material": {"restitution": 0.5}, "duration": 2, "fps": 15}
EOF
cat > "$work/cylinder_fill_pairs.json" <<'EOF'
{"wall": "cylinder:r=10,h=30,segments=24", "particles": {"count": 700, "radius": 0.42},
 "placement": {"kind": "fill"}, "particle_contacts": true,
 "material": {"restitution": 0.3, "friction": 0.3}, "duration": 0.1, "fps": 50}
EOF

echo "| scene | method | ms per step | simulate s | steps |"
echo "|---|---|---:|---:|---:|"
for scene in wall1_fill plate_pour cylinder_fill_pairs; do
  for m in ${methods//,/ }; do
    python3 -c "import json,sys; s=json.load(open(sys.argv[1])); s['method']=sys.argv[2]; json.dump(s, open(sys.argv[3],'w'))" \
      "$work/$scene.json" "$m" "$work/$scene.$m.json"
    if ! timeout "$limit" "$bin" run "$work/$scene.$m.json" --out "$work/out" --force --quiet \
        --backend "$backend" --threads "$threads" > "$work/log" 2>&1; then
      echo "| $scene | $m | (failed or over ${limit} s: $(tail -1 "$work/log")) | | |"
      continue
    fi
    python3 - "$work/out/result.json" "$scene" "$m" <<'EOF'
import json, sys
c = json.load(open(sys.argv[1]))["cost"]
print(f"| {sys.argv[2]} | {sys.argv[3]} | {1e3 * c['simulate_s'] / c['steps']:.4f} | {c['simulate_s']:.3f} | {c['steps']} |")
EOF
  done
done
