#!/usr/bin/env python3
"""The README's "speed against error" material from validation runs' summary.json files:
a markdown table of the equal-time relMSE ratios (ours ÷ each reference) per case and
backend — one column per run, so two runs can be compared — with the fixed costs and the
per-spp costs of every renderer, and an SVG plot of relMSE against sample time (ours,
Cycles, Mitsuba) for chosen cases.

  validation/speed_vs_error.py SUMMARY.json [SUMMARY2.json ...] [--svg docs/speed-vs-error.svg]
      [--cases CASE,CASE] [--markdown docs/speed-vs-error.md]
"""
import argparse
import html
import json
import math
import os
import sys

COLOURS = {"native": "#d62728", "embree": "#1f77b4", "mitsuba": "#2ca02c", "cycles": "#ff7f0e"}


def load(path):
    with open(path) as f:
        s = json.load(f)
    # References without an error-against-time ladder (POV-Ray) have no ratio.
    rows = [r for r in s["results"] if r.get("kind") == "radiance" and "refused" not in r and r.get("reference_curve")]
    return s, rows


def ratio_table(runs):
    """Markdown: one row per (case, backend, reference), one ratio column per run."""
    keys = []
    for _, rows in runs:
        for r in rows:
            k = (r["case"], r["backend"], r["reference"])
            if k not in keys:
                keys.append(k)
    head = "| case | ours | reference | " + " | ".join(f"run {i + 1}" for i in range(len(runs))) + " | fixed s (ours / ref) | ms per spp (ours / ref) |"
    out = [head, "|" + "---|" * (head.count("|") - 1)]
    for case, backend, ref in keys:
        cells, fits = [], "– | –"
        for _, rows in runs:
            r = next((r for r in rows if (r["case"], r["backend"], r["reference"]) == (case, backend, ref)), None)
            eq = r and r.get("equal_time_rel_mse_ratio")
            cells.append(f"{eq['ratio']:.2f}" if eq else "–")
            if r and r.get("timing") and r["timing"]["reference"]:
                t = r["timing"]
                fits = (f"{t['ours']['fixed_seconds']:.3f} / {t['reference']['fixed_seconds']:.3f} | "
                        f"{1e3 * t['ours']['seconds_per_spp']:.2f} / {1e3 * t['reference']['seconds_per_spp']:.2f}")
        out.append(f"| {case} | {backend} | {ref} | " + " | ".join(cells) + f" | {fits} |")
    return "\n".join(out)


def agreement(runs, tolerance=0.2, goal=0.5):
    """Markdown lines: how many rows (the `-H` ones aside: the naive estimator on purpose)
    agree between every pair of runs within `tolerance` (max ratio ÷ min ratio <= 1 +
    tolerance), the ones that do not, and the rows above `goal` in any run, unrounded."""
    table = {}
    for i, (_, rows) in enumerate(runs):
        for r in rows:
            eq = r.get("equal_time_rel_mse_ratio")
            if eq and "-H" not in r.get("flags", []):
                table.setdefault((r["case"], r["backend"], r["reference"]), [None] * len(runs))[i] = eq["ratio"]
    both = {k: v for k, v in table.items() if all(x is not None for x in v)}
    apart = {k: max(v) / min(v) for k, v in both.items() if max(v) > (1 + tolerance) * min(v)}
    fmt = lambda k, v: f"{k[0]} {k[1]} ÷ {k[2]} " + " / ".join("–" if x is None else f"{x:.3f}" for x in v)
    out = [f"{len(both) - len(apart)} of {len(both)} rows (`-H` aside) agree between the runs within {100 * tolerance:.0f} %."]
    out += [f"* apart by {f:.2f}×: {fmt(k, both[k])}" for k, f in sorted(apart.items(), key=lambda kv: -kv[1])]
    above = {k: v for k, v in table.items() if any(x is not None and x > goal for x in v)}
    out.append(f"{len(above)} rows above {goal} in some run" + (":" if above else "."))
    out += [f"* {fmt(k, v)}" for k, v in sorted(above.items(), key=lambda kv: -max(x or 0 for x in kv[1]))]
    return "\n".join(out)


