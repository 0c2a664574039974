#!/usr/bin/env python3
"""Charts of a `collidoscope gvm train` run, as SVG (standard library only).

  scripts/gvm_charts.py scatter PREDICTIONS.csv OUT.svg [--output time_per_frame_s]
      measured against predicted, log-log, for the GVM and the MLP baseline, with
      the +-15 % band (from `gvm train --predictions`)
  scripts/gvm_charts.py curve CURVE.csv OUT.svg
      train and validation loss per epoch, log scale (from `gvm train --curve`)
"""
import csv
import math
import sys

W, H, M = 560, 420, 60  # canvas and margin, px (the scatter sets a square canvas)


def axis_ticks(lo, hi):
    """Powers of ten covering [lo, hi] (log10 values)."""
    return list(range(math.floor(lo), math.ceil(hi) + 1))


def svg_open(title):
    return [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" '
            f'font-family="sans-serif" font-size="12">',
            f'<rect width="{W}" height="{H}" fill="white"/>',
            f'<text x="{W / 2}" y="20" text-anchor="middle" font-size="14">{title}</text>']


def frame(out, xlo, xhi, ylo, yhi, xlabel, ylabel, xlog=True):
    sx = lambda v: M + (v - xlo) / (xhi - xlo) * (W - 2 * M)
    sy = lambda v: H - M - (v - ylo) / (yhi - ylo) * (H - 2 * M)
    out.append(f'<rect x="{M}" y="{M}" width="{W - 2 * M}" height="{H - 2 * M}" '
               f'fill="none" stroke="#444"/>')
    for t in axis_ticks(ylo, yhi):
        if ylo <= t <= yhi:
            out.append(f'<line x1="{M}" x2="{W - M}" y1="{sy(t):.1f}" y2="{sy(t):.1f}" '
                       f'stroke="#ddd"/><text x="{M - 6}" y="{sy(t) + 4:.1f}" '
                       f'text-anchor="end">1e{t}</text>')
    xt = axis_ticks(xlo, xhi) if xlog else nice_linear(xlo, xhi)
    for t in xt:
        if xlo <= t <= xhi:
            label = f'1e{t}' if xlog else f'{t:g}'
            out.append(f'<line y1="{M}" y2="{H - M}" x1="{sx(t):.1f}" x2="{sx(t):.1f}" '
                       f'stroke="#ddd"/><text x="{sx(t):.1f}" y="{H - M + 16}" '
                       f'text-anchor="middle">{label}</text>')
    out.append(f'<text x="{W / 2}" y="{H - 18}" text-anchor="middle">{xlabel}</text>')
    out.append(f'<text x="16" y="{H / 2}" text-anchor="middle" '
               f'transform="rotate(-90 16 {H / 2})">{ylabel}</text>')
    return sx, sy


def nice_linear(lo, hi):
    step = 10 ** math.floor(math.log10(max(hi - lo, 1e-12)))
    if (hi - lo) / step < 4:
        step /= 2
    return [lo + i * step for i in range(int((hi - lo) / step) + 1)]


def legend(out, items, x=M + 14):
    for i, (label, color) in enumerate(items):
        y = M + 16 + 18 * i
        out.append(f'<circle cx="{x}" cy="{y - 4}" r="4" fill="{color}"/>'
                   f'<text x="{x + 10}" y="{y}">{label}</text>')


def scatter(pred_csv, out_svg, output):
    global W, H
    W, H = 480, 480  # equal scales on both axes, so the diagonal is at 45 degrees
    rows = list(csv.DictReader(open(pred_csv)))
    models = [("gvm", "#1f77b4"), ("mlp-backprop", "#ff7f0e")]
    pts = {m: [] for m, _ in models}
    for r in rows:
        t = float(r[output])
        if t <= 0:
            continue
        for m, _ in models:
            p = float(r[f"{m}_{output}"])
            if p > 0:
                pts[m].append((math.log10(t), math.log10(p), abs(p - t) / t))
    every = [v for m in pts for (a, b, _) in pts[m] for v in (a, b)]
    lo, hi = math.floor(min(every) * 4) / 4, math.ceil(max(every) * 4) / 4
    mape = {m: 100 * sum(e for *_, e in pts[m]) / max(1, len(pts[m])) for m in pts}
    out = svg_open(f"{output}, {len(rows)} validation rows")
    sx, sy = frame(out, lo, hi, lo, hi, f"measured {output}", f"predicted {output}")
    band = math.log10(1.15)
    out.append(f'<polygon points="{sx(lo):.1f},{sy(lo + band):.1f} {sx(hi - band):.1f},'
               f'{sy(hi):.1f} {sx(hi):.1f},{sy(hi):.1f} {sx(hi):.1f},{sy(hi - band):.1f} '
               f'{sx(lo + band):.1f},{sy(lo):.1f} {sx(lo):.1f},{sy(lo):.1f}" '
               f'fill="#2ca02c" fill-opacity="0.12"/>')
    out.append(f'<line x1="{sx(lo):.1f}" y1="{sy(lo):.1f}" x2="{sx(hi):.1f}" y2="{sy(hi):.1f}" '
               f'stroke="#2ca02c"/>')
    for m, color in reversed(models):
        for a, b, _ in pts[m]:
            out.append(f'<circle cx="{sx(a):.1f}" cy="{sy(b):.1f}" r="2.6" fill="{color}" '
                       f'fill-opacity="0.7"/>')
    legend(out, [(f"{m} (MAPE {mape[m]:.1f} %)", c) for m, c in models] +
           [("within 15 %", "#2ca02c")])
    out.append("</svg>")
    open(out_svg, "w").write("\n".join(out) + "\n")


def curve(curve_csv, out_svg):
    rows = list(csv.DictReader(open(curve_csv)))
    step = max(1, len(rows) // 400)  # a few hundred points draw the same line
    rows = rows[::step] + ([rows[-1]] if (len(rows) - 1) % step else [])
    ep = [int(r["epoch"]) for r in rows]
    series = [("train", "#1f77b4"), ("validation", "#d62728")]
    vals = {s: [math.log10(float(r[f"{s}_loss"])) for r in rows] for s, _ in series}
    every = [v for s in vals for v in vals[s]]
    ylo, yhi = math.floor(min(every) * 2) / 2, math.ceil(max(every) * 2) / 2
    out = svg_open("GVM loss per epoch (mean over the machines)")
    sx, sy = frame(out, 0, ep[-1], ylo, yhi, "epoch", "loss (MSE of scaled targets)",
                   xlog=False)
    for s, color in series:
        path = " ".join(f"{sx(e):.1f},{sy(v):.1f}" for e, v in zip(ep, vals[s]))
        out.append(f'<polyline points="{path}" fill="none" stroke="{color}" stroke-width="1.5"/>')
    # Top right: the curves start at the top left.
    legend(out, [(f"{s} (last {10 ** vals[s][-1]:.2e})", c) for s, c in series], x=W - M - 200)
    out.append("</svg>")
    open(out_svg, "w").write("\n".join(out) + "\n")


def main(argv):
    if len(argv) >= 3 and argv[0] == "scatter":
        output = argv[argv.index("--output") + 1] if "--output" in argv else "time_per_frame_s"
        scatter(argv[1], argv[2], output)
    elif len(argv) == 3 and argv[0] == "curve":
        curve(argv[1], argv[2])
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main(sys.argv[1:])
