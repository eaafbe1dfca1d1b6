#!/usr/bin/env python3
"""An environment map's light on a flat diffuse square against its closed form, in our renderer
and in each reference: which renderer's map lighting is off, if any.

Scene (written here as CS184 COLLADA from scenes/cs184/sky/CBspheres_lambertian.dae, whose
camera and lambertian material it keeps): a 0.6 m square of two triangles, albedo 0.8, facing
the camera at 45 degrees, alone under the map, rendered at -m 1 (direct light only). Every point
of the square sees the whole sky above its plane and nothing else, so its radiance is

    albedo / pi * integral of L(w) max(0, n.w) dw

over the map's bilinear lookup (texel centres at half-integers, wrapping in u, clamped in v:
the renderer's own model), integrated by a midpoint rule at S x S points per texel (S = 2, 4,
8 printed: the sum has converged when they agree). The harness (`run_cases.py full --scene`)
renders the square with ours and each reference from the same export (Cycles, whose exporter
refuses environment maps because of this study, from the same export with --environment-map
at the tier's reference sampling); this compares the
central block of each image (pixels well inside the square) with the closed form, per channel,
as (image / closed form - 1) +- its standard error, in parts in 10^4.

Measured 2026-11-29 at commit 0acbeac on 2-vCPU AMD EPYC (studio.exr): ours +1.4 / +1.4 / +1.4
+- 0.7, Mitsuba 3 +6.1 / +5.8 / +5.5 +- 3.1, Cycles 3.4 -4.4 / -2.7 / +1.8 +- 0.7 in R / G / B
(docs/validation/speed-vs-error.md, "Verdicts").

  validation/env_study.py [--map scenes/envmaps/studio.exr] [--out validation/out/env_study]
"""
import argparse
import glob
import json
import os
import re
import shutil
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
from cases import TIERS  # noqa: E402
from images import read_exr  # noqa: E402
from run_cases import cycles_ref_command  # noqa: E402

# The block of pixels inside the square at the harness's 256x192 (rows, columns).
BLOCK = (slice(70, 120), slice(90, 166))


