#!/usr/bin/env python3
"""The README's headline benchmark table, from the bench's own CSV (docs/benchmarks/bench.csv):
per scene, native's throughput ÷ each other contender's at 1 thread and at the run's most
threads, for camera, shadow, random and diffuse rays traced as batches (each other contender's
column the worst of those cells), with the run's date, commit and CPU from the first
line of docs/benchmarks/bench.md. Pasted between the README's bench markers by
scripts/bench-readme.sh; prints the table without --paste.

  scripts/bench-summary.py [--paste]
"""
import csv
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RAYS = ["camera", "shadow", "random", "diffuse"]


def main():
    rows = list(csv.DictReader(open(os.path.join(ROOT, "docs", "benchmarks", "bench.csv"))))
    bench_md = open(os.path.join(ROOT, "docs", "benchmarks", "bench.md")).read().splitlines()
    run = next((l for l in bench_md if l.startswith("Measured ")), "Measured at an unknown date and commit.")
    speed = {(r["scene"], r["rays"], int(r["threads"]), r["backend"]): float(r["mrays_per_s"]) for r in rows}
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    threads = sorted({int(r["threads"]) for r in rows})
    lo, hi = threads[0], threads[-1]
    peers = [b for b in dict.fromkeys(r["backend"] for r in rows) if b not in ("native", "brute")]

    def ratio(scene, rays, t, other):
        a, b = speed.get((scene, rays, t, "native")), speed.get((scene, rays, t, other))
        return a / b if a and b else None

    def cell(scene, rays, other):
        r = [ratio(scene, rays, t, other) for t in (lo, hi)]
        return " / ".join("–" if x is None else f"{x:.2f}" for x in r)

    main_peer = "embree" if "embree" in peers else (peers[0] if peers else None)
    others = [p for p in peers if p != main_peer]

    def worst(scene, other):
        r = [ratio(scene, k, t, other) for k in RAYS for t in (lo, hi)]
        r = [x for x in r if x is not None]
        return f"{min(r):.2f}" if r else "–"

    out = [f"Native's ray throughput ÷ each contender's on the same rays (above 1: native is faster), at {lo} / {hi} "
           f"threads, from one `pathtracer bench` run (`scripts/bench-readme.sh`), rays traced as batches; a "
           f"\"(worst)\" column is the lowest of that contender's {len(RAYS)} kinds at either thread count, and the "
           f"one-ray-a-call cells are in bench.md. {run}", ""]
    head = "| scene | " + " | ".join(f"÷ {main_peer}: {k}" if i == 0 else k for i, k in enumerate(RAYS)) + "".join(f" | ÷ {o} (worst)" for o in others) + " |"
    out += [head, "|---|" + "---:|" * (len(RAYS) + len(others))]
    out += [f"| {s} | " + " | ".join(cell(s, k, main_peer) for k in RAYS) + "".join(f" | {worst(s, o)}" for o in others) + " |"
            for s in scenes if any(ratio(s, k, lo, main_peer) for k in RAYS)]
    text = "\n".join(out).strip() + "\n\nEvery table of the run (builds, memory, SAH costs, renders): [docs/benchmarks/bench.md](docs/benchmarks/bench.md)."
    if "--paste" in sys.argv:
        path = os.path.join(ROOT, "README.md")
        doc = open(path).read()
        start, end = "<!-- bench:start (scripts/bench-readme.sh writes this part) -->", "<!-- bench:end -->"
        if start not in doc or end not in doc:
            sys.exit("bench-summary: README.md: bench markers missing")
        head, rest = doc.split(start, 1)
        _, tail = rest.split(end, 1)
        open(path, "w").write(head + start + "\n" + text + "\n" + end + tail)
        print("README.md: bench summary updated from docs/benchmarks/bench.csv")
    else:
        print(text)


if __name__ == "__main__":
    main()
