#!/usr/bin/env python3
"""The "speed against error" material from validation runs' summary.json files: a markdown
table of the equal-time relMSE ratios (ours ÷ each reference) per case and backend — one column
per run, so two runs can be compared — with the fixed costs and the per-spp costs of every
renderer, an SVG plot of relMSE against sample time (ours, Cycles, Mitsuba) for chosen cases,
and the documentation's tables.

  validation/speed_vs_error.py SUMMARY.json [SUMMARY2.json ...] [--svg docs/validation/speed-vs-error.svg]
      [--cases CASE,CASE] [--markdown FILE] [--csv docs/validation/speed-vs-error.csv] [--paste]
  validation/speed_vs_error.py --from-csv docs/validation/speed-vs-error.csv --paste

--csv keeps the runs' ratios with their date, commit and CPU (the data the documentation's
tables are made from); --paste writes the full table into docs/validation/speed-vs-error.md and
the headline table into README.md, between their speed-vs-error markers.
"""
import argparse
import html
import json
import math
import os
import sys

COLOURS = {"native": "#d62728", "embree": "#1f77b4", "embree3": "#1f77b4", "embree4": "#17becf", "mitsuba": "#2ca02c", "mitsuba_ptracer": "#98df8a", "cycles": "#ff7f0e"}


def load(path):
    with open(path) as f:
        s = json.load(f)
    # References without an error-against-time ladder (POV-Ray) have no ratio.
    rows = [r for r in s["results"] if r.get("kind") == "radiance" and "refused" not in r and r.get("reference_curve")]
    return s, rows


def csv_number(x):
    """`x` as the CSV writes it (4 decimals)."""
    return f"{x:.4f}"


def kept(x):
    """`x` at the CSV's precision, so that tables made from runs and from the CSV are the same."""
    return float(csv_number(x))


def table_rows(runs):
    """One dict per (case, backend, reference): the ratio of each run (None where a run has
    none), whether the row is a `-H` one, and the last run's fixed and per-spp costs, all at
    the CSV's precision."""
    out = {}
    for i, (_, rows) in enumerate(runs):
        for r in rows:
            k = (r["case"], r["backend"], r["reference"])
            row = out.setdefault(k, {"case": k[0], "backend": k[1], "reference": k[2], "ratios": [None] * len(runs),
                                     "hemisphere": "-H" in r.get("flags", []), "costs": None})
            eq = r.get("equal_time_rel_mse_ratio")
            row["ratios"][i] = kept(eq["ratio"]) if eq else None
            if r.get("timing") and r["timing"]["reference"]:
                t = r["timing"]
                row["costs"] = tuple(kept(c) for c in (t["ours"]["fixed_seconds"], t["reference"]["fixed_seconds"], 1e3 * t["ours"]["seconds_per_spp"], 1e3 * t["reference"]["seconds_per_spp"]))
    return list(out.values())


def provenance(runs):
    """The runs' date, commit, CPU and tier, from their summary.json."""
    s = runs[-1][0]
    return {"date": s.get("date", "?"), "commit": s.get("commit", "?"), "cpu": s.get("cpu", "?"), "tier": s.get("tier", "?"),
            "runs": str(len(runs)), "source": "validation/speed_vs_error.py " + " ".join(os.path.basename(p) for p in s.get("_paths", []))}


def write_csv(path, rows, meta):
    with open(path, "w") as f:
        f.write("# " + "; ".join(f"{k}={v}" for k, v in meta.items()) + "\n")
        runs = len(rows[0]["ratios"]) if rows else 0
        f.write("case,backend,reference,hemisphere," + ",".join(f"run{i + 1}" for i in range(runs)) + ",fixed_s_ours,fixed_s_ref,ms_per_spp_ours,ms_per_spp_ref\n")
        for r in rows:
            ratios = ["" if x is None else csv_number(x) for x in r["ratios"]]
            costs = ["", "", "", ""] if r["costs"] is None else [csv_number(c) for c in r["costs"]]
            f.write(",".join([r["case"], r["backend"], r["reference"], "1" if r["hemisphere"] else "0"] + ratios + costs) + "\n")


