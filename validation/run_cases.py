#!/usr/bin/env python3
"""The validation harness driver: export each case's scene from our loader, render it with
each of our backends (native, Embree 3, Embree 4) and with the reference renderers (Mitsuba 3, Blender Cycles, POV-Ray),
and write statistical verdicts to validation/out/summary.json and validation/out/report.html.

Two kinds of case:
* light transport (`radiance`): our image (BATCHES independent renders) against each
  reference (independent renders of its own), per-pixel Welch z plus a global batch-means
  test (stats.verdict), error-vs-time curves and equal-time error ratios;
* intersection (`geometry`): object-id and depth images at one ray through each pixel centre
  against POV-Ray (exact up to POV-Ray's half-float output), and object-id, depth and the
  normal pass averaged over the pixel against Cycles (statistical on interior pixels; only
  silhouette pixels may differ, and their count is reported).

References are cached under validation/out/cache by a hash of the exported scene and the
render settings.

Modules: cases.py (the tiers and their cases), stats.py (verdicts), metrics.py (relMSE, FLIP,
equal-time ratios), images.py (EXR/PNG files), geometry_checks.py (the intersection cases'
comparisons), report.py (the HTML report); one script per
reference renderer (mitsuba_ref.py, cycles_ref.py, pov_ref.py); this file runs the cases.
"""
import argparse
import hashlib
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
from cases import BATCHES, TIERS, find_scene, own_scene_cases  # noqa: E402
from images import read_exr, to_png, write_png, write_zmap  # noqa: E402
from metrics import equal_time_ratio, flip_error, from_renders, interp_loglog, ladder_curve, rel_mse  # noqa: E402
from report import write_report  # noqa: E402
from geometry_checks import geometry_vs_cycles, geometry_vs_pov  # noqa: E402
from provenance import provenance  # noqa: E402
def normalise_export(src, dst):
    """A copy of an exported scene moved and scaled into the references' comfort zone: moved
    by a multiple of 1024 (and of 4 extents) towards the origin, then scaled by a power of two to a size of
    about 2. Measured without it: at +8192, Mitsuba 3.9.1's spheres shadow themselves and
    Cycles 3.4's stand-in rounds onto its lamp (30 % dark); at scale 1e-3 Mitsuba is 1.5 %
    dark (its absolute epsilons). Both steps are exact in binary floating point (checked per
    coordinate, refused otherwise), so the references still see exactly our rounded
    geometry. Radiance does not change under the move and the uniform scale (point
    intensities are scaled by s^2 to keep that true); depths scale by s."""
    os.makedirs(dst, exist_ok=True)
    with open(os.path.join(src, "scene.json")) as f:
        spec = json.load(f)
    pts = [s["center"] for s in spec["shapes"] if s["type"] == "sphere"]
    meshes = {}
    # (the mean only picks the shift; exactness is checked per coordinate below)
    for s in spec["shapes"]:
        if s["type"] == "mesh":
            with open(os.path.join(src, s["file"])) as f:
                meshes[s["file"]] = f.read().splitlines()
            pts += [[float(c) for c in line.split()[1:4]] for line in meshes[s["file"]] if line.startswith("v ")]
    pts = np.asarray(pts, dtype=np.float64)
    extent = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
    # Move by whole blocks of at least 1024 and 4 extents: only a scene far from the
    # origin relative to its size moves at all.
    block = max(1024.0, 2.0 ** np.ceil(np.log2(max(4.0 * extent, 1e-30))))
    shift = -block * np.round(pts.mean(axis=0) / block)
    scale = 2.0 ** round(np.log2(2.0 / extent)) if extent > 0 else 1.0

    def mv(p):
        out = []
        for c in p:
            # Our coordinates are f32; the OBJ text is their shortest f32 spelling.
            c = float(np.float32(float(c)))
            q = (c + shift[len(out)]) * scale
            if float(np.float32(q)) != q or q / scale - shift[len(out)] != c:
                sys.exit(f"run_cases: normalising {src}: coordinate {c!r} does not move exactly (shift {shift.tolist()}, scale {scale})")
            out.append(float(q))
        return out

    spec["camera"]["origin"] = mv(spec["camera"]["origin"])
    spec["camera"]["near"] *= scale
    if spec["camera"]["far"] is not None:  # null: no far plane
        spec["camera"]["far"] *= scale
    spec["normalised"] = {"shift": shift.tolist(), "scale": scale}
    for s in spec["shapes"]:
        if s["type"] == "sphere":
            s["center"] = mv(s["center"])
            s["radius"] *= scale
        elif s["type"] == "mesh":
            with open(os.path.join(dst, s["file"]), "w") as g:
                for line in meshes[s["file"]]:
                    if line.startswith("v "):
                        line = "v " + " ".join(repr(c) for c in mv(line.split()[1:4]))
                    g.write(line + "\n")
    for l in spec["lights"]:
        for k in ("position", "corner"):
            if k in l:
                l[k] = mv(l[k])
        for k in ("ex", "ey"):
            if k in l:
                l[k] = [c * scale for c in l[k]]
        if l["type"] == "point":
            l["intensity"] = [c * scale * scale for c in l["intensity"]]
    with open(os.path.join(dst, "scene.json"), "w") as f:
        json.dump(spec, f, indent=1)
    return dst, scale


