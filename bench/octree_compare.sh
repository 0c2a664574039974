#!/usr/bin/env bash
# The octree method against the tree (bvh) on #18's meshes, on the GPU machine:
# `collidoscope bench detect` (exact, the whole frame) on the same 10^6
# particles, radii 0.5..1, half within 1.5 of the surface (NEAR to change it).
# The walls: the counter mesh, its 4 x 3 tiling (1,005,000 triangles), the
# icospheres of 1,310,720 and 81,920 triangles, the teapot and wall1.
# Usage (repo root, on the GPU machine): bash bench/octree_compare.sh BUILD_DIR [OUT_FILE]
set -uo pipefail
build=${1:?BUILD_DIR}; out=${2:-/dev/stdout}
app="$build/app/collidoscope"
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
counter=tests/data/meshes/counter_unitsmm_trimesh_83750tri.stl
/usr/bin/python3 bench/tile_stl.py "$counter" "$work/counter_x12.stl" 4 3
walls=("$counter" "$work/counter_x12.stl")
for spec in "sphere:r=500,subdivisions=8" "sphere:r=50,subdivisions=6" wall1; do
  dir="$work/$(echo "$spec" | tr ':=,' '___')"
  "$app" detect --wall "$spec" --particles 1 --snapshot "$dir" >/dev/null
  walls+=("$dir/wall.stl")
done
walls+=(tests/data/meshes/teapot_trimesh.stl)
echo "# octree_compare: 10^6 particles, radii 0.5..1, seed 1, near-surface ${NEAR:-0.5}; $(nvidia-smi --query-gpu=name --format=csv,noheader); $(date -u +%F)" >>"$out"
for w in "${walls[@]}"; do
  echo "## $w" >>"$out"
  "$app" bench detect --backend cuda --wall "$w" --min 1e6 --max 1e6 --methods bvh,octree \
    --traversals particle --precisions exact --near-surface "${NEAR:-0.5}" --repeats 10 --check-max 0 \
    | grep -E "^\| (method|bvh|octree) " >>"$out"
done
