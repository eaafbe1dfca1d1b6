#!/usr/bin/env python3
"""Bidirectional path tracing against our path tracer at equal render time, over the whole
image and over a region (a caustic): the harness's error-against-time measure
(metrics.ladder_curve: the variance part of relMSE from independent renders per rung, fixed
costs fitted out) for both integrators on the same scene, then relMSE(bdpt) / relMSE(path)
interpolated at equal time (metrics.equal_time_ratio).

  validation/bdpt_vs_path.py SCENE.dae -m 5 [--size 128 96] [--ladder 4,16,64] [--seeds 6]
      [--region X Y W H [--region ...]] [--region-names A,B] [--integrators path,bdpt[,bdpt:specular]]
      [--threads N] [--backend native]
      [--csv FILE.csv] [--curves FILE.json] [--svg FILE.svg]

Prints one table row per integrator pair; --csv appends the rows (with date, commit and CPU);
--curves appends both curves of every row to a JSON list, and --svg plots every curve in that
list (one log-log panel per scene and pixel set: relMSE against sample time).
An integrator "bdpt:specular" is --integrator bdpt --bdpt-light-paths specular.
A region is in image pixels, (0, 0) at the top left, as the EXR rows run; each is named in the
table, the CSV's `pixels` column and the curves by --region-names (default: region, region2, ...).
"""
import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from images import read_exr  # noqa: E402
from metrics import equal_time_ratio, ladder_curve  # noqa: E402
from speed_vs_error import svg  # noqa: E402

# The integrators' colours in the plot.
COLOURS = {"path": "#d62728", "bdpt": "#9467bd", "bdpt:specular": "#1f77b4", "light": "#8c564b"}

ROOT = os.path.dirname(HERE)


def cpu_name():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def render(pt, scene, integrator, m, spp, seed, size, threads, backend, out):
    # "bdpt:specular": --integrator bdpt --bdpt-light-paths specular.
    integrator, _, light_paths = integrator.partition(":")
    extra = ["--bdpt-light-paths", light_paths] if light_paths else []
    cmd = [pt, scene, "--integrator", integrator, *extra, "-m", str(m), "-s", str(spp), "--seed", str(seed), "-r", str(size[0]), str(size[1]),
           "--keep-fov", "-t", str(threads), "--backend", backend, "-f", out + ".png", "--exr", out + ".exr"]
    text = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    seconds = float(text.split("| render ")[1].split(" s")[0])
    return seconds, read_exr(out + ".exr")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scene")
    ap.add_argument("-m", type=int, default=5)
    ap.add_argument("--size", type=int, nargs=2, default=[128, 96])
    ap.add_argument("--ladder", default="4,16,64")
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--region", type=int, nargs=4, action="append", default=[], metavar=("X", "Y", "W", "H"))
    ap.add_argument("--region-names", default="", help="comma-separated names of the regions, in order")
    ap.add_argument("--integrators", default="path,bdpt")
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--backend", default="native")
    ap.add_argument("--pathtracer", default=os.path.join(ROOT, "target", "release", "pathtracer"))
    ap.add_argument("--csv", default="")
    ap.add_argument("--curves", default="", help="append every row's two curves to this JSON list")
    ap.add_argument("--svg", default="", help="with --curves: plot every curve of that list here")
    a = ap.parse_args()
    names = [n for n in a.region_names.split(",") if n] or ["region" if i == 0 else f"region{i + 1}" for i in range(len(a.region))]
    if len(names) != len(a.region):
        sys.exit(f"bdpt_vs_path: {len(a.region)} regions but {len(names)} names in --region-names")
    ladder = [int(x) for x in a.ladder.split(",")]
    integrators = a.integrators.split(",")
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for integ in integrators:
            runs[integ] = []
            for n in ladder:
                for k in range(a.seeds):
                    sec, img = render(a.pathtracer, a.scene, integ, a.m, n, 1000 + 7919 * k + n, a.size, a.threads, a.backend, os.path.join(tmp, f"{integ}_{n}_{k}"))
                    runs[integ].append((n, sec, img))
    # The normalisation image: the mean of every render at the largest rung, all integrators.
    top = max(ladder)
    ref = np.mean([img for integ in integrators for n, _, img in runs[integ] if n == top], axis=0)
    masks = {"image": np.ones(ref.shape[:2], dtype=bool)}
    for (x, y, w, h), region_name in zip(a.region, names):
        r = np.zeros(ref.shape[:2], dtype=bool)
        r[y:y + h, x:x + w] = True
        masks[region_name] = r
    name = os.path.splitext(os.path.basename(a.scene))[0]
    base = integrators[0]
    rows = []
    curve_rows = []
    for where, mask in masks.items():
        curves = {i: ladder_curve([(n, s, img[mask]) for n, s, img in runs[i]], ref[mask]) for i in integrators}
        for integ in integrators[1:]:
            eq = equal_time_ratio(curves[integ]["curve"], curves[base]["curve"])
            per_spp = {i: curves[i]["fit"]["seconds_per_spp"] for i in (base, integ)}
            rows.append((name, a.m, where, integ, base, eq["ratio"] if eq else float("nan"), eq["seconds"] if eq else float("nan"), per_spp[integ] / per_spp[base]))
            curve_rows.append({"case": f"{name} -m {a.m}, {where}", "backend": integ, "curve": curves[integ]["curve"], "reference": base,
                               "reference_curve": curves[base]["curve"], "date": str(datetime.date.today()), "cpu": cpu_name(), "threads": a.threads})
    print(f"{name} -m {a.m}, {a.size[0]}x{a.size[1]}, {a.threads} threads, {a.backend}, ladder {ladder} x {a.seeds} seeds, {cpu_name()}")
    print("| scene | -m | pixels | integrator | against | equal-time relMSE ratio | at seconds | time per sample ratio |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]} | {r[4]} | {r[5]:.3f} | {r[6]:.3f} | {r[7]:.2f} |")
    if a.curves:
        # Rows of the same case replace the older ones.
        old = []
        if os.path.exists(a.curves):
            with open(a.curves) as f:
                old = json.load(f)
        new_cases = {r["case"] for r in curve_rows}
        kept = [r for r in old if r["case"] not in new_cases] + curve_rows
        with open(a.curves, "w") as f:
            json.dump(kept, f, indent=1)
        if a.svg:
            cases = list(dict.fromkeys(r["case"] for r in kept))
            with open(a.svg, "w") as f:
                f.write(svg(kept, cases, colours=COLOURS))
    elif a.svg:
        sys.exit("bdpt_vs_path: --svg plots the curves kept by --curves; give both")
    if a.csv:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT).stdout.strip()
        if subprocess.run(["git", "diff", "--quiet", "HEAD", "--", "src"], cwd=ROOT).returncode != 0:
            commit += "+local changes"
        new = not os.path.exists(a.csv)
        with open(a.csv, "a") as f:
            if new:
                f.write("date,commit,cpu,threads,size,scene,max_depth,pixels,integrator,against,equal_time_rel_mse_ratio,seconds,time_per_sample_ratio\n")
            for r in rows:
                f.write(f"{datetime.date.today()},{commit},\"{cpu_name()}\",{a.threads},{a.size[0]}x{a.size[1]},{r[0]},{r[1]},{r[2]},{r[3]},{r[4]},{r[5]:.4f},{r[6]:.4f},{r[7]:.3f}\n")


if __name__ == "__main__":
    main()
