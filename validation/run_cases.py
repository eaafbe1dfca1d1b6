#!/usr/bin/env python3
"""The validation harness driver: export each case's scene from our loader, render it with
both of our backends and with Mitsuba 3, and write statistical verdicts to
validation/out/summary.json and validation/out/report.html.

Quick tier: small images, few cases. References are cached under validation/out/cache by a
hash of the exported scene and the render settings.
"""
import argparse
import hashlib
import html
import json
import os
import shutil
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
import stats  # noqa: E402

TIERS = {
    # name: (width, height, our spp, reference spp per render, reference renders, cases)
    "quick": (64, 48, 256, 128, 16, [("CBspheres_lambertian", None, 1), ("CBspheres_lambertian", None, 5), ("CBempty", "CBempty.dae", 3)]),
    "full": (256, 192, 1024, 512, 16, [("CBspheres_lambertian", None, 1), ("CBspheres_lambertian", None, 5), ("CBempty", "CBempty.dae", 3), ("CBbunny", "CBbunny.dae", 5)]),
}


def find_scene(name):
    if name is None:
        return None
    for d in [os.path.join(ROOT, "scenes"), os.path.join(ROOT, "..", "shared", "scenes", "cs184", "sky")]:
        p = os.path.join(d, name)
        if os.path.exists(p):
            return p
    sys.exit(f"run_cases: scene {name} not found")


def sh(cmd, **kw):
    r = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if r.returncode != 0:
        sys.exit(f"run_cases: {' '.join(cmd)} failed:\n{r.stdout}{r.stderr}")
    return r.stdout


def read_exr(path):
    import mitsuba as mi

    return np.array(mi.Bitmap(path), dtype=np.float64)


def write_png(path, img):
    """CS184's tone step, to compare images by eye."""
    import mitsuba as mi

    c = np.clip(np.power(np.maximum(img, 0) * np.sqrt(2.0), 1 / 2.2), 0, 1)
    mi.Bitmap((c * 255).astype(np.uint8), pixel_format=mi.Bitmap.PixelFormat.RGB).write(path)


