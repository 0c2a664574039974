#!/usr/bin/env python3
"""Charts of a `collidoscope study --out DIR` run, as PNG (matplotlib, Agg).

  /usr/bin/python3 bench/study_charts.py DIR [DIR ...] [--out IMGDIR]  (IMGDIR: DIR/charts)

Reads DIR/study_detect.csv and DIR/study_dynamics.csv (several DIRs are concatenated, so a
CPU run and a CUDA run written to separate folders chart together); writes
  pareto_<backend>_<scene>_<placement>.png   time against contact error, Pareto front
  stability_[<backend>_]<scene>[_pairs].png  verdict per (time step, impact speed)
  paper_table4.png/.md, paper_fig12.png, paper_fig13.png, paper_fig14.png
  summary.json                               Pareto fronts, auto on front, verdict counts
A missing file, column or value skips what needs it, with a note, never the whole run.
"""
import argparse
import csv
import json
import math
import os
import sys
import traceback
from collections import Counter, defaultdict

import matplotlib
import numpy as np
matplotlib.use("Agg")  # no display on the study machines
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.ticker import FuncFormatter  # noqa: E402

DPI = 110
METHOD_COLOR = {"reference": "black", "gravity": "C1", "circumcircle": "C0",
                "midpoint4": "C2", "bin": "C3", "bvh": "C4"}
TRAVERSAL_MARKER = {"particle": "o", "wall": "s"}
# Ordered from benign to worst, so a cell with several rows shows the worst one.
VERDICTS = [("stable", "#2ca02c"), ("loses_contacts", "#9467bd"),
            ("tunnels", "#ff7f0e"), ("blows_up", "#d62728")]
PAPER_N = [1e2, 1e3, 1e4, 1e5, 1e6]
# The paper's Table 4, s per frame. Colours follow our series of the same meaning.
PAPER_T4 = [("paper CPU", "grey", [0.025, 0.038, 0.195, 1.674, 16.56]),
            ("paper GTX480 gravity wall1", "C1", [0.056, 0.068, 0.159, 0.836, 6.518]),
            ("paper GTX480 circumcircle wall1", "C0", [0.037, 0.044, 0.103, 0.453, 3.315]),
            ("paper GTX480 circumcircle wall2", "C2", [0.045, 0.057, 0.138, 0.683, 5.265])]
OUR_T4 = [("wall1", "circumcircle", "C0"), ("wall1", "gravity", "C1"),
          ("wall2", "circumcircle", "C2"), ("wall1", "bin", "C3"),
          ("wall1", "reference", "black")]
COUNT_COLOR = {1e2: "C8", 1e3: "C4", 1e4: "C2", 1e5: "C0", 1e6: "C3"}
BACKEND_STYLE = {"cpu": (":", "o"), "cuda": ("-", "^")}


