#!/usr/bin/env bash
# #18's sweep on the GPU machine: the octree and the tree (bvh) at 10^5, 10^6 and
# 10^7 particles on the large walls (the counter mesh, its 4 x 3 tiling of
# 1,005,000 triangles, the icospheres of 1,310,720 and 81,920 triangles), half
# within 1.5 r_max of the surface and then all uniform, with cuBQL on the same
# particles where its peer is built (bench/cubql_peer.cu; bench/cubql_compare.sh
# says how). Radii 0.5..1, seed 1, exact, the whole frame, medians of 10.
# Usage (repo root): bash bench/octree_sweep.sh BUILD_DIR [CUBQL_PEER] [NEAR...]
#   NEAR: the fractions near the surface (default 0.5 0).
set -uo pipefail
build=${1:?BUILD_DIR}; peer=${2:-}; shift $(( $# > 1 ? 2 : 1 ))
nears=("$@"); [ ${#nears[@]} -eq 0 ] && nears=(0.5 0)
app="$build/app/collidoscope"
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
counter=tests/data/meshes/counter_unitsmm_trimesh_83750tri.stl
/usr/bin/python3 bench/tile_stl.py "$counter" "$work/counter_x12.stl" 4 3 >/dev/null
walls=("$counter" "$work/counter_x12.stl")
for spec in "sphere:r=500,subdivisions=8" "sphere:r=50,subdivisions=6"; do
  dir="$work/$(echo "$spec" | tr ':=,' '___')"
  "$app" detect --wall "$spec" --particles 1 --snapshot "$dir" >/dev/null
  walls+=("$dir/wall.stl")
done
echo "# octree_sweep: $(nvidia-smi --query-gpu=name --format=csv,noheader); $(date -u +%F)"
for near in "${nears[@]}"; do
  for w in "${walls[@]}"; do
    echo "## $w near $near"
    "$app" bench detect --backend cuda --wall "$w" --min 1e5 --max 1e7 --methods bvh,octree \
      --traversals particle --precisions exact --near-surface "$near" --repeats 10 --check-max 0 \
      | grep -E "^\| (method|bvh|octree) "
    if [ -n "$peer" ]; then
      for n in 100000 1000000 10000000; do "$peer" "$w" $n "$near" 0.5 1 1 10; done
    fi
  done
done
