#!/usr/bin/env bash
# The GPU machine has CUDA, CMake and a compiler but no package registry: the
# headers and static libraries the engine's tests and the CLI need beyond
# that (GoogleTest, nlohmann-json) are unpacked here from Debian's packages
# into gpu-carry/prefix, which the device runs carry (bench/study_gpu.sh).
# Usage: bash bench/make_gpu_carry.sh   (repo root)
set -euo pipefail
rm -rf gpu-carry && mkdir -p gpu-carry/debs gpu-carry/x
(cd gpu-carry/debs && apt-get download libgtest-dev nlohmann-json3-dev >/dev/null)
for d in gpu-carry/debs/*.deb; do dpkg -x "$d" gpu-carry/x; done
mv gpu-carry/x/usr gpu-carry/prefix && rm -rf gpu-carry/x gpu-carry/debs
# Debian's libgtest-dev keeps its CMake files under lib/x86_64-linux-gnu/cmake: found through the prefix.
du -sh gpu-carry