def num(v):
    """Float of a CSV field, None for empty, missing, nan or junk."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        return None
    return None if math.isnan(x) else x


def load(path, names):
    """Rows of a CSV; the text columns in names are stripped, and a missing one (older
    file, short row) reads as "unknown" rather than failing a key lookup later."""
    if not os.path.exists(path):
        print(f"note: {path} is missing; charts that need it are skipped")
        return []
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        for k in names:
            r[k] = (r.get(k) or "").strip() or "unknown"
    return rows


def write_text(path, text):
    """Through a temporary name, so a chart run cut short leaves no half file."""
    tmp = f"{path}.tmp-{os.getpid()}"
    with open(tmp, "w") as f:
        f.write(text)
    os.replace(tmp, path)


def save(fig, out, name):
    path = os.path.join(out, name)
    fig.savefig(path, dpi=DPI, bbox_inches="tight")  # tight: legends sit outside the axes
    plt.close(fig)
    print(path)


def plain_log(ax, which):
    """Plain numbers on a log axis spanning under 1.5 decades, where matplotlib's default
    would print one power of ten (or 4x10^0 style minor labels)."""
    lo, hi = ax.get_xlim() if which == "x" else ax.get_ylim()
    if lo <= 0 or hi / lo >= 30:
        return
    axis = ax.xaxis if which == "x" else ax.yaxis
    lead = lambda v: round(v / 10 ** math.floor(math.log10(v) + 1e-9))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    shown = range(1, 10) if hi / lo < 5 else (2, 3, 5)  # every minor tick only when few
    axis.set_minor_formatter(FuncFormatter(lambda v, _: f"{v:g}" if lead(v) in shown else ""))


def guarded(what, fn, *args):
    """One chart failing on odd data must not cost the others."""
    try:
        fn(*args)
    except Exception as e:  # noqa: BLE001
        print(f"note: skipped {what}: {type(e).__name__}: {e}")
        traceback.print_exc(limit=2, file=sys.stdout)


# ---------------------------------------------------------------- detection rows
def detect_rows(raw):
    """Timed rows with numbers parsed; failed rows and rows without a time are dropped."""
    rows = []
    for r in raw:
        t, n = num(r.get("frame_ms")), num(r.get("particles"))
        if r["verdict"] == "failed" or not t or t <= 0 or not n:
            continue
        # Every measurement of the setting: the study's two passes (older
        # studies timed one) and, for the automatic choice's candidates, the
        # choice's own.
        times = [t] + [x for x in (num(r.get("frame_ms_other_pass")), num(r.get("frame_ms_choice")))
                       if x and x > 0]
        d = dict(r, frame_ms=t, frame_ms_lo=min(times), frame_ms_hi=max(times), particles=n,
                 grid_factor=num(r.get("grid_factor")),
                 triangles_used=num(r.get("triangles_used")),
                 auto=(r.get("auto") or "").strip() == "1")
        miss, inv, ref = (num(r.get(k)) for k in ("missed", "invented", "contacts"))
        # Float precision decides the pairs inside its error band without a
        # check: they are uncertain even where they happened to come out right,
        # so they count against its accuracy (exact re-decides them in double).
        doubt = (num(r.get("band_pairs")) or 0) if r.get("precision") == "float" else 0
        # Per 10^5 reference contacts; a scene without contacts counts each error
        # against one contact so that a wrong row still shows up high.
        d["error"] = (None if None in (miss, inv, ref) else (miss + inv + doubt) * 1e5 / max(ref, 1))
        rows.append(d)
    return rows


def on_front(p, rows, tol=0.0, beyond_repeat=False):
    """Nobody both (more than tol) strictly faster and with error <= p's.
    beyond_repeat: q counts as faster only if even its slowest measurement
    beats p's fastest, so a difference a repeat could reverse does not decide
    (the study times every setting twice, and the automatic choice timed its
    candidates once more; frame_ms is the study's faster pass)."""
    faster = ((lambda q: q["frame_ms_hi"] < p["frame_ms_lo"]) if beyond_repeat
              else (lambda q: q["frame_ms"] < p["frame_ms"] * (1 - tol)))
    return not any(q is not p and faster(q) and q["error"] <= p["error"] for q in rows)


def folder_backends(rows):
    """Each study folder's backends (its rows but the reference's)."""
    out = defaultdict(set)
    for r in rows:
        if r["method"] != "reference":
            out[r["_dir"]].add(r["backend"])
    return out


def pareto_groups(rows):
    """(backend, scene, placement) -> (largest particle count, its rows with an error)."""
    groups = defaultdict(list)
    # The reference runs on the CPU whatever the study's backend: it belongs to
    # the groups of its own study (folder), measured on that machine, not to
    # another machine's charts.
    backends = folder_backends(rows)
    for r in rows:
        if r["error"] is None:
            continue
        for b in (backends.get(r["_dir"]) or {"cpu"} if r["method"] == "reference" else [r["backend"]]):
            groups[(b, r["scene"], r["placement"])].append(r)
    out = {}
    for key, rs in sorted(groups.items()):
        n = max(r["particles"] for r in rs)
        out[key] = (n, [r for r in rs if r["particles"] == n])
    return out


def pareto_chart(out, key, n, rs):
    backend, scene, placement = key
    fig, ax = plt.subplots(figsize=(8, 5))
    for r in rs:
        c = METHOD_COLOR.get(r["method"], "C7")
        if r["frame_ms_hi"] > r["frame_ms_lo"]:  # its measurements: two passes (and the choice's)
            ax.plot([r["frame_ms_lo"], r["frame_ms_hi"]], [r["error"]] * 2, color=c, lw=1, alpha=0.6,
                    zorder=2)
        ax.scatter(r["frame_ms"], r["error"], s=42, zorder=3, linewidths=1.4, edgecolors=c,
                   marker=TRAVERSAL_MARKER.get(r["traversal"], "D"),
                   facecolors="none" if r["precision"] == "float" else c)
    front = sorted((r for r in rs if on_front(r, rs)), key=lambda r: (r["frame_ms"], r["error"]))
    ax.step([r["frame_ms"] for r in front], [r["error"] for r in front], where="post",
            color="0.35", lw=1, zorder=2)
    for r in rs:
        if r["auto"]:
            ax.scatter(r["frame_ms"], r["error"], marker="*", s=380, zorder=4,
                       facecolors="gold", edgecolors="black", linewidths=0.8)
            ax.annotate("auto", (r["frame_ms"], r["error"]), xytext=(9, 9),
                        textcoords="offset points", fontweight="bold")
    ax.set_xscale("log")
    ax.set_yscale("symlog", linthresh=1)  # linear below 1, so error 0 is on the chart
    top = max(r["error"] for r in rs)
    ax.set_ylim(-0.4, max(top * 2.5, 3))  # headroom: symlog autoscale clips the top row
    ax.grid(True, which="major", alpha=0.3)
    plain_log(ax, "x")
    ax.set_xlabel("time per frame (ms, fastest of the timed frames; a line: its other measurements)")
    ax.set_ylabel("contact error: missed + invented (+ float's unchecked\nband pairs) per $10^5$ reference contacts")
    ax.set_title(f"{scene}, {placement} placement, {n:,.0f} particles, {backend}")
    present = {r["method"] for r in rs}
    methods = [m for m in METHOD_COLOR if m in present] + sorted(present - set(METHOD_COLOR))
    handles = [Patch(color=METHOD_COLOR.get(m, "C7"), label=m) for m in methods]
    mark = lambda label, m="o", **kw: Line2D([], [], ls="", marker=m, color="0.3",
                                             label=label, **kw)
    handles += [mark(f"{t} traversal", TRAVERSAL_MARKER.get(t, "D"))
                for t in sorted({r["traversal"] for r in rs})]
    handles += [mark("exact / double"), mark("float", mfc="none"),
                Line2D([], [], color="0.35", lw=1, label="Pareto front"),
                mark("automatic choice", "*", ms=14, mfc="gold", mec="black")]
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1), fontsize=9)
    save(fig, out, f"pareto_{backend}_{scene}_{placement}.png")


