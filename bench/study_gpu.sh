#!/usr/bin/env bash
# The full study and the GPU test suites on the GPU machine, as docs/study.md
# reports them. Usage (repo root, with the carried prefix of gtest/nlohmann
# that bench/make_gpu_carry.sh unpacks; where gpu-carry/bins.tgz holds binaries
# built here by bench/make_gpu_bins.sh, those run and nothing is built there):
#   bash bench/study_gpu.sh OUT_DIR [tests|study-walls|study-meshes|study-dynamics|bench|bench-large]...
# The study's parts land in OUT_DIR/{walls,meshes,dynamics}; one table of them:
#   /usr/bin/python3 bench/study_merge.py bench/data/study_gpu OUT_DIR/{walls,meshes,dynamics}/study.json
set -uo pipefail
out=${1:?OUT_DIR}; shift
targets=(collidoscope)
for step in "$@"; do [ "$step" = tests ] && targets+=(detect_test bvh_test dynamics_test contact_models_test); done
if [ -f gpu-carry/bins.tgz ]; then
  # Binaries built here beforehand (bench/make_gpu_bins.sh): no build on the machine.
  tar xzf gpu-carry/bins.tgz
  echo "binaries built from $(cat build-dev/source_rev)"
  src=$(cat build-dev/source_dir)
  if [ ! -e "$src" ]; then mkdir -p "$(dirname "$src")" && ln -s "$PWD" "$src"; fi
else
  cmake -S . -B build-dev -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH="$PWD/gpu-carry/prefix" \
    -DCOLLIDO_CUDA=ON -DCMAKE_CUDA_ARCHITECTURES=90 -DCOLLIDO_WITH_RENDER=OFF \
    -DCOLLIDO_WITH_MESH_IMPORT=OFF -DCOLLIDO_WITH_SERVICE=OFF >"$out/cmake.log" 2>&1 || { tail -20 "$out/cmake.log"; exit 1; }
  cmake --build build-dev -j16 --target "${targets[@]}" >"$out/build.log" 2>&1 || { grep -m20 error "$out/build.log"; exit 1; }
fi
for step in "$@"; do
  case $step in
    tests)
      (build-dev/tests/sim/detect_test; build-dev/tests/sim/bvh_test; build-dev/tests/sim/dynamics_test; build-dev/tests/sim/contact_models_test) >"$out/gpu_tests.log" 2>&1
      grep -E "PASSED|FAILED|^\[  FAILED" "$out/gpu_tests.log" ;;
    study-walls)  # the paper's walls up to 10^6 particles
      build-dev/app/collidoscope study --backend cuda --only detect --scenes wall1,wall2 --out "$out/walls" \
        >"$out/study_walls.log" 2>&1
      tail -4 "$out/study_walls.log" ;;
    study-meshes)  # the third-party meshes up to 10^5
      build-dev/app/collidoscope study --backend cuda --only detect --max-particles 100000 \
        --scenes 3dsmax_export_assimp,plate_holes_trimesh_binary_solid_header,sphere_with_hole_assimp,teapot_trimesh,triangle_with_two_solids_assimp,wuson_assimp \
        --out "$out/meshes" >"$out/study_meshes.log" 2>&1
      tail -4 "$out/study_meshes.log" ;;
    study-dynamics)
      build-dev/app/collidoscope study --backend cpu --only dynamics --out "$out/dynamics" >"$out/study_dynamics.log" 2>&1
      tail -4 "$out/study_dynamics.log" ;;
    bench-large)  # #18: large meshes, 10^5..10^7 particles, half near the surface and all uniform
      python3 bench/tile_stl.py tests/data/meshes/counter_unitsmm_trimesh_83750tri.stl /tmp/counter_x12.stl 4 3
      for near in 0.5 0; do
        for w in tests/data/meshes/counter_unitsmm_trimesh_83750tri.stl /tmp/counter_x12.stl \
                 "sphere:r=500,subdivisions=8" wall1 "sphere:r=50,subdivisions=6" tests/data/meshes/teapot_trimesh.stl; do
          m=bin,bvh; case $w in *x12*|*subdivisions=8*) ;; *) m=bin,circumcircle,bvh;; esac
          build-dev/app/collidoscope bench detect --backend cuda --wall "$w" --min 100000 --max 10000000 \
            --methods $m --traversals particle --precisions exact --near-surface $near --repeats 10 --check-max 0
        done
      done >"$out/bench_large.txt" 2>&1
      grep -E "^# bench|^\| (bin|circumcircle|bvh) \|" "$out/bench_large.txt" ;;
    bench)
      for w in wall1 tests/data/meshes/teapot_trimesh.stl; do
        build-dev/app/collidoscope bench detect --backend cuda --wall "$w" --min 1000000 --max 1000000 \
          --methods bin,circumcircle --near-surface 0.5 --repeats 20 --check-max 1000000
      done >"$out/bench_detect_filter.txt" 2>&1
      grep -E "^\| (bin|circumcircle)" "$out/bench_detect_filter.txt" ;;
  esac
done