def read_csv(path):
    with open(path) as f:
        lines = [l.rstrip("\n") for l in f if l.strip()]
    meta = dict(kv.split("=", 1) for kv in lines[0].lstrip("# ").split("; "))
    head = lines[1].split(",")
    nruns = sum(1 for h in head if h.startswith("run"))
    rows = []
    for line in lines[2:]:
        c = line.split(",")
        costs = c[4 + nruns:8 + nruns]
        rows.append({"case": c[0], "backend": c[1], "reference": c[2], "hemisphere": c[3] == "1",
                     "ratios": [float(x) if x else None for x in c[4:4 + nruns]],
                     "costs": None if not costs[0] else tuple(float(x) for x in costs)})
    return rows, meta


def ratio_table(rows):
    """Markdown: one row per (case, backend, reference), one ratio column per run."""
    nruns = len(rows[0]["ratios"]) if rows else 0
    head = "| case | ours | reference | " + " | ".join(f"run {i + 1}" for i in range(nruns)) + " | fixed s (ours / ref) | ms per spp (ours / ref) |"
    out = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        cells = ["–" if x is None else f"{x:.2f}" for x in r["ratios"]]
        c = r["costs"]
        fits = "– | –" if c is None else f"{c[0]:.3f} / {c[1]:.3f} | {c[2]:.2f} / {c[3]:.2f}"
        out.append(f"| {r['case']} | {r['backend']} | {r['reference']} | " + " | ".join(cells) + f" | {fits} |")
    return "\n".join(out)


def headline_table(rows, meta, goal=0.5):
    """The README's table: native ÷ Cycles and ÷ Mitsuba per case, the worst of the runs
    (`-H` rows aside), and how many rows of every backend meet the goal."""
    cases = list(dict.fromkeys(r["case"] for r in rows if not r["hemisphere"]))
    worst = lambda r: max(x for x in r["ratios"] if x is not None) if any(x is not None for x in r["ratios"]) else None
    cell = lambda case, ref: next((f"{worst(r):.2f}" for r in rows if r["case"] == case and r["backend"] == "native" and r["reference"] == ref and worst(r) is not None), "–")
    out = [f"Equal-time relMSE, ours (native backend) ÷ reference, below 1 is better; {runs_words(meta)} "
           f"(`validation/speed_vs_error.py`). {provenance_line(meta)}", "",
           "| case | integrator | ÷ Cycles 3.4 | ÷ Mitsuba 3 |", "|---|---|---:|---:|"]
    out += [f"| {case_name(c)} | {integrator(c)} | {cell(c, 'cycles')} | {cell(c, 'mitsuba')} |" for c in cases]
    rated = [r for r in rows if not r["hemisphere"] and worst(r) is not None]
    every = " in every run" if int(meta["runs"]) > 1 else ""
    out += ["", f"{sum(1 for r in rated if worst(r) <= goal)} of {len(rated)} rows at or below {goal}{every}."]
    return "\n".join(out)


def runs_words(meta, worse=True):
    """"one full-tier run", or "the worse of 2 full-tier runs" ("2 full-tier runs" with
    `worse` false)."""
    n = int(meta["runs"])
    if n == 1:
        return f"one {meta['tier']}-tier run"
    return f"{'the worse of ' if worse else ''}{n} {meta['tier']}-tier runs"


def provenance_line(meta):
    """The sentence every generated table carries (validation/provenance.py)."""
    return f"Measured {meta['date']} at commit {meta['commit']} on {meta['cpu']}."


BDPT_TAGS = {"_specular_bdpt": "BDPT, specular light paths", "_light_bdpt": "light tracing", "_lens_bdpt": "BDPT", "_env_bdpt": "BDPT", "_bdpt": "BDPT"}


def integrator(case):
    """The integrator a case's tag names (the path tracer without one)."""
    return next((name for tag, name in BDPT_TAGS.items() if case.endswith(tag)), "path")


def case_name(case):
    """The case without its integrator tag (the lens and environment tags stay as words)."""
    for tag in BDPT_TAGS:
        if case.endswith(tag):
            rest = case[: -len(tag)]
            return rest + {"_lens_bdpt": "_lens", "_env_bdpt": "_env"}.get(tag, "")
    return case


def paste(path, name, text):
    """Replace the text between `<!-- NAME:start -->` and `<!-- NAME:end -->` in `path`."""
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    with open(path) as f:
        doc = f.read()
    if start not in doc or end not in doc:
        sys.exit(f"speed_vs_error: {path}: the {name} markers are missing")
    head, rest = doc.split(start, 1)
    _, tail = rest.split(end, 1)
    with open(path, "w") as f:
        f.write(head + start + "\n" + text.strip() + "\n" + end + tail)
    print(f"{path}: {name} table updated")


