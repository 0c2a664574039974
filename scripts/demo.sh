#!/usr/bin/env bash
# `make run` until the service exists: the paper's wall1 (cylinder r=50, h=100,
# 40 segments, 156 triangles) twice. First one detection frame of 200,000
# particles checked against the exact reference, then a simulation: 2,000
# particles poured into wall1 (scenes/wall1_pour.json), rendered to a video.
# Everything lands in results/demo/.
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
echo "== simulation: 2000 particles poured into wall1 (scenes/wall1_pour.json)"
if "$app" --help | grep -q "^  render"; then video=--video; else video=; fi
"$app" run scenes/wall1_pour.json --out "$out/pour" --force $video --width 1280 --height 720

echo "results in $out/:"
echo "  detection: summary.json, contacts.csv, run/ (wall + snapshot), render/ (poster, frame PNG)"
echo "  simulation: pour/stats.csv (per frame), pour/result.json (files, cost), pour/frames/ (snapshots)${video:+, pour/render/ (video.mp4, video.webm, loop.gif, poster.png)}"