def write_zmap(path, z):
    """Blue (z <= -4) .. white (0) .. red (z >= 4), per pixel the worst channel."""
    import mitsuba as mi

    zz = z[..., np.argmax(np.abs(z), axis=-1)] if False else np.take_along_axis(z, np.argmax(np.abs(z), axis=-1)[..., None], -1)[..., 0]
    t = np.clip(zz / 4.0, -1, 1)
    rgb = np.stack([1 - np.clip(-t, 0, 1), 1 - np.abs(t), 1 - np.clip(t, 0, 1)], -1)
    mi.Bitmap((rgb * 255).astype(np.uint8), pixel_format=mi.Bitmap.PixelFormat.RGB).write(path)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("tier", choices=sorted(TIERS))
    ap.add_argument("--pathtracer", default=os.path.join(ROOT, "target", "release", "pathtracer"))
    ap.add_argument("--out", default=os.path.join(HERE, "out"))
    args = ap.parse_args()
    w, h, spp, ref_spp, ref_renders, cases = TIERS[args.tier]
    out = args.out
    os.makedirs(os.path.join(out, "cache"), exist_ok=True)
    backends = ["native"]
    info = sh([args.pathtracer, "--version"])
    probe = subprocess.run([args.pathtracer, "--backend", "embree", "-r", "4", "3", "-s", "1", "-f", os.path.join(out, "probe.png")], capture_output=True, text=True)
    if probe.returncode == 0:
        backends.append("embree")
    else:
        print(f"run_cases: embree backend unavailable ({probe.stderr.strip()}); native only", file=sys.stderr)
    for f in ("probe.png", "probe_rate.png"):
        if os.path.exists(os.path.join(out, f)):
            os.remove(os.path.join(out, f))
    results = []
    for name, file, m in cases:
        case = f"{name}_m{m}"
        folder = os.path.join(out, case)
        if os.path.exists(folder):
            shutil.rmtree(folder)
        os.makedirs(folder)
        scene_args = [find_scene(file)] if file else []
        view = ["-r", str(w), str(h), "--keep-fov"]
        sh([args.pathtracer, "export", *scene_args, *view, "--out", os.path.join(folder, "scene")])
        with open(os.path.join(folder, "scene", "scene.json"), "rb") as f:
            key = hashlib.sha256(f.read() + b"".join(open(os.path.join(folder, "scene", p), "rb").read() for p in sorted(os.listdir(os.path.join(folder, "scene"))) if p.endswith(".obj"))).hexdigest()[:16]
        ref = os.path.join(out, "cache", f"mitsuba_{key}_m{m}_{ref_spp}x{ref_renders}")
        if not os.path.exists(ref + ".exr"):
            sh([sys.executable, os.path.join(HERE, "mitsuba_ref.py"), os.path.join(folder, "scene"), "--max-depth", str(m), "--spp", str(ref_spp), "--renders", str(ref_renders), "--out", ref])
        r, var_r = read_exr(ref + ".exr"), read_exr(ref + "_var.exr")
        with open(ref + ".json") as f:
            ref_meta = json.load(f)
        write_png(os.path.join(folder, "mitsuba.png"), r)
        for backend in backends:
            exr = os.path.join(folder, f"{backend}.exr")
            var = os.path.join(folder, f"{backend}_var.exr")
            t0 = time.time()
            sh([args.pathtracer, *scene_args, *view, "-s", str(spp), "-m", str(m), "--backend", backend, "--seed", "7", "-f", os.path.join(folder, f"{backend}.png"), "--exr", exr, "--variance-exr", var])
            seconds = time.time() - t0
            x, var_x = read_exr(exr), read_exr(var)
            v = stats.verdict(x, var_x, r, var_r)
            write_zmap(os.path.join(folder, f"{backend}_z.png"), v.pop("z_image"))
            v.update({"case": case, "scene": name, "max_depth": m, "backend": backend, "reference": ref_meta["renderer"], "spp": spp, "seconds": seconds, "reference_spp": ref_meta["spp"], "reference_seconds": ref_meta["seconds"], "size": [w, h]})
            results.append(v)
            print(f"{case} {backend} vs mitsuba: {'PASS' if v['passed'] else 'FAIL'} pixels {v['pass_fraction']*100:.2f}% global z {v['global_z']:+.2f} relMSE {v['rel_mse']:.2e}")
    summary = {"tier": args.tier, "pathtracer": info.strip(), "results": results, "all_passed": all(r["passed"] for r in results)}
    with open(os.path.join(out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    write_report(out, summary)
    print(f"wrote {os.path.join(out, 'report.html')} and summary.json: {'all passed' if summary['all_passed'] else 'FAILURES'}")
    sys.exit(0 if summary["all_passed"] else 1)


def write_report(out, summary):
    rows = []
    for r in summary["results"]:
        c = r["case"]
        rows.append(
            "<tr><td>{case}</td><td>{backend}</td><td>{ref}</td><td class='{cls}'>{verdict}</td><td>{pf:.2f} %</td><td>{gz:+.2f}</td>"
            "<td>{rd:+.3f} %</td><td>{rm:.2e}</td><td>{sm:.4f}</td><td>{t:.1f} s</td>"
            "<td><img src='{c}/{backend}.png'></td><td><img src='{c}/mitsuba.png'></td><td><img src='{c}/{backend}_z.png'></td></tr>".format(
                case=html.escape(c), backend=r["backend"], ref=html.escape(r["reference"]), cls="pass" if r["passed"] else "fail",
                verdict="pass" if r["passed"] else "FAIL", pf=100 * r["pass_fraction"], gz=r["global_z"], rd=100 * (r["relative_mean_difference"] or 0),
                rm=r["rel_mse"], sm=r["smape"], t=r["seconds"], c=html.escape(c)))
    doc = f"""<!doctype html><html><head><meta charset="utf-8"><title>pathtracer validation ({summary['tier']})</title>
<style>body{{font-family:sans-serif}} table{{border-collapse:collapse}} td,th{{border:1px solid #999;padding:3px 6px;text-align:right}}
img{{width:128px;image-rendering:pixelated}} .pass{{background:#cfc}} .fail{{background:#fcc}}</style></head><body>
<h1>pathtracer validation: {summary['tier']} tier</h1>
<p>{html.escape(summary['pathtracer'])}. Verdict: per pixel-channel Welch z-test (alpha 0.01, Šidák), pass at &ge; 99.75 % of
pixel-channels, plus a global mean test (|Z| &le; 2.58). z-map: blue z &le; -4, white 0, red z &ge; 4.</p>
<table id="verdicts"><tr><th>case</th><th>backend</th><th>reference</th><th>verdict</th><th>pixels passing</th><th>global Z</th><th>mean diff</th>
<th>relMSE</th><th>SMAPE</th><th>our time</th><th>ours</th><th>reference</th><th>z-map</th></tr>
{''.join(rows)}</table></body></html>"""
    with open(os.path.join(out, "report.html"), "w") as f:
        f.write(doc)


if __name__ == "__main__":
    main()
