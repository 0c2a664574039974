#!/usr/bin/env bash
# `make run` today: one detection frame on the paper's wall1 (cylinder r=50,
# h=100, 40 segments, 156 triangles) with 200,000 particles, checked against the
# exact reference, written to results/demo/ with a picture of the contacts.
set -euo pipefail
build=${1:-build}
app="$build/app/collidoscope"
out=results/demo
mkdir -p "$out"

echo "== detection: wall1, 200000 particles (radius 0.5..1), bin method"
"$app" detect --wall wall1 --particles 200000 --radius-range 0.5:1 --seed 7 --method bin \
  --out "$out/contacts.csv" --snapshot "$out/run" --json > "$out/summary.json"
"$app" detect --wall wall1 --particles 200000 --radius-range 0.5:1 --seed 7 --method bin

echo "== the same frame by the exact double-precision reference"
"$app" detect --wall wall1 --particles 200000 --radius-range 0.5:1 --seed 7 --method reference \
  --out "$out/contacts_reference.csv" > /dev/null
if cmp -s <(cut -d, -f1,2 "$out/contacts.csv") <(cut -d, -f1,2 "$out/contacts_reference.csv"); then
  echo "bin and reference report the same $(($(wc -l < "$out/contacts.csv") - 1)) contacts"
else
  echo "bin and reference differ (see $out/contacts*.csv)" >&2
  exit 1
fi

if "$app" --help | grep -q "^  render"; then
  echo "== picture: particles touching the wall in orange"
  "$app" render "$out/run" --out "$out/render" --color contact --camera iso --video none --png-every 1
fi
echo "results in $out/: summary.json, contacts.csv, run/ (wall + snapshot), render/ (poster and frame PNG)"