def pareto_summary(key, n, rs):
    front = sorted((r for r in rs if on_front(r, rs)), key=lambda r: r["frame_ms"])
    auto = next((r for r in rs if r["auto"]), None)
    pick = lambda r: {k: r[k] for k in ("method", "traversal", "grid_factor",
                                            "precision", "frame_ms", "error")}
    return {"backend": key[0], "scene": key[1], "placement": key[2], "particles": int(n),
            "front": [pick(r) for r in front], "auto": auto and pick(auto),
            "auto_on_front": auto and on_front(auto, rs),
            "auto_on_front_within_5pct": auto and on_front(auto, rs, 0.05),
            "auto_on_front_beyond_repeat": auto and on_front(auto, rs, beyond_repeat=True)}


# ---------------------------------------------------------------- paper redraws
def paper_rows(rows, scene=None, method=None, traversal="particle", gf=2.0):
    """The paper's setting: uniform, exact, grid length 2 r_max, particle traversal.
    The reference has no grid and computes in double, so it is taken as it is."""
    return [r for r in rows if r["placement"] == "uniform"
            and scene in (None, r["scene"]) and method in (None, r["method"])
            and (r["method"] == "reference" or (
                r["precision"] == "exact" and r["traversal"] == traversal
                and r["grid_factor"] is not None and abs(r["grid_factor"] - gf) < 1e-9))]


