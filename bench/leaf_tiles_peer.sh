#!/bin/bash
# The octree method's prototype (bench/leaf_tiles_peer.cu) on #18's walls, beside the
# engine's bvh, on the GPU machine with the binaries of bench/make_gpu_bins.sh carried
# in gpu-carry. Each setting runs as `tiles` and as WALK=1.
# Usage (repo root, on the GPU machine):
#   WALLS="counter x12 ico50 ico500 teapot wall1" ARGS="2 2 16;3 2 16" [NEARS="0.5 0"]
#     [REF=1] [REFM=bvh] bash bench/leaf_tiles_peer.sh
# The output of 2026-11-30 (stop 64) is bench/data/leaf_tiles_peer_h200.txt.
set -u
nvcc -O3 -std=c++17 -arch=sm_90 -I. -Xcompiler -ffp-contract=off bench/leaf_tiles_peer.cu sim/accuracy.cpp sim/stl_io.cpp sim/mesh.cpp -o /tmp/leaf_tiles_peer 2>&1 | grep -E "error" | head
tar xzf gpu-carry/bins.tgz
app=build-dev/app/collidoscope
work=/tmp/w; mkdir -p $work
/usr/bin/python3 bench/tile_stl.py tests/data/meshes/counter_unitsmm_trimesh_83750tri.stl $work/counter_x12.stl 4 3
for spec in "sphere:r=500,subdivisions=8" "sphere:r=50,subdivisions=6" wall1; do
  dir="$work/$(echo "$spec" | tr ':=,' '___')"
  $app detect --wall "$spec" --particles 1 --snapshot "$dir" >/dev/null
done
for w in $WALLS; do
  case $w in counter) f=tests/data/meshes/counter_unitsmm_trimesh_83750tri.stl;; x12) f=$work/counter_x12.stl;;
    ico500) f=$work/sphere_r_500_subdivisions_8/wall.stl;; ico50) f=$work/sphere_r_50_subdivisions_6/wall.stl;;
    wall1) f=$work/wall1/wall.stl;; teapot) f=tests/data/meshes/teapot_trimesh.stl;; esac
  for near in ${NEARS:-0.5 0}; do
    IFS=';' read -ra AS <<< "${ARGS:-2 2 16}"
    for a in "${AS[@]}"; do
      echo "== $w near $near args $a"
      timeout 150 /tmp/leaf_tiles_peer $f 1000000 $near 0.5 1 1 $a 10 ${SAMPLE:-5000} | grep -v "^wall "
      WALK=1 timeout 150 /tmp/leaf_tiles_peer $f 1000000 $near 0.5 1 1 $a 10 ${SAMPLE:-5000} | grep -v "^wall \|^extra"
    done
    if [ "${REF:-1}" = 1 ]; then
      timeout 200 $app bench detect --backend cuda --wall $f --min 1e6 --max 1e6 --methods ${REFM:-bvh} --traversals particle --precisions exact --near-surface $near --repeats 10 --check-max 0 2>&1 | grep -E "^\| (bin|bvh) /"
    fi
  done
done
