#!/usr/bin/env bash
# Builds the engine's CUDA binaries here for the H200 (sm_90) and packs them
# for the GPU machine, so that a device call spends its minutes running rather
# than compiling (a build there took about 4.5 of each call's minutes). The
# binaries link only CUDA's static runtime and the C and C++ libraries, and the
# machine's newer system runs them (seen 2026-11-29).
# Usage (repo root): bash bench/make_gpu_bins.sh [REV]
#   REV (optional): also pack that commit's collidoscope as build-old/, for
#   A/B runs against it (built in a temporary worktree).
# Then carry gpu-carry in `run`; bench/study_gpu.sh unpacks gpu-carry/bins.tgz
# into build-dev/ and skips its build. On this 2-core VM: 3.5 minutes from
# scratch, about 4.5 with REV (2026-11-29).
set -euo pipefail
flags=(-DCMAKE_BUILD_TYPE=Release -DCOLLIDO_CUDA=ON -DCMAKE_CUDA_ARCHITECTURES=90
       -DCOLLIDO_WITH_RENDER=OFF -DCOLLIDO_WITH_MESH_IMPORT=OFF -DCOLLIDO_WITH_SERVICE=OFF)
tests=(detect_test bvh_test dynamics_test contact_models_test)
cmake -S . -B build-sm90 "${flags[@]}" >/dev/null
cmake --build build-sm90 -j2 --target collidoscope "${tests[@]}" >/dev/null
stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
mkdir -p "$stage/build-dev/app" "$stage/build-dev/tests/sim"
cp build-sm90/app/collidoscope "$stage/build-dev/app/"
for t in "${tests[@]}"; do cp "build-sm90/tests/sim/$t" "$stage/build-dev/tests/sim/"; done
if [ -n "${1:-}" ]; then
  wt="$stage/old-src"
  git worktree add -q --detach "$wt" "$1"
  cmake -S "$wt" -B "$stage/old-build" "${flags[@]}" >/dev/null
  cmake --build "$stage/old-build" -j2 --target collidoscope >/dev/null
  mkdir -p "$stage/build-old/app" && cp "$stage/old-build/app/collidoscope" "$stage/build-old/app/"
  git worktree remove --force "$wt"
fi
strip "$stage"/build-*/app/collidoscope "$stage"/build-dev/tests/sim/*
# The tests read their data where this checkout keeps it (COLLIDO_TEST_DATA):
# study_gpu.sh links that path to the checkout there.
echo "$PWD" >"$stage/build-dev/source_dir"
# Which source: study_gpu.sh prints it, so stale binaries show.
echo "$(git rev-parse --short HEAD)$(git diff --quiet HEAD || echo " + uncommitted changes $(git diff HEAD | sha1sum | cut -c1-8)")" \
  >"$stage/build-dev/source_rev"
mkdir -p gpu-carry
tar czf gpu-carry/bins.tgz -C "$stage" $(cd "$stage" && ls -d build-*)
du -h gpu-carry/bins.tgz