def series(rs, x="particles"):
    """Sorted (x, s per frame); a repeated x keeps its fastest row."""
    best = {}
    for r in rs:
        if r[x] is not None:
            best[r[x]] = min(best.get(r[x], math.inf), r["frame_ms"] / 1e3)
    return sorted(best.items())


def paper_table4(out, rows):
    fig, ax = plt.subplots(figsize=(8.5, 5.5))
    ours = []  # (label, {n: s})
    for backend in sorted({r["backend"] for r in rows}):
        ls, mk = BACKEND_STYLE.get(backend, ("-.", "s"))
        for scene, method, color in OUR_T4:
            if method == "reference" and backend != "cpu":
                continue
            # The CPU's reference from the CPU's own study where there is one (a
            # GPU study's reference ran on that machine's host).
            cpu_dirs = {d for d, bs in folder_backends(rows).items() if "cpu" in bs}
            mine = [r for r in rows if r["backend"] == backend
                    and (method != "reference" or not cpu_dirs or r["_dir"] in cpu_dirs)]
            pts = series(paper_rows(mine, scene, method))
            if pts:
                label = f"ours {backend} {method} {scene}"
                ax.plot(*zip(*pts), ls=ls, marker=mk, color=color, label=label)
                ours.append((label, dict(pts)))
    if not ours:
        plt.close(fig)
        print("note: skipped paper_table4: no uniform exact grid-2 particle-traversal rows")
        return
    for label, color, vals in PAPER_T4:
        ax.plot(PAPER_N, vals, ls="--", color=color, alpha=0.55, marker="x", label=label)
    ax.set(xscale="log", yscale="log", xlabel="particles", ylabel="time per frame (s)",
           title="Paper Table 4 / Fig. 11 against this build\n(uniform, exact, "
                 "grid length 2 $r_{max}$, particle traversal)")
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1), fontsize=8.5)
    save(fig, out, "paper_table4.png")

    # Columns: the paper's counts plus any other count the study ran.
    cols = sorted(set(PAPER_N) | {n for _, d in ours for n in d})
    head = lambda n: f"1e{math.log10(n):.0f}" if n in PAPER_N else f"{n:,.0f}"
    row = lambda label, d, f: (f"| {label} | " + " | ".join(
        "" if d.get(n) is None else f.format(d[n]) for n in cols) + " |")
    lines = ["| series (s per frame) | " + " | ".join(map(head, cols)) + " |",
             "|---" * (len(cols) + 1) + "|"]
    # The paper's values as printed; ours to 4 significant digits, trailing zeros kept.
    lines += [row(label, dict(zip(PAPER_N, vals)), "{:g}") for label, _, vals in PAPER_T4]
    lines += [row(label, d, "{:#.4g}") for label, d in ours]
    # Speed-up: the paper's best GPU series over our fastest wall1 series at that count.
    paper_gpu = dict(zip(PAPER_N, PAPER_T4[2][2]))
    best = {n: min((d[n] for lab, d in ours if lab.endswith("wall1") and n in d), default=None)
            for n in cols}
    lines.append("| speed-up (paper GPU circumcircle wall1 / our best wall1) | " + " | ".join(
        f"{paper_gpu[n] / best[n]:.3g}x" if n in paper_gpu and best[n] else "" for n in cols)
        + " |")
    lines.append("\nSpeed-up above 1: this build is faster than the paper's GTX480 circumcircle.")
    path = os.path.join(out, "paper_table4.md")
    write_text(path, "\n".join(lines) + "\n")
    print(path)