def cycles_ref_command(blender, scene_dir, *args):
    """Blender's Python running cycles_ref.py on the exported scene in `scene_dir`."""
    return [blender, "-b", "--factory-startup", "--python-exit-code", "1", "-P", os.path.join(HERE, "cycles_ref.py"), "--", scene_dir, *args]


def sh(cmd, **kw):
    r = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if r.returncode != 0:
        sys.exit(f"run_cases: {' '.join(cmd)} failed:\n{r.stdout[-3000:]}{r.stderr[-3000:]}")
    return r.stdout


class Harness:
    def __init__(self, args, tier):
        self.pt = args.pathtracer
        self.out = args.out
        self.t = tier
        self.view = ["-r", str(tier["w"]), str(tier["h"]), "--keep-fov"]
        self.cache = os.path.join(self.out, "cache")
        os.makedirs(self.cache, exist_ok=True)
        # The backend axis: native and each Embree that loads here. CI
        # requires both Embrees (PATHTRACER_REQUIRE_EMBREE, as the tests do).
        self.backends = ["native"]
        required = os.environ.get("PATHTRACER_REQUIRE_EMBREE", "")
        required = ["3", "4"] if required in ("1", "all") else [m.strip() for m in required.split(",") if m.strip()]
        for major in ("3", "4"):
            backend = f"embree{major}"
            probe = subprocess.run([self.pt, "--backend", backend, "-r", "4", "3", "-s", "1", "-f", os.path.join(self.out, "probe.png")], capture_output=True, text=True)
            if probe.returncode == 0:
                self.backends.append(backend)
            elif major in required:
                sys.exit(f"run_cases: PATHTRACER_REQUIRE_EMBREE names Embree {major}, but: {probe.stderr.strip()}")
            else:
                print(f"run_cases: {backend} backend unavailable ({probe.stderr.strip()}); left out", file=sys.stderr)
        for f in ("probe.png", "probe_rate.png"):
            if os.path.exists(os.path.join(self.out, f)):
                os.remove(os.path.join(self.out, f))
        if args.backends:
            wanted = [b for b in args.backends.split(",") if b]
            missing = [b for b in wanted if b not in self.backends]
            if missing:
                sys.exit(f"run_cases: --backends {args.backends}: {', '.join(missing)} not available here (available: {', '.join(self.backends)})")
            self.backends = wanted
        self.blender = shutil.which("blender")
        self.povray_bin = shutil.which("povray")

    def export(self, case, folder):
        """Export the case's scene with our loader into folder/scene. With `ref_shift`, the
        references get a copy moved by that vector (folder/scene_ref), see shift_export.
        Returns (our scene arguments, cache key of the references' scene, its folder)."""
        scene = find_scene(case["scene"])
        extra = case.get("scene_flags", [])
        sh([self.pt, "export", scene, *extra, *self.view, "--out", os.path.join(folder, "scene")])
        d = os.path.join(folder, "scene")
        self.ref_scale = 1.0
        if case.get("ref_shift"):
            d, self.ref_scale = normalise_export(d, os.path.join(folder, "scene_ref"))
        h = hashlib.sha256()
        # The reference scripts are part of the key: a changed exporter never reuses a
        # reference rendered by the old one.
        for p in ("mitsuba_ref.py", "cycles_ref.py", "pov_ref.py", "mesh_io.py"):
            with open(os.path.join(HERE, p), "rb") as f:
                h.update(p.encode() + f.read())
        for p in sorted(os.listdir(d)):
            with open(os.path.join(d, p), "rb") as f:
                h.update(p.encode() + f.read())
        return [scene, *extra], h.hexdigest()[:16], d

    # ---- references: each returns {renderer, mean, var, image_means, spp, seconds} ----

    def mitsuba(self, scene_dir, key, m, integrator="path"):
        t = self.t
        name = "mitsuba" if integrator == "path" else f"mitsuba_{integrator}"
        ref = os.path.join(self.cache, f"{name}_{key}_m{m}_{t['ref_spp']}x{t['ref_renders']}")
        if not os.path.exists(ref + ".json"):
            r = subprocess.run([sys.executable, os.path.join(HERE, "mitsuba_ref.py"), scene_dir, "--max-depth", str(m), "--spp", str(t["ref_spp"]),
                                "--renders", str(t["ref_renders"]), "--integrator", integrator, "--out", ref], capture_output=True, text=True)
            if r.returncode == 3:
                return {"refused": r.stderr.strip()}
            if r.returncode != 0:
                sys.exit(f"run_cases: mitsuba_ref.py failed:\n{r.stderr[-3000:]}")
        mean = read_exr(ref + ".exr")
        with open(ref + ".json") as f:
            meta = json.load(f)
        return {"renderer": meta["renderer"], "mean": mean, "var": read_exr(ref + "_var.exr"), "image_means": meta["image_means"], "spp": meta["spp"],
                "seconds": meta["seconds"]}

    def mitsuba_ptracer(self, scene_dir, key, m):
        """Mitsuba's particle tracer: the light tracer's like (`--integrator light`)."""
        return self.mitsuba(scene_dir, key, m, "ptracer")

    def cycles(self, scene_dir, key, m, mode="radiance", spp=None, renders=None):
        if not self.blender:
            sys.exit("run_cases: blender not found (validation/setup installs Debian's blender)")
        t = self.t
        spp = spp or t["ref_spp"]
        renders = renders or t["ref_renders"]
        ref = os.path.join(self.cache, f"cycles_{key}_{mode}_m{m}_{spp}x{renders}")
        if not os.path.exists(ref + "_cycles.json"):
            r = subprocess.run(cycles_ref_command(self.blender, scene_dir, "--mode", mode, "--max-depth", str(m), "--spp", str(spp), "--renders", str(renders), "--out", ref),
                               capture_output=True, text=True)
            if r.returncode == 3 or "cannot represent exactly" in r.stderr:
                return {"refused": [l for l in r.stderr.splitlines() if "cycles_ref" in l][-1]}
            if r.returncode != 0 or not os.path.exists(ref + "_cycles.json"):
                sys.exit(f"run_cases: blender/cycles_ref.py failed (rc {r.returncode}):\n{r.stdout[-2000:]}{r.stderr[-2000:]}")
        with open(ref + "_cycles.json") as f:
            meta = json.load(f)
        out = from_renders([read_exr(p["file"]) for p in meta["renders"]], meta)
        return {**out, "renderer": meta["renderer"], "spp": spp * len(out["renders"]), "normal_deviation": meta.get("normal_deviation", 0.0)}

    def reference_ladder(self, rname, scene_dir, m, folder):
        """The reference's error-against-time ladder, rendered and timed afresh on every run
        (never cached: a timing is only comparable with ours when measured in the same
        run): `ladder_seeds` independent renders per rung, each timed on its own inside
        the renderer's process (process start and scene loading excluded, as for ours).
        Returns [(spp, seconds, image)]."""
        t = self.t
        lad = ",".join(str(n) for n in t["ladder"])
        out = os.path.join(folder, f"{rname}_ladder")
        if rname in ("mitsuba", "mitsuba_ptracer"):
            integrator = "ptracer" if rname == "mitsuba_ptracer" else "path"
            sh([sys.executable, os.path.join(HERE, "mitsuba_ref.py"), scene_dir, "--max-depth", str(m), "--spp", "1", "--renders", "0",
                "--integrator", integrator, "--ladder", lad, "--ladder-seeds", str(t["ladder_seeds"]), "--out", out])
            with open(out + "_ladder.json") as f:
                runs = json.load(f)
        elif rname == "cycles":
            sh(cycles_ref_command(self.blender, scene_dir, "--mode", "radiance", "--max-depth", str(m), "--spp", "1", "--renders", "0", "--ladder", lad,
                                  "--ladder-seeds", str(t["ladder_seeds"]), "--out", out))
            with open(out + "_cycles.json") as f:
                runs = json.load(f)["ladder"]
        else:
            return []
        return [(p["spp"], p["seconds"], read_exr(p["file"])) for p in runs]

    def povray(self, scene_dir, key, m):
        """Direct lighting only (POV-Ray has no unbiased global illumination)."""
        if m != 1:
            return {"refused": "POV-Ray validates direct lighting (-m 1) only: its radiosity is a biased irradiance cache"}
        t = self.t
        S, n = t["pov_supersample"], t["pov_lightlets"]
        ref = os.path.join(self.cache, f"pov_{key}_radiance_s{S}_n{n}_x{t['ref_renders']}")
        if not os.path.exists(ref + "_pov.json"):
            r = subprocess.run([sys.executable, os.path.join(HERE, "pov_ref.py"), scene_dir, "--mode", "radiance", "--renders", str(t["ref_renders"]),
                                "--supersample", str(S), "--lightlets", str(n), "--out", ref], capture_output=True, text=True)
            if r.returncode == 3:
                return {"refused": r.stderr.strip()}
            if r.returncode != 0:
                sys.exit(f"run_cases: pov_ref.py failed:\n{r.stderr[-3000:]}")
        with open(ref + "_pov.json") as f:
            meta = json.load(f)
        imgs = []
        for p in meta["renders"]:
            a = read_exr(p["file"])
            imgs.append(a.reshape(a.shape[0] // S, S, a.shape[1] // S, S, 3).mean(axis=(1, 3)))
        return {**from_renders(imgs, meta), "renderer": f"{meta['renderer']}, {n}x{n} lightlets, {S}x{S} rays/px", "spp": S * S * len(imgs)}

    # ---- ours ----

    def ours(self, scene_args, folder, backend, args, spp, batches, tag):
        """`batches` independent renders; mean, variance of the mean (pooled within-render
        variance) and the renders' image means."""
        t0 = time.time()
        xs, vs = [], []
        for b in range(batches):
            exr = os.path.join(folder, f"{backend}_{tag}_b{b}.exr")
            var = os.path.join(folder, f"{backend}_{tag}_b{b}_var.exr")
            sh([self.pt, *scene_args, *self.view, "-s", str(spp // batches), *args, "--backend", backend, "--seed", str(7 + b),
                "-f", os.path.join(folder, f"{backend}_{tag}_b{b}.png"), "--exr", exr, "--variance-exr", var])
            xs.append(read_exr(exr))
            vs.append(read_exr(var))
        return np.mean(xs, axis=0), np.mean(vs, axis=0) / batches, [float(i.mean()) for i in xs], time.time() - t0, xs

    def ladder(self, scene_args, folder, backend, args):
        """Our error-against-time ladder: `ladder_seeds` independent renders (seeds) per spp
        rung, each timed by its summary line (process start, scene loading and BVH build
        excluded, as the references' timings exclude theirs). Returns [(spp, seconds, image)]."""
        runs = []
        for n in self.t["ladder"]:
            for k in range(self.t["ladder_seeds"]):
                exr = os.path.join(folder, f"{backend}_spp{n}_k{k}.exr")
                text = sh([self.pt, *scene_args, *self.view, "-s", str(n), *args, "--backend", backend, "--seed", str(100 + n + 7919 * k),
                           "-f", os.path.join(folder, f"{backend}_spp{n}_k{k}.png"), "--exr", exr])
                runs.append((n, float(text.split("| render ")[1].split(" s")[0]), read_exr(exr)))
        return runs

    # ---- cases ----

    def run_radiance(self, case, results):
        name = os.path.splitext(os.path.basename(case["scene"]))[0]
        cid = f"{name}_m{case['m']}" + "".join(f.replace("-", "_") for f in case["flags"]) + case.get("tag", "")
        folder = self.fresh(cid)
        scene_args, key, ref_dir = self.export(case, folder)
        args = ["-m", str(case["m"]), *case["flags"]]
        refs = {}
        for rname in case["refs"]:
            ref = getattr(self, rname)(ref_dir, key, case["m"])
            if "refused" in ref:
                print(f"{cid}: {rname} refuses the scene: {ref['refused']}")
                results.append({"kind": "radiance", "case": cid, "label": case["label"], "reference": rname, "backend": "-", "refused": ref["refused"], "passed": True})
                continue
            refs[rname] = ref
            write_png(os.path.join(folder, f"{rname}.png"), to_png(ref["mean"]))
        ref_ladders = {rname: self.reference_ladder(rname, ref_dir, case["m"], folder) for rname in refs}
        for backend in self.backends:
            spp = self.t["spp"] * case["spp_scale"]
            x, var_x, means_x, seconds, xs = self.ours(scene_args, folder, backend, args, spp, BATCHES, "img")
            write_png(os.path.join(folder, f"{backend}.png"), to_png(x))
            ladder_runs = self.ladder(scene_args, folder, backend, args)
            for rname, ref in refs.items():
                v = stats.verdict(x, var_x, ref["mean"], ref["var"], means_x, ref["image_means"], spp, self.max_sample(folder, case), xs, ref.get("renders"))
                z = v.pop("z_image")
                write_zmap(os.path.join(folder, f"{backend}_{rname}_z.png"), z)
                worst = np.argsort(-np.abs(z).max(-1), axis=None)[:8]
                v["worst_pixels"] = [{"y": int(i // z.shape[1]), "x": int(i % z.shape[1]), "ours": x.reshape(-1, 3)[i].tolist(), "reference": ref["mean"].reshape(-1, 3)[i].tolist(),
                                      "z": z.reshape(-1, 3)[i].tolist()} for i in worst]
                # Both curves measure error against the same image (the reference's mean), so
                # the ratio compares the two renderers' noise, not their agreement (the
                # verdict tests that).
                ours_c, ref_c = ladder_curve(ladder_runs, ref["mean"]), ladder_curve(ref_ladders[rname], ref["mean"])
                v.update({"kind": "radiance", "case": cid, "label": case["label"], "scene": name, "max_depth": case["m"], "flags": case["flags"], "backend": backend,
                          "reference": rname, "reference_renderer": ref["renderer"], "spp": spp, "seconds": seconds, "reference_spp": ref["spp"],
                          "reference_seconds": ref["seconds"], "size": [self.t["w"], self.t["h"]], "curve": ours_c["curve"], "reference_curve": ref_c["curve"],
                          "timing": {"ours": ours_c["fit"], "reference": ref_c["fit"]},
                          "reference_noise_floor": float(np.mean(ref["var"] / (ref["mean"] ** 2 + 1e-2))),
                          "equal_time_rel_mse_ratio": equal_time_ratio(ours_c["curve"], ref_c["curve"]),
                          "flip": flip_error(x, ref["mean"])})
                results.append(v)
                eq = v["equal_time_rel_mse_ratio"]
                print(f"{cid} {backend} vs {rname}: {'PASS' if v['passed'] else 'FAIL'} pixels {v['pass_fraction']*100:.2f}% global t {v['global_z']:+.2f} "
                      f"relMSE {v['rel_mse']:.2e} equal-time ratio {eq['ratio'] if eq else float('nan'):.2f}")

    def max_sample(self, folder, case):
        """The largest value one sample of uniform hemisphere sampling (-H) can take at -m 1:
        (albedo/π)·L·cos/(1/2π) <= 2·albedo·L, with L the brightest emitted radiance. None
        for other estimators (no such bound is used)."""
        if "-H" not in case["flags"] or case["m"] != 1:
            return None
        with open(os.path.join(folder, "scene", "scene.json")) as f:
            spec = json.load(f)
        if any(l["type"] not in ("emissive_shape",) for l in spec["lights"]):
            return None  # delta lights are sampled explicitly even with -H
        albedo = max(max(s["albedo"]) for s in spec["shapes"])
        radiance = max(max(s["emission"]) for s in spec["shapes"])
        return 2.0 * albedo * radiance

    def run_adaptive(self, case, results):
        name = os.path.splitext(os.path.basename(case["scene"]))[0]
        cid = f"{name}_m{case['m']}_adaptive"
        folder = self.fresh(cid)
        scene_args, key, ref_dir = self.export(case, folder)
        S = self.t["spp"]
        # Independent numbers for this case: it tests the stopping rules, whose
        # variance estimates assume independent samples, and with Owen-Sobol the
        # converged image is precise enough (image-mean se 0.04 %) that the global
        # test sees a +0.2 % systematic of both references at 64x48 that lives in
        # the 14 pixels straddling the light's edge (Cycles +0.98 % there, the rest
        # +0.025 %; our -H and light-sampling estimates agree to 0.03 %): pixel
        # footprint, not light transport; not yet explained.
        sampler = ["--sampler", "independent"]
        a_flags = ["-a", str(case["batch"]), str(case["tol"]), *sampler]
        refs = {r: self.getref(r, ref_dir, key, case["m"]) for r in case["refs"]}
        refs = {r: v for r, v in refs.items() if "refused" not in v}
        direct = {r: self.getref(r, ref_dir, key, 1) for r in case["refs"]}
        direct = {r: v for r, v in direct.items() if "refused" not in v}
        for rname, ref in refs.items():
            write_png(os.path.join(folder, f"{rname}.png"), to_png(ref["mean"]))
        for backend in self.backends:
            # Uniform sampling at S/8 .. S, for "samples saved at equal error".
            uni = []
            for n in [S // 8, S // 4, S // 2, S]:
                exr = os.path.join(folder, f"{backend}_u{n}.exr")
                text = sh([self.pt, *scene_args, *self.view, "-s", str(n), *sampler, "-m", str(case["m"]), "--backend", backend, "--seed", str(300 + n), "-f", os.path.join(folder, f"{backend}_u{n}.png"), "--exr", exr])
                uni.append((n, float(text.split("| render ")[1].split(" s")[0]), read_exr(exr)))
            for rule, extra in (("cs184", []), ("pilot", ["--adaptive-pilot"])):
                # 1. The converged image: 8 independent adaptive renders at the full maximum.
                xs, vs, kept = [], [], []
                t0 = time.time()
                for b in range(BATCHES):
                    exr, var = (os.path.join(folder, f"{backend}_{rule}_b{b}{e}.exr") for e in ("", "_var"))
                    text = sh([self.pt, *scene_args, *self.view, "-s", str(S), *a_flags, *extra, "-m", str(case["m"]), "--backend", backend, "--seed", str(7 + b),
                               "-f", os.path.join(folder, f"{backend}_{rule}_b{b}.png"), "--exr", exr, "--variance-exr", var])
                    xs.append(read_exr(exr))
                    vs.append(read_exr(var))
                    kept.append(float(text.split("samples kept (")[1].split("/px")[0]))
                seconds = time.time() - t0
                x, var_x = np.mean(xs, 0), np.mean(vs, 0) / BATCHES
                tag = f"{backend}_{rule}"
                write_png(os.path.join(folder, f"{tag}.png"), to_png(x))
                shutil.copy(os.path.join(folder, f"{backend}_{rule}_b0_rate.png"), os.path.join(folder, f"{tag}_rate.png"))
                # 2. One adaptive render against the uniform ones, at equal error.
                exr = os.path.join(folder, f"{tag}_a1.exr")
                text = sh([self.pt, *scene_args, *self.view, "-s", str(S), *a_flags, *extra, "-m", str(case["m"]), "--backend", backend, "--seed", "299",
                           "-f", os.path.join(folder, f"{tag}_a1.png"), "--exr", exr])
                a_spp = float(text.split("samples kept (")[1].split("/px")[0])
                a_sec = float(text.split("| render ")[1].split(" s")[0])
                a_img = read_exr(exr)
                for rname, ref in refs.items():
                    v = stats.verdict(x, var_x, ref["mean"], ref["var"], [float(i.mean()) for i in xs], ref["image_means"], renders_x=xs, renders_r=ref.get("renders"))
                    write_zmap(os.path.join(folder, f"{tag}_{rname}_z.png"), v.pop("z_image"))
                    ucurve = [{"spp": n, "seconds": sec, "rel_mse": rel_mse(img, ref["mean"])} for n, sec, img in uni]
                    a_err = rel_mse(a_img, ref["mean"])
                    eq_spp = interp_loglog([(p["rel_mse"], p["spp"]) for p in ucurve], a_err)
                    eq_sec = interp_loglog([(p["rel_mse"], p["seconds"]) for p in ucurve], a_err)
                    v.update({"kind": "adaptive", "case": cid, "rule": rule, "image": tag, "label": f"adaptive -a {case['batch']} {case['tol']} -s {S}, {rule} rule",
                              "scene": name, "max_depth": case["m"], "flags": a_flags + extra,
                              "backend": backend, "reference": rname, "reference_renderer": ref["renderer"], "spp": S, "mean_samples_kept": float(np.mean(kept)), "seconds": seconds,
                              "uniform_curve": ucurve, "adaptive_single": {"samples_per_pixel": a_spp, "seconds": a_sec, "rel_mse": a_err},
                              "uniform_spp_at_equal_error": eq_spp, "samples_saved": (1 - a_spp / eq_spp) if eq_spp else None,
                              "uniform_seconds_at_equal_error": eq_sec, "time_saved": (1 - a_sec / eq_sec) if eq_sec else None})
                    if rule == "cs184":
                        # CS184's rule decides on the samples it keeps: its image is biased
                        # dark by design (measured in the bias rows). Its verdict is reported;
                        # the pilot rule's image and the bias rows are what must pass.
                        v["verdict_passed"] = v["passed"]
                        v["passed"] = True
                        v["informational"] = "CS184's stopping rule is biased by design; reported, not a gate"
                    results.append(v)
                    vp = v.get("verdict_passed", v["passed"])
                    print(f"{cid} {backend} {rule} rule vs {rname}: {'PASS' if vp else ('BIASED (expected)' if rule == 'cs184' else 'FAIL')} pixels {v['pass_fraction']*100:.2f}% "
                          f"global t {v['global_z']:+.2f}; {a_spp:.1f} spp/px ({a_sec:.2f} s) vs uniform {eq_spp or float('nan'):.1f} ({eq_sec or float('nan'):.2f} s) at equal error")
            # 3. Bias of the stopping rules on a rare-path configuration.
            if direct:
                rname, ref = next(iter(direct.items()))
                rmeans = np.asarray(ref["image_means"])
                bias = {}
                for rule, extra in (("cs184", []), ("pilot", ["--adaptive-pilot"])):
                    means = []
                    for k in range(case["bias_runs"]):
                        exr = os.path.join(folder, f"{backend}_bias_{rule}.exr")
                        sh([self.pt, *scene_args, *self.view, "-s", str(S), "-a", "16", "0.05", "-H", "-m", "1", *sampler, *extra, "--backend", backend, "--seed", str(500 + k),
                            "-f", os.path.join(folder, f"{backend}_bias_{rule}.png"), "--exr", exr])
                        means.append(float(read_exr(exr).mean()))
                    m = np.asarray(means)
                    se = float(np.sqrt(m.var(ddof=1) / m.size + rmeans.var(ddof=1) / rmeans.size))
                    t = float((m.mean() - rmeans.mean()) / se)
                    bias[rule] = {"runs": m.size, "mean": float(m.mean()), "relative_bias": float(m.mean() / rmeans.mean() - 1), "se_relative": se / float(rmeans.mean()), "t": t}
                crit = stats.T_CRIT_001[min(case["bias_runs"], rmeans.size) - 1]
                passed = abs(bias["pilot"]["t"]) <= crit
                results.append({"kind": "adaptive_bias", "case": cid, "backend": backend, "reference": rname, "reference_renderer": ref["renderer"], "t_critical": crit,
                                "config": f"-H -m 1 -s {S} -a 16 0.05, {case['bias_runs']} runs per rule", "bias": bias, "passed": bool(passed)})
                print(f"{cid} {backend} stopping-rule bias vs {rname}: CS184 {100*bias['cs184']['relative_bias']:+.2f} % (t {bias['cs184']['t']:+.1f}), "
                      f"pilot {100*bias['pilot']['relative_bias']:+.2f} % (t {bias['pilot']['t']:+.1f}): {'PASS' if passed else 'FAIL'}")

    def getref(self, rname, ref_dir, key, m):
        return getattr(self, rname)(ref_dir, key, m)

    def pov_geometry(self, sc, key):
        """POV-Ray's object ids and depths: one ray through each pixel centre, as ours at -s 1."""
        pov = {}
        for mode in ("object-id", "depth"):
            p = os.path.join(self.cache, f"pov_{key}_{mode}.exr")
            if not os.path.exists(p):
                sh([sys.executable, os.path.join(HERE, "pov_ref.py"), sc, "--mode", mode, "--out", p])
            pov[mode] = read_exr(p)
        return pov

    def run_geometry(self, case, results):
        name = os.path.splitext(os.path.basename(case["scene"]))[0]
        cid = f"{name}_geometry"
        folder = self.fresh(cid)
        scene_args, key, sc = self.export(case, folder)
        pov = self.pov_geometry(sc, key)
        # Depths of a normalised reference scene are in its units.
        pov["depth"] = pov["depth"] / self.ref_scale
        # Cycles: pixel averages over the box filter, independent renders.
        cyc = {mode: self.cycles(sc, key, 1, mode, spp=64, renders=8) for mode in ("object-id", "depth", "normal")}
        if "refused" not in cyc["depth"]:
            d = cyc["depth"]
            d["mean"], d["var"], d["renders"] = d["mean"] / self.ref_scale, d["var"] / self.ref_scale ** 2, [r / self.ref_scale for r in d["renders"]]
        for backend in self.backends:
            centre = {}
            for mode in ("object-id", "depth"):
                exr = os.path.join(folder, f"{backend}_{mode}_centre.exr")
                sh([self.pt, *scene_args, *self.view, "-s", "1", "--integrator", mode, "--backend", backend, "-f", os.path.join(folder, f"{backend}_{mode}_centre.png"), "--exr", exr])
                centre[mode] = read_exr(exr)
            results.append(geometry_vs_pov(cid, name, backend, centre, pov, folder))
            avg = {}
            spp, batches = 512, 8
            for mode, integ in (("object-id", "object-id"), ("depth", "depth"), ("normal", "normals")):
                x, var_x, _, _, xs = self.ours(scene_args, folder, backend, ["--integrator", integ], spp, batches, mode)
                avg[mode] = (x, var_x, xs)
            # Our variance pools the renders' within-render sample variances.
            results.append(geometry_vs_cycles(cid, name, backend, avg, cyc, folder, self.camera(sc), spp - batches))
            for r in results[-2:]:
                print(f"{cid} {backend} vs {r['reference']}: {'PASS' if r['passed'] else 'FAIL'} {r['summary']}")

    def camera(self, scene_dir):
        with open(os.path.join(scene_dir, "scene.json")) as f:
            return json.load(f)["camera"]

    def fresh(self, cid):
        folder = os.path.join(self.out, cid)
        if os.path.exists(folder):
            shutil.rmtree(folder)
        os.makedirs(folder)
        return folder


def selected_cases(tier, only):
    """The tier's cases whose scene name with its tag contains one of `only`'s comma-separated
    strings (all of them when `only` is empty)."""
    wanted = only.split(",") if only else []
    return [c for c in tier["cases"] if not wanted or any(o in c["scene"] + c.get("tag", "") for o in wanted)]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("tier", choices=sorted(TIERS))
    ap.add_argument("--pathtracer", default=os.path.join(ROOT, "target", "release", "pathtracer"))
    ap.add_argument("--out", default=os.path.join(HERE, "out"))
    ap.add_argument("--only", default="", help="run only cases whose scene name (with its tag, e.g. CBspheres_lambertian.dae_lens) contains one of these comma-separated strings")
    ap.add_argument("--scene", default="", help="run your own scene (.dae, .obj, .ply) instead of the tier's cases, at the tier's image size and sample counts")
    ap.add_argument("-m", dest="max_depth", type=int, default=5, help="with --scene: the maximum path depth (default 5)")
    ap.add_argument("--refs", default="mitsuba,cycles", help="with --scene: the references to compare against (mitsuba, cycles, povray; default mitsuba,cycles)")
    ap.add_argument("--backends", default="", help="our backends to run, comma-separated (native, embree3, embree4; default: every one that loads here)")
    ap.add_argument("--scene-flags", default="", help="with --scene: flags that change the scene, passed to the export too (e.g. \"-e map.exr -b 0.1 -d 4.5\")")
    args = ap.parse_args()
    tier = dict(TIERS[args.tier])
    if args.scene:
        refs = [r for r in args.refs.split(",") if r]
        unknown = [r for r in refs if r not in ("mitsuba", "cycles", "povray")]
        if unknown or not refs:
            sys.exit(f"run_cases: --refs {args.refs}: expected some of mitsuba, cycles, povray")
        tier["cases"] = own_scene_cases(args.scene, args.max_depth, refs, args.scene_flags.split())
    hz = Harness(args, tier)
    results = []
    for case in selected_cases(tier, args.only):
        {"radiance": hz.run_radiance, "geometry": hz.run_geometry, "adaptive": hz.run_adaptive}[case["kind"]](case, results)
    import mitsuba

    pov = subprocess.run([hz.povray_bin, "--version"], capture_output=True, text=True)
    refs = [f"mitsuba {mitsuba.__version__} scalar_rgb", sh([hz.blender, "--version"]).splitlines()[0] + " (Cycles)",
            next((l.strip() for l in (pov.stdout + pov.stderr).splitlines() if l.startswith("POV-Ray")), "POV-Ray")]
    summary = {"tier": args.tier, "pathtracer": sh([args.pathtracer, "--version"]).strip(), "references": refs, "backends": hz.backends, "results": results,
               "all_passed": all(r["passed"] for r in results), **provenance()}
    with open(os.path.join(args.out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    write_report(args.out, summary)
    print(f"wrote {os.path.join(args.out, 'report.html')} and summary.json: {'all passed' if summary['all_passed'] else 'FAILURES'}")
    sys.exit(0 if summary["all_passed"] else 1)


if __name__ == "__main__":
    main()
