#!/usr/bin/env bash
# The bvh walk of two builds side by side on the GPU machine, by where the
# particles lie (#18): 10^6 particles all uniform in the wall's box, half within
# 1.5 r_max of its surface, and all near it, on the counter mesh, its twelvefold
# tiling, two icospheres, the teapot and wall1; old and new alternate per case.
# Needs gpu-carry/bins.tgz packed with an old build (bash bench/make_gpu_bins.sh
# REV), carried in `run`; also runs the GPU test suites of the new build.
#   bash bench/bvh_walk_ab.sh OUT_DIR
set -uo pipefail
out=${1:?OUT_DIR}
mkdir -p "$out"
bash bench/study_gpu.sh "$out" tests
[ -x build-old/app/collidoscope ] || { echo "no build-old (pack bins with a REV)"; exit 1; }
python3 bench/tile_stl.py tests/data/meshes/counter_unitsmm_trimesh_83750tri.stl /tmp/counter_x12.stl 4 3
walls=(tests/data/meshes/counter_unitsmm_trimesh_83750tri.stl /tmp/counter_x12.stl
       "sphere:r=500,subdivisions=8" "sphere:r=50,subdivisions=6"
       tests/data/meshes/teapot_trimesh.stl wall1)
for near in 0 0.5 1; do
  for w in "${walls[@]}"; do
    for b in build-old build-dev; do
      echo "## $b near=$near wall=$w"
      $b/app/collidoscope bench detect --backend cuda --wall "$w" --min 1000000 --max 1000000 \
        --methods bvh --traversals particle --precisions exact --near-surface $near --repeats 10 \
        --check-max 0
    done
  done
done >"$out/walk_ab.txt" 2>&1
# The new build's contact sets against the reference at 10^5, uniform and half near.
for near in 0 0.5; do
  build-dev/app/collidoscope bench detect --backend cuda \
    --wall tests/data/meshes/counter_unitsmm_trimesh_83750tri.stl --min 100000 --max 100000 \
    --methods bvh --traversals particle --precisions exact --near-surface $near --repeats 3 \
    --check-max 100000
done >"$out/walk_checked.txt" 2>&1
grep -E "^## |^\| bvh" "$out/walk_ab.txt" | head -80