def svg(rows, cases, width=330, height=240):
    """Small multiples: one log-log panel per case, relMSE against sample time."""
    panels = []
    for case in cases:
        rs = [r for r in rows if r["case"] == case]
        if not rs:
            continue
        series = {}
        for r in rs:
            series.setdefault(r["backend"], r["curve"])
            series.setdefault(r["reference"], r["reference_curve"])
        panels.append((case, series))
    if not panels:
        return None
    cols = min(3, len(panels))
    nrows = math.ceil(len(panels) / cols)
    W, H = cols * width, nrows * height + 30
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif">',
             f'<rect width="{W}" height="{H}" fill="white"/>']
    # Legend.
    for i, (name, col) in enumerate(COLOURS.items()):
        parts.append(f'<rect x="{10 + i * 90}" y="8" width="14" height="4" fill="{col}"/><text x="{28 + i * 90}" y="14" font-size="11">{name}</text>')
    for k, (case, series) in enumerate(panels):
        ox, oy = (k % cols) * width, 30 + (k // cols) * height
        pts = [(p["seconds"], p["rel_mse"]) for c in series.values() for p in c if p["seconds"] > 0 and p["rel_mse"] > 0]
        if not pts:
            continue
        lx0, lx1 = math.log10(min(t for t, _ in pts)) - 0.1, math.log10(max(t for t, _ in pts)) + 0.1
        ly0, ly1 = math.log10(min(e for _, e in pts)) - 0.1, math.log10(max(e for _, e in pts)) + 0.1
        x = lambda t: ox + 50 + (math.log10(t) - lx0) / (lx1 - lx0) * (width - 60)
        y = lambda e: oy + height - 40 - (math.log10(e) - ly0) / (ly1 - ly0) * (height - 60)
        parts.append(f'<rect x="{ox + 50}" y="{oy + 20}" width="{width - 60}" height="{height - 60}" fill="none" stroke="#999"/>')
        parts.append(f'<text x="{ox + 52}" y="{oy + 14}" font-size="11">{html.escape(case)}</text>')
        parts.append(f'<text x="{ox + 50}" y="{oy + height - 26}" font-size="9">{10 ** lx0:.2g} s</text>'
                     f'<text x="{ox + width - 45}" y="{oy + height - 26}" font-size="9">{10 ** lx1:.2g} s</text>')
        parts.append(f'<text x="{ox + 2}" y="{oy + height - 40}" font-size="9">{10 ** ly0:.0e}</text>'
                     f'<text x="{ox + 2}" y="{oy + 28}" font-size="9">{10 ** ly1:.0e}</text>')
        parts.append(f'<text x="{ox + width / 2 - 40}" y="{oy + height - 12}" font-size="10">sample time (log)</text>')
        for name, c in series.items():
            line = " ".join(f"{x(p['seconds']):.1f},{y(p['rel_mse']):.1f}" for p in sorted(c, key=lambda p: p["seconds"]) if p["seconds"] > 0 and p["rel_mse"] > 0)
            parts.append(f'<polyline points="{line}" fill="none" stroke="{COLOURS.get(name, "#333")}" stroke-width="2"/>')
    parts.append("</svg>")
    return "\n".join(parts)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("summaries", nargs="+")
    ap.add_argument("--svg", help="write the plot here")
    ap.add_argument("--cases", default="", help="comma-separated cases to plot (default: every case of the first run)")
    ap.add_argument("--markdown", help="write the table here (default: print it)")
    args = ap.parse_args()
    runs = [load(p) for p in args.summaries]
    table = ratio_table(runs)
    if len(runs) > 1:
        table += "\n\n" + agreement(runs)
    if args.markdown:
        with open(args.markdown, "w") as f:
            f.write(table + "\n")
    else:
        print(table)
    if args.svg:
        rows = runs[0][1]
        cases = [c for c in args.cases.split(",") if c] or list(dict.fromkeys(r["case"] for r in rows))
        doc = svg(rows, cases)
        if doc is None:
            sys.exit(f"speed_vs_error: none of the cases {cases} in {args.summaries[0]}")
        os.makedirs(os.path.dirname(os.path.abspath(args.svg)), exist_ok=True)
        with open(args.svg, "w") as f:
            f.write(doc)


if __name__ == "__main__":
    main()
