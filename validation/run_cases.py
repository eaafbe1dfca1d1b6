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

BATCHES = 8

TIERS = {
    # name: (width, height, our spp, reference spp per render, reference renders, spp ladder for
    # the error-vs-time curves, cases)
    "quick": (64, 48, 256, 128, 16, [4, 16, 64], [("CBspheres_lambertian", None, 1), ("CBspheres_lambertian", None, 5), ("CBempty", "CBempty.dae", 3)]),
    "full": (256, 192, 1024, 512, 16, [4, 16, 64, 256], [("CBspheres_lambertian", None, 1), ("CBspheres_lambertian", None, 5), ("CBempty", "CBempty.dae", 3), ("CBbunny", "CBbunny.dae", 5)]),
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

    zz = np.take_along_axis(z, np.argmax(np.abs(z), axis=-1)[..., None], -1)[..., 0]
    t = np.clip(zz / 4.0, -1, 1)
    rgb = np.stack([1 - np.clip(-t, 0, 1), 1 - np.abs(t), 1 - np.clip(t, 0, 1)], -1)
    mi.Bitmap((rgb * 255).astype(np.uint8), pixel_format=mi.Bitmap.PixelFormat.RGB).write(path)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("tier", choices=sorted(TIERS))
    ap.add_argument("--pathtracer", default=os.path.join(ROOT, "target", "release", "pathtracer"))
    ap.add_argument("--out", default=os.path.join(HERE, "out"))
    args = ap.parse_args()
    w, h, spp, ref_spp, ref_renders, ladder, cases = TIERS[args.tier]
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
        lad = ",".join(str(n) for n in ladder)
        ref = os.path.join(out, "cache", f"mitsuba_{key}_m{m}_{ref_spp}x{ref_renders}_l{lad.replace(',', '-')}")
        if not os.path.exists(ref + "_ladder.json"):
            sh([sys.executable, os.path.join(HERE, "mitsuba_ref.py"), os.path.join(folder, "scene"), "--max-depth", str(m), "--spp", str(ref_spp), "--renders", str(ref_renders), "--out", ref, "--ladder", lad])
        r, var_r = read_exr(ref + ".exr"), read_exr(ref + "_var.exr")
        with open(ref + ".json") as f:
            ref_meta = json.load(f)
        write_png(os.path.join(folder, "mitsuba.png"), r)
        for backend in backends:
            # Ours as BATCHES independent renders (seeds 7, 8, ...): their mean is the image,
            # the pooled within-render variance gives each pixel's variance of the mean, and
            # the spread of the renders' image means feeds the global test.
            t0 = time.time()
            xs, vs = [], []
            for b in range(BATCHES):
                exr = os.path.join(folder, f"{backend}_b{b}.exr")
                var = os.path.join(folder, f"{backend}_b{b}_var.exr")
                sh([args.pathtracer, *scene_args, *view, "-s", str(spp // BATCHES), "-m", str(m), "--backend", backend, "--seed", str(7 + b), "-f", os.path.join(folder, f"{backend}_b{b}.png"), "--exr", exr, "--variance-exr", var])
                xs.append(read_exr(exr))
                vs.append(read_exr(var))
            seconds = time.time() - t0
            x = np.mean(xs, axis=0)
            var_x = np.mean(vs, axis=0) / BATCHES
            write_png(os.path.join(folder, f"{backend}.png"), x)
            v = stats.verdict(x, var_x, r, var_r, [float(i.mean()) for i in xs], ref_meta["image_means"])
            write_zmap(os.path.join(folder, f"{backend}_z.png"), v.pop("z_image"))
            v.update({"case": case, "scene": name, "max_depth": m, "backend": backend, "reference": ref_meta["renderer"], "spp": spp, "seconds": seconds, "reference_spp": ref_meta["spp"], "reference_seconds": ref_meta["seconds"], "size": [w, h]})
            v["curve"] = error_curve(args.pathtracer, scene_args, view, m, backend, ladder, folder, r)
            results.append(v)
            print(f"{case} {backend} vs mitsuba: {'PASS' if v['passed'] else 'FAIL'} pixels {v['pass_fraction']*100:.2f}% global z {v['global_z']:+.2f} relMSE {v['rel_mse']:.2e}")
        with open(ref + "_ladder.json") as f:
            mcurve = [{"spp": p["spp"], "seconds": p["seconds"], "rel_mse": float(np.mean((read_exr(p["file"]) - r) ** 2 / (r * r + 1e-2)))} for p in json.load(f)]
        floor = float(np.mean(var_r / (r * r + 1e-2)))
        for res in results:
            if res["case"] == case:
                res["mitsuba_curve"] = mcurve
                res["reference_noise_floor"] = floor
                res["equal_time_rel_mse_ratio"] = equal_time_ratio(res["curve"], mcurve)
    summary = {"tier": args.tier, "pathtracer": info.strip(), "results": results, "all_passed": all(r["passed"] for r in results)}
    with open(os.path.join(out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    write_report(out, summary)
    print(f"wrote {os.path.join(out, 'report.html')} and summary.json: {'all passed' if summary['all_passed'] else 'FAILURES'}")
    sys.exit(0 if summary["all_passed"] else 1)


def error_curve(pt, scene_args, view, m, backend, ladder, folder, r):
    """Our relMSE against the reference at each spp of the ladder, with the render time
    our summary line reports (process start and scene loading excluded, as for Mitsuba)."""
    curve = []
    for n in ladder:
        exr = os.path.join(folder, f"{backend}_spp{n}.exr")
        text = sh([pt, *scene_args, *view, "-s", str(n), "-m", str(m), "--backend", backend, "--seed", str(100 + n), "-f", os.path.join(folder, f"{backend}_spp{n}.png"), "--exr", exr])
        seconds = float(text.split("| render ")[1].split(" s")[0])
        x = read_exr(exr)
        curve.append({"spp": n, "seconds": seconds, "rel_mse": float(np.mean((x - r) ** 2 / (r * r + 1e-2)))})
    return curve


def equal_time_ratio(ours, theirs):
    """relMSE(ours) / relMSE(theirs) at equal render time: both curves interpolated
    log-log at the geometric mean of the overlapping time range. None without overlap."""
    def at(curve, t):
        pts = sorted((p["seconds"], p["rel_mse"]) for p in curve)
        for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
            if t0 <= t <= t1 and t1 > t0 and e0 > 0 and e1 > 0:
                a = (np.log(t) - np.log(t0)) / (np.log(t1) - np.log(t0))
                return float(np.exp(np.log(e0) + a * (np.log(e1) - np.log(e0))))
        return None
    lo = max(min(p["seconds"] for p in ours), min(p["seconds"] for p in theirs))
    hi = min(max(p["seconds"] for p in ours), max(p["seconds"] for p in theirs))
    if not (hi > lo > 0):
        return None
    t = float(np.sqrt(lo * hi))
    a, b = at(ours, t), at(theirs, t)
    return {"seconds": t, "ratio": a / b} if a and b else None


def svg_curves(series, width=360, height=240):
    """A log-log plot of relMSE against seconds, as inline SVG."""
    pts = [(p["seconds"], p["rel_mse"]) for _, c, _ in series for p in c if p["seconds"] > 0 and p["rel_mse"] > 0]
    if not pts:
        return ""
    lx = [np.log10(t) for t, _ in pts]
    ly = [np.log10(e) for _, e in pts]
    x0, x1, y0, y1 = min(lx) - 0.1, max(lx) + 0.1, min(ly) - 0.1, max(ly) + 0.1
    px = lambda v: 40 + (np.log10(v) - x0) / (x1 - x0) * (width - 50)
    py = lambda v: height - 30 - (np.log10(v) - y0) / (y1 - y0) * (height - 40)
    parts = [f'<svg width="{width}" height="{height}" class="curve"><rect x="40" y="10" width="{width-50}" height="{height-40}" fill="none" stroke="#999"/>',
             f'<text x="{width/2}" y="{height-5}" font-size="11">render time (s, log)</text><text x="2" y="20" font-size="11">relMSE</text>',
             f'<text x="40" y="{height-18}" font-size="9">{10**x0:.2g}</text><text x="{width-40}" y="{height-18}" font-size="9">{10**x1:.2g}</text>',
             f'<text x="2" y="{height-30}" font-size="9">{10**y0:.1e}</text><text x="2" y="40" font-size="9">{10**y1:.1e}</text>']
    for i, (name, c, colour) in enumerate(series):
        line = " ".join(f"{px(p['seconds']):.1f},{py(p['rel_mse']):.1f}" for p in sorted(c, key=lambda p: p["seconds"]) if p["seconds"] > 0 and p["rel_mse"] > 0)
        parts.append(f'<polyline points="{line}" fill="none" stroke="{colour}" stroke-width="2"/>')
        parts.append(f'<text x="{width-110}" y="{25+14*i}" font-size="11" fill="{colour}">{html.escape(name)}</text>')
    parts.append("</svg>")
    return "".join(parts)


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
    curves = []
    eff_rows = []
    for case in sorted({r["case"] for r in summary["results"]}):
        rs = [r for r in summary["results"] if r["case"] == case]
        colours = {"native": "#d62728", "embree": "#1f77b4"}
        series = [(r["backend"], r["curve"], colours.get(r["backend"], "#333")) for r in rs] + [("mitsuba", rs[0]["mitsuba_curve"], "#2ca02c")]
        curves.append(f"<div class='plot'><h3>{html.escape(case)}</h3>{svg_curves(series)}</div>")
        for name, c, _ in series:
            best = max(c, key=lambda p: p["spp"])
            eff_rows.append(f"<tr><td>{html.escape(case)}</td><td>{name}</td><td>{best['spp']}</td><td>{best['seconds']:.3f}</td><td>{best['rel_mse']:.2e}</td><td>{1.0/(best['rel_mse']*best['seconds']):.3g}</td></tr>")
        for r in rs:
            eq = r.get("equal_time_rel_mse_ratio")
            eff_rows.append(f"<tr><td>{html.escape(case)}</td><td>{r['backend']} ÷ mitsuba at equal time</td><td colspan='4'>{'%.2f at %.3f s' % (eq['ratio'], eq['seconds']) if eq else 'no overlapping times'}</td></tr>")
    doc = f"""<!doctype html><html><head><meta charset="utf-8"><title>pathtracer validation ({summary['tier']})</title>
<style>body{{font-family:sans-serif}} table{{border-collapse:collapse}} td,th{{border:1px solid #999;padding:3px 6px;text-align:right}}
img{{width:128px;image-rendering:pixelated}} .pass{{background:#cfc}} .fail{{background:#fcc}} .plot{{display:inline-block}}</style>
<script>window.addEventListener("load", () => {{ const imgs = [...document.images];
document.body.dataset.images = imgs.length; document.body.dataset.imagesOk = imgs.filter(i => i.complete && i.naturalWidth > 0).length; }});</script></head><body>
<h1>pathtracer validation: {summary['tier']} tier</h1>
<p>{html.escape(summary['pathtracer'])}. Verdict: per pixel-channel Welch z-test (alpha 0.01, Šidák), pass at &ge; 99.75 % of
pixel-channels, plus a global test of the image mean by batch means (ours: {BATCHES} independent renders, the reference: its
independent renders; Student t, alpha 0.01). z-map: blue z &le; -4, white 0, red z &ge; 4.</p>
<table id="verdicts"><tr><th>case</th><th>backend</th><th>reference</th><th>verdict</th><th>pixels passing</th><th>global t</th><th>mean diff</th>
<th>relMSE</th><th>SMAPE</th><th>our time</th><th>ours</th><th>reference</th><th>z-map</th></tr>
{''.join(rows)}</table>
<h2>Error against time</h2><p>relMSE against the reference (reference noise floor included: see summary.json) for the spp ladder; render time excludes process start.</p>
{''.join(curves)}
<h2>Efficiency</h2><table id="efficiency"><tr><th>case</th><th>renderer</th><th>spp</th><th>seconds</th><th>relMSE</th><th>1/(relMSE·s)</th></tr>{''.join(eff_rows)}</table>
</body></html>"""
    with open(os.path.join(out, "report.html"), "w") as f:
        f.write(doc)


if __name__ == "__main__":
    main()