def per_backend_axes(rows, width=6.0, height=4.6, sharey=True):
    backends = sorted({r["backend"] for r in rows})
    fig, axs = plt.subplots(1, len(backends), figsize=(width * len(backends), height),
                            squeeze=False, sharey=sharey, layout="constrained")
    return fig, list(zip(backends, axs[0]))


def finish(fig, axes, title, name, out):
    axes[0][1].set_ylabel("time per frame (s)")
    fig.suptitle(title, fontsize=11)
    save(fig, out, name)


def paper_fig12(out, rows):
    rows = [r for r in rows if r["scene"] == "wall1" and r["method"] != "reference"]
    if not rows:
        return print("note: skipped paper_fig12: no wall1 rows")
    fig, axes = per_backend_axes(rows)
    for backend, ax in axes:
        b = [r for r in rows if r["backend"] == backend]
        for method in ("circumcircle", "gravity", "bin"):
            for trav, ls in (("particle", "-"), ("wall", "--")):
                pts = series(paper_rows(b, "wall1", method, trav))
                if pts:
                    ax.plot(*zip(*pts), ls=ls, marker="o", ms=4, color=METHOD_COLOR[method],
                            label=f"{method}, {trav} traversal")
        ax.set(xscale="log", yscale="log", xlabel="particles", title=f"{backend}")
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=8, loc="upper left")
    finish(fig, axes, "Paper Fig. 12: wall traversal (dashed) against particle traversal "
           "(solid)\nwall1, uniform, exact, grid 2 $r_{max}$", "paper_fig12.png", out)


def paper_fig13(out, rows):
    rows = [r for r in rows if r["method"] in ("gravity", "circumcircle", "midpoint4")
            and r["triangles_used"]]
    rows = paper_rows(rows)
    if not rows:
        return print("note: skipped paper_fig13: no division-method rows with triangles_used")
    fig, axes = per_backend_axes(rows, 6.5)
    markers = {"gravity": "o", "circumcircle": "s", "midpoint4": "^"}
    for backend, ax in axes:
        b = [r for r in rows if r["backend"] == backend]
        for n in sorted({r["particles"] for r in b})[-2:]:
            for method, mk in markers.items():
                pts = [(r["triangles_used"] / 1e3, r["frame_ms"] / 1e3) for r in b
                       if r["particles"] == n and r["method"] == method]
                if pts:
                    ax.scatter(*zip(*pts), marker=mk, color=COUNT_COLOR.get(n, "C7"), s=30,
                               label=f"{n:,.0f} particles, {method}")
        xs = [0, max(r["triangles_used"] for r in b) * 1.05]
        # The paper's fits share the colour of our points at the same particle count.
        for a, c, n in ((2.477e-9, 0.2712, 1e5), (2.078e-5, 1.8970, 1e6)):
            ax.plot([x / 1e3 for x in xs], [a * x + c for x in xs], "--", color=COUNT_COLOR[n],
                    label=f"paper fit, $10^{math.log10(n):.0f}$ particles")
        ax.set(yscale="log", xlabel="triangles after division (thousands)", title=backend)
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2)
        plain_log(ax, "y")
    finish(fig, axes, "Paper Fig. 13: time per frame against triangles after division\n"
           "(all scenes; uniform, exact, grid 2 $r_{max}$)", "paper_fig13.png", out)


def paper_fig14(out, rows):
    rows = [r for r in rows if r["scene"] == "wall1" and r["method"] != "reference"
            and r["placement"] == "uniform" and r["precision"] == "exact"
            and r["traversal"] == "particle" and r["grid_factor"]]
    if not rows:
        return print("note: skipped paper_fig14: no wall1 uniform exact particle rows")
    fig, axes = per_backend_axes(rows, sharey=False)  # the shape matters, not the level
    for backend, ax in axes:
        b = [r for r in rows if r["backend"] == backend]
        n = max(r["particles"] for r in b)
        for method in sorted({r["method"] for r in b}):
            pts = series([r for r in b if r["particles"] == n and r["method"] == method],
                         "grid_factor")
            ax.plot(*zip(*pts), marker="o", color=METHOD_COLOR.get(method, "C7"), label=method)
        ax.set(yscale="log", xlabel="grid length ($r_{max}$)",
               title=f"{backend}, {n:,.0f} particles")
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=8)
        plain_log(ax, "y")
    finish(fig, axes, "Paper Fig. 14: time per frame against grid length, wall1, uniform, "
           "exact\n(the paper's curve rose from about 0.1 s to 0.2 s over grid lengths 2 to 7)",
           "paper_fig14.png", out)


