#!/usr/bin/env python3
"""How much the same jobs' measured times move between passes on this machine:
the noise floor a perfect cost model would still show against one run.

Run one job sweep several times with the same seed and one repeat a pass, e.g.
  for k in 1 2 3 4; do
    collidoscope calibrate --jobs --backend cpu --configs 120 --repeats 1 \\
      --job-threads 2 --budget 200 --meshes tests/data/meshes --seed 1 --out run$k.csv
  done
  python3 bench/job_noise.py run1.csv run2.csv run3.csv run4.csv

For each time (total and each stage) it prints, over the jobs every log holds:
a single run's MAPE against the median of all its runs; |run1 / run2 - 1|
(mean and median); with four logs or more, |min(1, 2) / min(3, 4) - 1|, what
keeping the faster of two repeats leaves; and how the stages' deviations go
together within a run (a pace of the whole job moves them together).
With --merged, one merged log (`collidoscope gvm merge`, whose rows keep each
run's total in total_s_runs): the floor a perfect model would show against the
log's own rows. Each job's four runs split into two pairs (passes 1 and 3, 2
and 4); the means of two pairs differ by sqrt(2) of a pair's error, twice a
four-run mean's, so half their mean |difference| estimates what the four-run
figure carries (the row's median of four a little more), by the jobs' length.
Usage: job_noise.py LOG.csv LOG.csv [LOG.csv ...] | job_noise.py --merged LOG.csv"""
import csv
import math
import statistics
import sys

# The columns that name a job: the sweep draws them, so equal values are the same job.
KEY = ["wall", "particles", "method", "placement", "steps", "render_width", "formats",
       "particle_contacts", "friction"]
TIMES = ["total_s", "prepare_s", "simulate_s", "render_s"]


def merged_floor(path):
    rows = []
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            runs = [float(x) for x in r.get("total_s_runs", "").split(";") if x]
            if len(runs) == 4 and min(runs) > 0:
                a, b = (runs[0] + runs[2]) / 2, (runs[1] + runs[3]) / 2
                rows.append((float(r["total_s"]), abs(a - b) / ((a + b) / 2)))
    print(f"{len(rows)} jobs with four runs")
    if not rows:
        return
    for lo, hi in [(0, 0.1), (0.1, 0.3), (0.3, 1), (1, math.inf), (0, math.inf)]:
        d = [x for t, x in rows if lo <= t < hi]
        if d:
            print(f"total {lo:g}-{hi:g} s: {len(d):4d} jobs, two pairs' means differ by"
                  f" {100 * statistics.fmean(d):5.1f} %; a four-run figure carries about"
                  f" {50 * statistics.fmean(d):5.1f} % (MAPE a perfect model would show)")


def main():
    if len(sys.argv) == 3 and sys.argv[1] == "--merged":
        return merged_floor(sys.argv[2])
    paths = sys.argv[1:]
    if len(paths) < 2:
        sys.exit(__doc__.split("Usage: ")[1])
    logs = []
    for p in paths:
        with open(p, newline="") as f:
            logs.append({tuple(r[c] for c in KEY): r for r in csv.DictReader(f)})
    common = set(logs[0]).intersection(*logs[1:])
    print(f"{len(common)} jobs in all {len(logs)} logs")
    if not common:
        return
    deviation = {}  # time -> {(job, run): log(run / median)}
    for t in TIMES:
        single, pair, paired_min = [], [], []
        deviation[t] = {}
        for job in common:
            v = [float(log[job][t]) for log in logs]
            if min(v) <= 0:
                continue
            med = statistics.median(v)
            single += [abs(x / med - 1) for x in v]
            pair.append(abs(v[0] / v[1] - 1))
            if len(v) >= 4:
                paired_min.append(abs(min(v[0], v[1]) / min(v[2], v[3]) - 1))
            for k, x in enumerate(v):
                deviation[t][(job, k)] = math.log(x / med)
        if not pair:
            continue
        line = (f"{t:11s} {len(pair):4d} jobs: one run vs the median {100 * statistics.fmean(single):5.1f} % MAPE;"
                f" |run1/run2 - 1| mean {100 * statistics.fmean(pair):5.1f} %, median {100 * statistics.median(pair):5.1f} %")
        if paired_min:
            line += (f"; |min(1,2)/min(3,4) - 1| mean {100 * statistics.fmean(paired_min):5.1f} %,"
                     f" median {100 * statistics.median(paired_min):5.1f} %")
        print(line)
    stages = TIMES[1:]
    for i, a in enumerate(stages):
        for b in stages[i + 1:]:
            both = [k for k in deviation[a] if k in deviation[b]]
            if len(both) > 2:
                r = statistics.correlation([deviation[a][k] for k in both], [deviation[b][k] for k in both])
                print(f"stages move together: {a} and {b}: correlation {r:.2f} over {len(both)} runs")
    for k in range(len(logs)):
        ratios = sorted(math.exp(deviation["total_s"][(job, k)]) for job in common
                        if (job, k) in deviation["total_s"])
        print(f"{paths[k]}: total / the median, median {ratios[len(ratios) // 2]:.3f},"
              f" 10th-90th percentile {ratios[len(ratios) // 10]:.3f}-{ratios[9 * len(ratios) // 10]:.3f}")


if __name__ == "__main__":
    main()
