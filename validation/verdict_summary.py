#!/usr/bin/env python3
"""The harness's verdicts in a few lines, from a run's summary.json: per reference and backend,
how many comparisons passed, and which did not (with the statistic that failed). Pasted between
the verdicts markers of README.md and docs/validation/README.md with --paste; printed otherwise.

  validation/verdict_summary.py [validation/out/summary.json] [--paste]
"""
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
KINDS = {"radiance": "images", "geometry": "intersections", "adaptive": "adaptive images", "adaptive_bias": "stopping-rule bias"}


def summarize(s):
    results = [r for r in s["results"] if "refused" not in r or r.get("kind") == "geometry"]
    refused = sorted({(r["case"], r["reference"]) for r in s["results"] if r.get("refused") and r.get("kind") == "radiance"})
    refs = list(dict.fromkeys(r["reference"] for r in results))
    backends = [b for b in s.get("backends", []) if any(r.get("backend") == b for r in results)]
    out = [f"The harness's {s['tier']} tier (`validation/run {s['tier']}`, summarised by `validation/verdict_summary.py`): "
           f"comparisons passed of those made. Measured {s.get('date', '?')} at commit {s.get('commit', '?')} on {s.get('cpu', '?')}.", ""]
    out += ["| reference | " + " | ".join(backends) + " |", "|---|" + "---:|" * len(backends)]
    for ref in refs:
        cells = []
        for b in backends:
            rs = [r for r in results if r["reference"] == ref and r.get("backend") == b]
            cells.append(f"{sum(1 for r in rs if r['passed'])} of {len(rs)}" if rs else "–")
        out.append(f"| {ref} | " + " | ".join(cells) + " |")
    failed = [r for r in results if not r["passed"]]
    out.append("")
    if failed:
        out.append("Not passed:")
        for r in failed:
            why = f"global t {r['global_z']:+.2f}" if "global_z" in r else r.get("summary", "")
            out.append(f"* {r['case']} ({r.get('backend', '-')}) against {r['reference']}: {why}")
    else:
        out.append("Every comparison passed.")
    if refused:
        out.append(f"Refused by the reference's exporter (it cannot represent the scene exactly): "
                   + ", ".join(f"{c} ({ref})" for c, ref in refused) + ".")
    return "\n".join(out)


def paste(path, text):
    start, end = "<!-- verdicts:start -->", "<!-- verdicts:end -->"
    doc = open(path).read()
    if start not in doc or end not in doc:
        sys.exit(f"verdict_summary: {path}: the verdicts markers are missing")
    head, rest = doc.split(start, 1)
    _, tail = rest.split(end, 1)
    open(path, "w").write(head + start + "\n" + text + "\n" + end + tail)
    print(f"{path}: verdicts updated")


def main():
    args = [a for a in sys.argv[1:] if a != "--paste"]
    path = args[0] if args else os.path.join(HERE, "out", "summary.json")
    with open(path) as f:
        text = summarize(json.load(f))
    if "--paste" in sys.argv:
        paste(os.path.join(ROOT, "README.md"), text)
        paste(os.path.join(ROOT, "docs", "validation", "README.md"), text)
    else:
        print(text)


if __name__ == "__main__":
    main()