# ---------------------------------------------------------------- dynamics
def log_position(ticks, v):
    """Where v falls on categorical axis positions 0..n-1 of the sorted ticks, read as a
    log scale between neighbours; None outside them."""
    logs, lv = [math.log10(t) for t in ticks], math.log10(v)
    return float(np.interp(lv, logs, range(len(logs)))) if logs[0] <= lv <= logs[-1] else None


def stability_chart(out, name, title, rs):
    names = [v for v, _ in VERDICTS]
    pts = [(num(r.get("dt_factor")), num(r.get("speed_factor")), r) for r in rs]
    pts = [(d, s, r) for d, s, r in pts if d and s]
    if not pts:
        return print(f"note: skipped {name}: no rows with dt_factor and speed_factor")
    # Every method panel uses the scene's full axes, so panels line up cell for cell.
    dts, sps = sorted({d for d, _, _ in pts}), sorted({s for _, s, _ in pts})
    methods = sorted({r["method"] for _, _, r in pts})
    ncol = min(len(methods), 4)
    nrow = math.ceil(len(methods) / ncol)
    fig, axs = plt.subplots(nrow, ncol, figsize=(3.3 * ncol + 0.4, 3.2 * nrow + 0.9),
                            squeeze=False)
    cmap = ListedColormap([c for _, c in VERDICTS] + ["#bbbbbb"])  # last: unknown verdict
    cmap.set_bad("white")  # a combination the study did not run
    for ax, method in zip(axs.flat, methods):
        grid = [[math.nan] * len(dts) for _ in sps]
        for d, s, r in pts:
            if r["method"] == method:
                v = names.index(r["verdict"]) if r["verdict"] in names else len(names)
                i, j = sps.index(s), dts.index(d)
                grid[i][j] = v if math.isnan(grid[i][j]) else max(grid[i][j], v)
        ax.imshow(grid, cmap=cmap, vmin=-0.5, vmax=len(names) + 0.5, origin="lower",
                  aspect="auto", interpolation="nearest")
        ax.set_xticks(range(len(dts)), [f"{d:g}" for d in dts], rotation=60, fontsize=8)
        ax.set_yticks(range(len(sps)), [f"{s:g}" for s in sps], fontsize=8)
        ax.set_xticks([k - 0.5 for k in range(len(dts) + 1)], minor=True)
        ax.set_yticks([k - 0.5 for k in range(len(sps) + 1)], minor=True)
        ax.grid(True, which="minor", color="white", lw=1)
        ax.tick_params(which="minor", length=0)
        x = log_position(dts, 1.0)
        if x is not None:
            ax.axvline(x, color="black", ls="--", lw=1.2)
        ax.set_title(method)
        ax.set_xlabel("time step / automatic step")
    for ax in axs.flat[len(methods):]:
        ax.axis("off")
    for row in axs:
        row[0].set_ylabel("impact speed / scene's speed")
    handles = [Patch(color=c, label=v.replace("_", " ")) for v, c in VERDICTS]
    handles += [Patch(facecolor="white", edgecolor="0.6", label="not run"),
                Line2D([], [], color="black", ls="--", label="automatic step")]
    fig.legend(handles=handles, loc="lower center", ncol=6, bbox_to_anchor=(0.5, -0.02))
    fig.suptitle(title)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    save(fig, out, name)