def write_square(path):
    """The square as COLLADA: CBspheres_lambertian's camera and materials, its spheres replaced
    by two triangles (file coordinates: z up, the camera looking along -y)."""
    s = open(os.path.join(ROOT, "scenes", "cs184", "sky", "CBspheres_lambertian.dae")).read()
    n = np.array([0.0, 1.0, 1.0]) / np.sqrt(2.0)
    e1, e2 = np.array([1.0, 0.0, 0.0]), np.array([0.0, -1.0, 1.0]) / np.sqrt(2.0)
    corners = [u * 0.3 * e1 + v * 0.3 * e2 for u, v in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    pos = " ".join(f"{x:.9g}" for c in corners for x in c)
    geom = (f'<geometry id="Sphere1-data" name="Square"><mesh>'
            f'<source id="S-pos"><float_array id="S-pos-array" count="12">{pos}</float_array><technique_common><accessor source="#S-pos-array" count="4" stride="3">'
            '<param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/></accessor></technique_common></source>'
            f'<source id="S-nrm"><float_array id="S-nrm-array" count="3">{n[0]:.9g} {n[1]:.9g} {n[2]:.9g}</float_array><technique_common><accessor source="#S-nrm-array" count="1" stride="3">'
            '<param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/></accessor></technique_common></source>'
            '<vertices id="S-vtx"><input semantic="POSITION" source="#S-pos"/></vertices>'
            '<polylist material="lambertian" count="2"><input semantic="VERTEX" source="#S-vtx" offset="0"/><input semantic="NORMAL" source="#S-nrm" offset="1"/>'
            '<vcount>3 3</vcount><p>0 0 1 0 2 0 0 0 2 0 3 0</p></polylist></mesh></geometry>')
    s = re.sub(r'<geometry id="Sphere1-data".*?</geometry>', geom, s, count=1, flags=re.S)
    s = re.sub(r'<geometry id="Sphere2-data".*?</geometry>', "", s, count=1, flags=re.S)
    i, j = s.index("<visual_scene"), s.index("</visual_scene>")
    body = s[i:j]
    nodes = list(re.finditer(r'<node id="([^"]+)".*?</node>', body, re.S))
    for m in nodes:
        if m.group(1) not in ("Sphere2", "Camera"):
            body = body.replace(m.group(0), "")
    nodes = [m.group(1) for m in nodes]
    body = body.replace("1 0 0 0.4 0 1 0 -0.3 0 0 1 0.3 0 0 0 1", "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1")
    assert "Sphere2" in nodes and "Camera" in nodes, "the template's nodes changed"
    with open(path, "w") as f:
        f.write(s[:i] + body + s[j:])


def bilerp(env, x, y):
    h, w = env.shape[:2]
    fx, fy = x - 0.5, y - 0.5
    i0, j0 = np.floor(fx), np.floor(fy)
    tx, ty = (fx - i0)[..., None], (fy - j0)[..., None]
    i0, j0 = i0.astype(np.int64), j0.astype(np.int64)
    i1, j1 = (i0 + 1) % w, np.clip(j0 + 1, 0, h - 1)
    i0, j0 = i0 % w, np.clip(j0, 0, h - 1)
    return (env[j0, i0] * (1 - tx) + env[j0, i1] * tx) * (1 - ty) + (env[j1, i0] * (1 - tx) + env[j1, i1] * tx) * ty


def irradiance(env, n, s):
    """integral of L(w) max(0, n.w) dw, midpoint rule at s x s points per texel."""
    h, w = env.shape[:2]
    xs = (np.arange(w * s) + 0.5) / s
    e = np.zeros(3)
    for ys in np.array_split((np.arange(h * s) + 0.5) / s, 8 * s):
        x, y = np.meshgrid(xs, ys)
        th, psi = y / h * np.pi, x / w * 2 * np.pi - np.pi
        d = np.stack([np.sin(th) * np.cos(psi), np.cos(th), -np.sin(th) * np.sin(psi)], -1)
        c = np.maximum(d @ n, 0) * np.sin(th) * (2 * np.pi / (w * s)) * (np.pi / (h * s))
        e += (bilerp(env, x, y) * c[..., None]).sum((0, 1))
    return e


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--map", default=os.path.join(ROOT, "scenes", "envmaps", "studio.exr"))
    ap.add_argument("--out", default=os.path.join(HERE, "out", "env_study"))
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    dae = os.path.join(args.out, "square.dae")
    write_square(dae)
    run = os.path.join(args.out, "run")
    r = subprocess.run([sys.executable, os.path.join(HERE, "run_cases.py"), "full", "--scene", dae, "-m", "1", "--scene-flags", f"-e {os.path.abspath(args.map)}",
                        "--backends", "native", "--out", run])
    if not os.path.exists(os.path.join(run, "summary.json")):
        sys.exit(f"env_study: the harness wrote no summary (exit {r.returncode})")
    case = os.path.join(run, "square_m1")
    spec = json.load(open(os.path.join(case, "scene", "scene.json")))
    env = np.maximum(read_exr(os.path.join(case, "scene", "environment.exr")).astype(np.float64), 0)
    obj = open(os.path.join(case, "scene", "mesh_0.obj")).read().splitlines()
    normal = next(np.array(l.split()[1:4], float) for l in obj if l.startswith("vn "))
    centre = np.mean([np.array(l.split()[1:4], float) for l in obj if l.startswith("v ")], axis=0)
    # The side the camera sees (the square reflects from both sides).
    if normal @ (np.array(spec["camera"]["origin"]) - centre) < 0:
        normal = -normal
    albedo = np.array(spec["shapes"][0]["albedo"])
    closed = None
    for s in (2, 4, 8):
        closed = albedo / np.pi * irradiance(env, normal / np.linalg.norm(normal), s)
        print(f"closed form, {s}x{s} points per texel: {closed}")

    def line(name, m, se):
        print(f"{name:8s} " + "  ".join(f"{(m[c] / closed[c] - 1) * 1e4:+6.2f} +- {se[c] / closed[c] * 1e4:4.2f}" for c in range(3)) + "   (x 1e-4, R G B)")

    def report(name, images):
        means = np.array([i[BLOCK].mean((0, 1)) for i in images])
        line(name, means.mean(0), means.std(0, ddof=1) / np.sqrt(len(means)))

    report("ours", [read_exr(f) for f in sorted(glob.glob(os.path.join(case, "native_img_b*[0-9].exr")))])
    cache = os.path.join(run, "cache")
    # The harness's Cycles exporter refuses environment maps (this study is why); rendered
    # here anyway, from the same export at the tier's reference sampling.
    blender = shutil.which("blender")
    if blender:
        t = TIERS["full"]
        prefix = os.path.join(run, "cycles_environment_map")
        subprocess.run(cycles_ref_command(blender, os.path.join(case, "scene"), "--mode", "radiance", "--environment-map", "--max-depth", "1",
                                          "--spp", str(t["ref_spp"]), "--renders", str(t["ref_renders"]), "--out", prefix), check=True, capture_output=True)
        with open(prefix + "_cycles.json") as f:
            report("cycles", [read_exr(r["file"]) for r in json.load(f)["renders"]])
    else:
        print("cycles   not installed (validation/setup installs Debian's blender)")
    for f in glob.glob(os.path.join(cache, "mitsuba_*_m1_*[0-9].exr")):
        mean, var = read_exr(f)[BLOCK], read_exr(f[:-4] + "_var.exr")[BLOCK]
        # The pixels' variances of the mean, summed: pixels of independent samples.
        line("mitsuba", mean.mean((0, 1)), np.sqrt(var.sum((0, 1))) / (mean.shape[0] * mean.shape[1]))


if __name__ == "__main__":
    main()