def agreement(rows, tolerance=0.2, goal=0.5):
    """Markdown lines: how many rows (the `-H` ones aside: the naive estimator on purpose)
    agree between every pair of runs within `tolerance` (max ratio ÷ min ratio <= 1 +
    tolerance), the ones that do not, and the rows above `goal` in any run, unrounded."""
    table = {(r["case"], r["backend"], r["reference"]): r["ratios"] for r in rows if not r["hemisphere"]}
    both = {k: v for k, v in table.items() if all(x is not None for x in v)}
    apart = {k: max(v) / min(v) for k, v in both.items() if max(v) > (1 + tolerance) * min(v)}
    fmt = lambda k, v: f"{k[0]} {k[1]} ÷ {k[2]} " + " / ".join("–" if x is None else f"{x:.3f}" for x in v)
    out = [f"{len(both) - len(apart)} of {len(both)} rows (`-H` aside) agree between the runs within {100 * tolerance:.0f} %."]
    out += [f"* apart by {f:.2f}×: {fmt(k, both[k])}" for k, f in sorted(apart.items(), key=lambda kv: -kv[1])]
    above = {k: v for k, v in table.items() if any(x is not None and x > goal for x in v)}
    out.append(f"{len(above)} rows above {goal} in some run" + (":" if above else "."))
    out += [f"* {fmt(k, v)}" for k, v in sorted(above.items(), key=lambda kv: -max(x or 0 for x in kv[1]))]
    return "\n".join(out)


def svg(rows, cases, width=330, height=240, colours=COLOURS):
    """Small multiples: one log-log panel per case, relMSE against sample time; `colours`
    names the series (backends and references) and their colours, for the legend."""
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
    for i, (name, col) in enumerate(colours.items()):
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
            parts.append(f'<polyline points="{line}" fill="none" stroke="{colours.get(name, "#333")}" stroke-width="2"/>')
    parts.append("</svg>")
    return "\n".join(parts)


ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("summaries", nargs="*")
    ap.add_argument("--from-csv", help="take the runs from this CSV (written by --csv) instead of summary.json files")
    ap.add_argument("--svg", help="write the plot here")
    ap.add_argument("--cases", default="", help="comma-separated cases to plot (default: every case of the first run)")
    ap.add_argument("--markdown", help="write the table here (default: print it)")
    ap.add_argument("--csv", help="write the runs' ratios, costs, date, commit and CPU here")
    ap.add_argument("--paste", action="store_true", help="paste the tables into docs/validation/speed-vs-error.md and README.md")
    args = ap.parse_args()
    if bool(args.summaries) == bool(args.from_csv):
        sys.exit("speed_vs_error: give summary.json files or --from-csv FILE (one of the two)")
    if args.from_csv:
        rows, meta = read_csv(args.from_csv)
        runs = []
    else:
        runs = []
        for p in args.summaries:
            s, r = load(p)
            s["_paths"] = args.summaries
            runs.append((s, r))
        rows, meta = table_rows(runs), provenance(runs)
    table = ratio_table(rows)
    if len(rows[0]["ratios"]) > 1:
        table += "\n\n" + agreement(rows)
    if args.csv:
        write_csv(args.csv, rows, meta)
    if args.paste:
        intro = (f"{runs_words(meta, worse=False).capitalize()}. {provenance_line(meta)} "
                 "Equal-time relMSE ratio ours ÷ reference (below 0.5 is the goal; `-H` rows are the naive estimator on purpose), "
                 "with the fixed and per-spp costs of the last run (`validation/speed_vs_error.py`):")
        paste(os.path.join(ROOT, "docs", "validation", "speed-vs-error.md"), "speed-vs-error", intro + "\n\n" + table)
        paste(os.path.join(ROOT, "README.md"), "speed-vs-error", headline_table(rows, meta))
    elif args.markdown:
        with open(args.markdown, "w") as f:
            f.write(table + "\n")
    else:
        print(table)
    if args.svg:
        if not runs:
            sys.exit("speed_vs_error: --svg needs the summary.json files (the CSV has no curves)")
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
