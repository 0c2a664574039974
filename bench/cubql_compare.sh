#!/usr/bin/env bash
# Large meshes on the GPU, side by side: `collidoscope bench detect` (bin and
# bvh, exact, the whole frame) and cuBQL (bench/cubql_peer.cu: the library's
# GPU builder, fixed-radius traversal and float point-triangle distance; the
# query kernel alone, its particles sorted on the host) on the same 10^6
# particles, radii 0.5..1, half within 1.5 of the surface and then all
# uniform. cuBQL is not part of this repository: CUBQL_DIR is a copy of
# github.com/ingowald/cuBQL holding cuBQL/bvh.h.
# Usage: bash bench/cubql_compare.sh BUILD_DIR CUBQL_DIR [PARTICLES]   (repo root, on the GPU machine)
set -euo pipefail
build=${1:?BUILD_DIR}; cubql=${2:?CUBQL_DIR}; n=${3:-1000000}
app="$build/app/collidoscope"
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
nvcc -O3 -DNDEBUG -std=c++17 -arch=sm_90 --extended-lambda --expt-relaxed-constexpr \
  -Xcompiler -ffp-contract=off -I. -I"$cubql" bench/cubql_peer.cu sim/accuracy.cpp sim/stl_io.cpp \
  sim/mesh.cpp -o "$work/cubql_peer"
/usr/bin/python3 bench/tile_stl.py tests/data/meshes/counter_unitsmm_trimesh_83750tri.stl "$work/counter_x12.stl" 4 3
walls=(tests/data/meshes/counter_unitsmm_trimesh_83750tri.stl "$work/counter_x12.stl")
for spec in "sphere:r=500,subdivisions=8" "sphere:r=50,subdivisions=6" wall1; do  # written out once: both read the same triangles
  dir="$work/$(echo "$spec" | tr ':=,' '___')"
  "$app" detect --wall "$spec" --particles 1 --snapshot "$dir" >/dev/null
  walls+=("$dir/wall.stl")
done
walls+=(tests/data/meshes/teapot_trimesh.stl)
echo "# cubql_compare: $n particles, radii 0.5..1, seed 1; $(nvidia-smi --query-gpu=name --format=csv,noheader); $(date -u +%F)"
for w in "${walls[@]}"; do
  for near in 0.5 0; do
    echo "## $w, near-surface $near"
    "$app" bench detect --backend cuda --wall "$w" --min "$n" --max "$n" --methods bin,bvh \
      --traversals particle --precisions exact --near-surface $near --repeats 10 --check-max 0 \
      | grep -E "^\| (method|bin|bvh) |^# bench"
    "$work/cubql_peer" "$w" "$n" $near 0.5 1 1 10
  done
done