def stability_charts(out, raw):
    # The backend goes into the name only when the file has several, so a CPU-only
    # study keeps the short names.
    multi = len({r["backend"] for r in raw}) > 1
    by = defaultdict(list)
    for r in raw:
        by[(r["backend"], r["scene"])].append(r)
    pc_text = {"0": "no particle-particle contacts", "1": "with particle-particle contacts"}
    for (backend, scene), rs in sorted(by.items()):
        stem = f"stability_{backend}_{scene}" if multi else f"stability_{scene}"
        where = scene + (f", {backend}" if multi else "")
        pcs = {r["particle_contacts"] for r in rs}
        # Both present: the plain name shows 0 (walls alone), _pairs shows 1.
        if {"0", "1"} <= pcs:
            parts = [("0", ""), ("1", "_pairs")]
        else:
            parts = [(pcs.pop() if len(pcs) == 1 else None, "")]
        for pc, suffix in parts:
            sel = [r for r in rs if pc is None or r["particle_contacts"] == pc]
            label = pc_text.get(pc, "")
            guarded(stem + suffix, stability_chart, out, stem + suffix + ".png",
                    f"{where}: verdict" + (f", {label}" if label else ""), sel)


# ---------------------------------------------------------------- main
def main(argv):
    ap = argparse.ArgumentParser(description="Charts of a `collidoscope study` run.")
    ap.add_argument("dirs", nargs="+", metavar="DIR", help="a study's --out directory")
    ap.add_argument("--out", help="where the charts go (default: the first DIR/charts)")
    args = ap.parse_args(argv)
    out = args.out or os.path.join(args.dirs[0], "charts")
    os.makedirs(out, exist_ok=True)

    rows = detect_rows([dict(r, _dir=k) for k, d in enumerate(args.dirs) for r in load(
        os.path.join(d, "study_detect.csv"),
        ("backend", "scene", "placement", "method", "traversal", "precision", "verdict"))])
    summary = {"detect": [], "dynamics": {}}
    for key, (n, rs) in pareto_groups(rows).items():
        guarded(f"pareto {key}", pareto_chart, out, key, n, rs)
        summary["detect"].append(pareto_summary(key, n, rs))
    if not rows:
        print("note: no timed detection rows; Pareto and paper charts skipped")
    else:
        for what, fn in (("paper_table4", paper_table4), ("paper_fig12", paper_fig12),
                         ("paper_fig13", paper_fig13), ("paper_fig14", paper_fig14)):
            guarded(what, fn, out, rows)

    dyn = [r for d in args.dirs for r in load(os.path.join(d, "study_dynamics.csv"),
                                              ("backend", "scene", "method",
                                               "particle_contacts", "verdict"))]
    if not dyn:
        print("note: no dynamics rows; stability charts skipped")
    stability_charts(out, dyn)
    summary["dynamics"]["verdicts"] = dict(Counter(r["verdict"] for r in dyn))
    per = defaultdict(Counter)
    for r in dyn:
        per[f"{r['backend']}/{r['scene']}/{r['method']}"][r["verdict"]] += 1
    summary["dynamics"]["verdicts_by_backend_scene_method"] = {
        k: dict(v) for k, v in sorted(per.items())}

    path = os.path.join(out, "summary.json")
    write_text(path, json.dumps(summary, indent=1))
    print(path)

    print(f"\n{'backend':8} {'scene':12} {'placement':9} {'particles':>10} {'auto':32} "
          "on_front within_5% beyond_repeat")
    yn = lambda v: "-" if v is None else ("yes" if v else "NO")
    text = lambda v: "?" if v in (None, "") else f"{v:g}" if isinstance(v, float) else v
    for g in summary["detect"]:
        a = g["auto"]
        desc = "/".join(text(a[k]) for k in ("method", "traversal", "grid_factor", "precision")
                        ) if a else "(no auto row)"
        print(f"{g['backend']:8} {g['scene']:12} {g['placement']:9} {g['particles']:10,.0f} "
              f"{desc:32} {yn(g['auto_on_front']):8} {yn(g['auto_on_front_within_5pct']):11} "
              f"{yn(g['auto_on_front_beyond_repeat'])}")


if __name__ == "__main__":
    main(sys.argv[1:])
