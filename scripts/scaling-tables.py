#!/usr/bin/env python3
"""The thread-scaling tables of docs/benchmarks/scaling.md, from the raw output of scripts/measure-scaling.sh.

    scripts/scaling-tables.py RUN1_DIR_OR_CSV [RUN2 ...] [--peers PEERS_CSV] [--render RENDER_TXT]

Each RUN is a bench CSV (or a directory holding bench.csv / bench.md) of one
`measure-scaling.sh` run at 1,2,4,8,16 threads (native and Embree). Prints
Markdown: speed-up and 16-thread Mrays/s from the last run; native / Embree
at every thread count, one column per run, so that runs can be compared; the
builds (best of 3, from the bench Markdown); native / obvhs from a peers run;
the renders' seconds per thread count with their md5 check.
"""
import csv
import re
import sys
from pathlib import Path

KINDS = ["camera", "shadow", "random", "diffuse"]


def load(path):
    p = Path(path)
    if p.is_dir():
        p = p / "bench.csv"
    rows = {}
    order = []
    for r in csv.DictReader(open(p)):
        key = (r["scene"], r["rays"], int(r["threads"]), r["backend"])
        rows[key] = float(r["mrays_per_s"])
        if r["scene"] not in order:
            order.append(r["scene"])
    return rows, order


def builds(md_path):
    """scene -> {backend: build ms} from a bench Markdown throughput table."""
    out = {}
    for line in open(md_path):
        m = re.match(r"\| (\S+) \| (\d+) \| (native|embree|obvhs) \| ([0-9.]+) \|", line)
        if m:
            out.setdefault(m.group(1), {})[m.group(3)] = float(m.group(4))
    return out


def main(argv):
    runs, peers, render = [], None, None
    it = iter(argv)
    for a in it:
        if a == "--peers":
            peers = next(it)
        elif a == "--render":
            render = next(it)
        else:
            runs.append(a)
    if not runs:
        raise SystemExit(__doc__)
    data = [load(r) for r in runs]
    last, order = data[-1]
    threads = sorted({k[2] for k in last})
    top = threads[-1]
    print(f"Speed-up {top} threads ÷ 1 thread (Mrays/s at {top} threads), last run:\n")
    print("| scene | " + " | ".join(f"{k} {b}" for k in KINDS for b in ["native", "Embree"]) + " |")
    print("|---|" + "---:|" * 6)
    for s in order:
        cells = []
        for k in KINDS:
            for b in ["native", "embree"]:
                one, many = last.get((s, k, 1, b)), last.get((s, k, top, b))
                cells.append(f"{many / one:.1f}× ({many:.0f})" if one and many else "–")
        print(f"| {s} | " + " | ".join(cells) + " |")
    print(f"\nnative ÷ Embree at {', '.join(map(str, threads))} threads (run " + " / run ".join(str(i + 1) for i in range(len(data))) + "):\n")
    print("| scene | rays | " + " | ".join(f"{t}T" for t in threads) + " |")
    print("|---|---|" + "---:|" * len(threads))
    for s in order:
        for k in KINDS:
            cells = []
            for t in threads:
                rs = []
                for rows, _ in data:
                    n, e = rows.get((s, k, t, "native")), rows.get((s, k, t, "embree"))
                    rs.append(f"{n / e:.2f}" if n and e else "–")
                cells.append(" / ".join(rs))
            print(f"| {s} | {k} | " + " | ".join(cells) + " |")
    mds = [Path(r) / "bench.md" if Path(r).is_dir() else Path(r).with_suffix(".md") for r in runs]
    bs = [builds(m) for m in mds if m.exists()]
    if bs:
        print(f"\nBuild ms on {top} threads, best of 3 (native / Embree), run " + " / run ".join(str(i + 1) for i in range(len(bs))) + ":\n")
        print("| scene | " + " | ".join(f"run {i + 1}" for i in range(len(bs))) + " |")
        print("|---|" + "---|" * len(bs))
        for s in order:
            cells = [f"{b[s]['native']:.1f} / {b[s]['embree']:.1f}" if s in b and "embree" in b[s] else "–" for b in bs]
            print(f"| {s} | " + " | ".join(cells) + " |")
    if peers:
        prow, porder = load(peers)
        pts = sorted({k[2] for k in prow})
        print(f"\nnative ÷ obvhs (and ÷ Embree) from the peers run at {' and '.join(map(str, pts))} threads:\n")
        print("| scene | " + " | ".join(f"{k} {t}T" for k in KINDS for t in pts) + " |")
        print("|---|" + "---:|" * (3 * len(pts)))
        for s in porder:
            cells = []
            for k in KINDS:
                for t in pts:
                    n, o, e = (prow.get((s, k, t, b)) for b in ["native", "obvhs", "embree"])
                    cells.append(f"{n / o:.2f} ({n / e:.2f})" if n and o and e else "–")
            print(f"| {s} | " + " | ".join(cells) + " |")
    if render:
        times, md5s = {}, {}
        for line in open(render):
            m = re.match(r"render (\S+) (\S+) t=(\d+) \| render ([0-9.]+) s .* md5 (\w+)", line)
            if m:
                key = (m.group(1), m.group(2))
                times.setdefault(key, {})[int(m.group(3))] = float(m.group(4))
                md5s.setdefault(key, set()).add(m.group(5))
        if times:
            ts = sorted({t for v in times.values() for t in v})
            print("\nPath-traced renders (480×360, 32 spp, `-m 5`, seed 1), seconds:\n")
            print("| scene | backend | " + " | ".join(f"{t}T" for t in ts) + f" | {ts[-1]}T ÷ 1T | same image at every count |")
            print("|---|---|" + "---:|" * (len(ts) + 1) + "---|")
            for (sc, b), v in times.items():
                sp = v[ts[0]] / v[ts[-1]] if ts[0] in v and ts[-1] in v else float("nan")
                print(f"| {sc} | {b} | " + " | ".join(f"{v[t]:.2f}" if t in v else "–" for t in ts) + f" | {sp:.1f}× | {'yes' if len(md5s[(sc, b)]) == 1 else 'NO'} |")


if __name__ == "__main__":
    main(sys.argv[1:])
