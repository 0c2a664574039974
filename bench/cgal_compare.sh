#!/usr/bin/env bash
# Large meshes on the CPU, side by side: `collidoscope bench detect` (bin and
# bvh, exact, all cores) and CGAL's AABB tree on one thread (bench/cgal_peer,
# Debian's libcgal-dev, installed here when missing), on the same particles:
# half within 1.5 r_max of the surface, half uniform in the box.
# Usage: bash bench/cgal_compare.sh BUILD_DIR [PARTICLES] [WALL...]   (repo root)
# Default walls: the counter mesh and its twelvefold tiling (bench/tile_stl.py).
set -euo pipefail
build=${1:?BUILD_DIR}; n=${2:-1000000}; shift $(( $# > 1 ? 2 : 1 ))
walls=("$@")
counter=tests/data/meshes/counter_unitsmm_trimesh_83750tri.stl
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
if [ ${#walls[@]} -eq 0 ]; then  # the counter, and twelve of it (1,005,000 triangles)
  /usr/bin/python3 bench/tile_stl.py "$counter" "$work/counter_x12.stl" 4 3
  walls=("$counter" "$work/counter_x12.stl")
fi
if ! dpkg -s libcgal-dev >/dev/null 2>&1; then
  if [ "$(id -u)" = 0 ]; then DEBIAN_FRONTEND=noninteractive apt-get install -y libcgal-dev >/dev/null
  else echo "libcgal-dev is not installed (sudo apt-get install libcgal-dev)"; exit 77; fi
  cmake "$build" >/dev/null  # finds CGAL now
fi
cmake --build "$build" -j 2 --target collidoscope cgal_peer >/dev/null
echo "# cgal_compare: $n particles, radii 0.5..1, half within 1.5 of the surface, seed 1, $(nproc) cores; $(date -u +%F)"
for w in "${walls[@]}"; do
  file=$w
  if [ ! -f "$w" ]; then  # a shape spec: written out once so both read the same triangles
    "$build/app/collidoscope" detect --wall "$w" --particles 1 --snapshot "$work/snap" >/dev/null
    file="$work/snap/wall.stl"
  fi
  echo "## $w"
  "$build/app/collidoscope" bench detect --wall "$file" --methods bin,bvh --traversals particle \
    --precisions exact --min "$n" --max "$n" --near-surface 0.5 --repeats 3 --check-max 0 \
    | grep -E "^\| (method|bin|bvh) |^# bench"
  "$build/bench/cgal_peer" "$file" "$n" 0.5 0.5 1 1
done
