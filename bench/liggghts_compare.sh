#!/usr/bin/env bash
# Side by side on one core: `collidoscope bench run`'s block scene (particles of
# radius 1 m on a cubic lattice of spacing 1.999 m standing on a box floor under
# gravity; linear spring 1e9 N/m, restitution 0.5, friction 0.3 with tangential
# history, 0.1 of the critical step) and the same scene in LIGGGHTS 3.8 (Debian's
# package, installed here when missing): hooke/stiffness with kt = 2/7 kn and the
# same damping, tangential history, primitive walls, the same step.
# Usage: bash bench/liggghts_compare.sh BUILD_DIR [STEPS] [ROUNDS]   (repo root)
# BASE=OTHER_BUILD_DIR also runs that build's collidoscope in every round (the
# two taking turns to go first) and gives the median of the rounds' ratios: on
# a VM whose pace moves by tens of per cent, builds compared within a round
# follow the same hour. Still rough there: one build against itself gave 0.868
# over 10 rounds (2026-11-29, a noisy hour), so give it 30 rounds or more; a
# change of a few per cent wants two engines stepped alternately in one
# process (docs/benchmarks.md, stop 49 and 57).
# Each round runs LIGGGHTS and then collidoscope; on a shared machine single
# runs move by tens of per cent, so the summary gives each one's median and the
# median of the rounds' ratios.
set -euo pipefail
build=${1:?BUILD_DIR}; steps=${2:-200}; rounds=${3:-1}
app="$build/app/collidoscope"
base_app=${BASE:+$BASE/app/collidoscope}
[ -z "$base_app" ] || [ -x "$base_app" ] || { echo "no $base_app"; exit 1; }
if ! command -v liggghts >/dev/null; then
  if [ "$(id -u)" = 0 ]; then DEBIAN_FRONTEND=noninteractive apt-get install -y liggghts >/dev/null
  else echo "liggghts is not installed (sudo apt-get install liggghts)"; exit 77; fi
fi
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
n=9680  # 22 x 22 x 20: whole layers, as bench run places them
/usr/bin/python3 - "$work" "$n" "$steps" <<'PY'
import math, sys
work, n, steps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
r, s, rho, k, e, mu, g = 1.0, 1.999, 2500.0, 1e9, 0.5, 0.3, 9.81
side = math.ceil(round(n ** (1 / 3), 9))
ext = side * s
m = rho * 4 / 3 * math.pi * r ** 3
meff = m / 2
zeta = -math.log(e) / math.sqrt(math.pi ** 2 + math.log(e) ** 2)
crit = 2 / math.sqrt(k / meff) * (math.sqrt(1 + zeta ** 2) - zeta)
dt = 0.1 * crit  # bench run's step: step_fraction of the critical step
gamma = 2 * zeta * math.sqrt(k / meff)  # LIGGGHTS multiplies it by the effective mass
half = (ext + 4 * r) / 2
with open(f"{work}/block.data", "w") as f:
    f.write(f"LIGGGHTS block\n\n{n} atoms\n1 atom types\n\n{-half-1} {half+1} xlo xhi\n"
            f"{-half-1} {half+1} ylo yhi\n-1 {ext * 1.5 + 6} zlo zhi\n\nAtoms\n\n")
    k_ = 0
    for z in range(side):
        for y in range(side):
            for x in range(side):
                if k_ == n: break
                k_ += 1
                f.write(f"{k_} 1 {2*r} {rho} {-ext/2+(x+0.5)*s} {-ext/2+(y+0.5)*s} {r*0.999+z*s}\n")
walls = "\n".join(
    f"fix w{i} all wall/gran model hooke/stiffness tangential history primitive type 1 {p} {v}"
    for i, (p, v) in enumerate([("xplane", -half), ("xplane", half), ("yplane", -half),
                                ("yplane", half), ("zplane", 0.0)]))
with open(f"{work}/in.block", "w") as f:
    f.write(f"""atom_style granular
atom_modify map array
boundary f f f
newton off
communicate single vel yes
units si
read_data {work}/block.data
neighbor 0.5 bin
neigh_modify delay 0
fix m1 all property/global kn peratomtypepair 1 {k}
fix m2 all property/global kt peratomtypepair 1 {2 / 7 * k}
fix m3 all property/global gamman peratomtypepair 1 {gamma}
fix m4 all property/global gammat peratomtypepair 1 {gamma}
fix m5 all property/global coefficientFriction peratomtypepair 1 {mu}
pair_style gran model hooke/stiffness tangential history
pair_coeff * *
timestep {dt}
fix gravi all gravity {g} vector 0.0 0.0 -1.0
{walls}
fix integr all nve/sphere
thermo {steps}
run 5
run {steps}
""")
print(f"# {n} particles, step {dt:.6g} s, {steps} timed steps")
PY
echo "## LIGGGHTS $(dpkg-query -W -f='${Version}' liggghts 2>/dev/null), 1 process; collidoscope bench run, 1 thread"
# One thread of the block's steps, ms a step, by the collidoscope binary $1.
block_ms() {
  "$1" bench run --counts $n --pairs on --steps "$steps" --threads 1 |
    awk -F'|' -v n=$n '$2 + 0 == n {gsub(/ /, "", $4); print $4}'
}
if [ -n "$base_app" ]; then
  echo "| round | LIGGGHTS ms/step | collidoscope ms/step | ratio | base build ms/step | this / base |"
  echo "|---:|---:|---:|---:|---:|---:|"
else
  echo "| round | LIGGGHTS ms/step | collidoscope ms/step | ratio |"
  echo "|---:|---:|---:|---:|"
fi
for round in $(seq 1 "$rounds"); do
  (cd "$work" && liggghts -in in.block -log "$work/log.liggghts" >/dev/null)
  lig=$(grep "^Loop time" "$work/log.liggghts" | tail -1 | awk -v s="$steps" '{printf "%.4f", 1000 * $4 / s}')
  # With a base build, the two take turns going first (the one right after
  # LIGGGHTS ran 3-10 % differently as the same build, measured).
  if [ -n "$base_app" ] && [ $((round % 2)) = 0 ]; then based=$(block_ms "$base_app"); fi
  ours=$(block_ms "$app")
  row="| $round | $lig | $ours | $(awk -v a="$ours" -v b="$lig" 'BEGIN {printf "%.3f", a / b}') |"
  if [ -n "$base_app" ]; then
    [ $((round % 2)) = 1 ] && based=$(block_ms "$base_app")
    row="$row $based | $(awk -v a="$ours" -v b="$based" 'BEGIN {printf "%.3f", a / b}') |"
    echo "$ours $based" >>"$work/base_rounds"
  fi
  echo "$row"
  echo "$lig $ours" >>"$work/rounds"
done
# The median of the numbers on stdin, one a line.
median() { sort -g | awk '{a[NR] = $1} END {print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2}'; }
printf "median LIGGGHTS %.4f ms/step; collidoscope %.4f; median ratio %.3f (%d rounds)\n" \
  "$(awk '{print $1}' "$work/rounds" | median)" "$(awk '{print $2}' "$work/rounds" | median)" \
  "$(awk '{print $2 / $1}' "$work/rounds" | median)" "$rounds"
if [ -n "$base_app" ]; then
  printf "base build %.4f ms/step; median ratio this / base %.3f (%d rounds)\n" \
    "$(awk '{print $2}' "$work/base_rounds" | median)" \
    "$(awk '{print $1 / $2}' "$work/base_rounds" | median)" "$rounds"
fi
