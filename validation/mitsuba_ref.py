#!/usr/bin/env python3
"""Render a reference for an exported scene (scene.json from `pathtracer export`) with
Mitsuba 3 (scalar_rgb), as R independent renders whose per-pixel mean and variance of the
mean are written as OpenEXR.

Conventions (docs/validation/README.md, measured): perspective sensor with the horizontal
field of view, box pixel filter, linear float RGB film, `path` integrator with
max_depth = our -m + 1 (Mitsuba counts emitter hits as a depth), diffuse BSDFs wrapped in
`twosided` (ours reflect from both sides), area emitters one-sided along the geometric normal
(ours too). Anything Mitsuba cannot represent exactly is refused, never approximated.

Materials: mirror = `twosided` `conductor` with
material "none" (a 100 % reflector) times the reflectance, exact; glass = `dielectric` with
int_ior = ior and ext_ior = 1.0 (Mitsuba's default is air, 1.000277), exact Fresnel and the
same (eta_i/eta_t)^2 radiance scaling as ours, exact; microfacet = `roughconductor` Beckmann
with our alpha, eta and k: D and the exact conductor Fresnel at wi.h are ours, and Mitsuba's
separable Smith G uses Walter's rational fit of G1, within 0.35 % of the exact G1 we use (the
one stated tolerance; it matters only at grazing angles); CS184's `refraction` (no Fresnel)
has no Mitsuba equivalent and is refused. Thin lens = `thinlens` (the same uniform disk and
focal plane). The environment map = `envmap` after two exact fixes: Mitsuba's lat-long has the
other handedness (the map is flipped left-right and turned 90 degrees about +y) and puts rows
at v = j/(H-1) (the map is resampled to 2H+1 rows that reproduce our clamped bilinear lookup);
before rendering, Mitsuba's own lookup is compared with ours in 4096 directions, and a
mismatch refuses the scene. The hemisphere light (L for y > 0) is an envmap whose rows down to
the horizon's are L and the rest 0 (`hemisphere_envmap`): exactly L above the horizon, a band
0.0014 degrees high under it ramping to 0, checked the same way outside that band.

`--integrator ptracer` renders with Mitsuba's particle tracer instead (the same max_depth and
Russian roulette): the reference for our light tracer (`--integrator light`), which like it
cannot see what the camera sees in or through mirrors and glass.
"""
import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from mesh_io import read_obj  # noqa: E402


def refuse(msg):
    print(f"mitsuba_ref: cannot represent exactly: {msg}", file=sys.stderr)
    sys.exit(3)


def rgb(v):
    return {"type": "rgb", "value": [float(x) for x in v]}


def cs184_lookup(tex, d):
    """Our environment lookup (CS184's lat-long and clamped bilinear filter) for unit
    directions d (N x 3), in numpy: the oracle Mitsuba's envmap is checked against."""
    h, w, _ = tex.shape
    theta = np.arccos(np.clip(d[:, 1], -1, 1))
    phi = np.arctan2(-d[:, 2], d[:, 0]) + np.pi
    x = np.mod(phi / (2 * np.pi) * w, w) - 0.5
    y = theta / np.pi * h - 0.5
    i0 = np.floor(x).astype(int)
    j0 = np.floor(y).astype(int)
    tx = (x - i0)[:, None]
    ty = (y - j0)[:, None]
    def t(i, j):
        return tex[np.clip(j, 0, h - 1), np.mod(i, w)]
    top = t(i0, j0) * (1 - tx) + t(i0 + 1, j0) * tx
    bottom = t(i0, j0 + 1) * (1 - tx) + t(i0 + 1, j0 + 1) * tx
    return top * (1 - ty) + bottom * ty


def mitsuba_envmap(tex, out_path):
    """Our lat-long texels as a Mitsuba envmap that looks up exactly what we look up."""
    import mitsuba as mi

    h, w, _ = tex.shape
    flipped = tex[:, ::-1, :]
    rows = np.empty((2 * h + 1, w, 3))
    rows[1::2] = flipped
    rows[2:-1:2] = 0.5 * (flipped[:-1] + flipped[1:])
    rows[0] = flipped[0]
    rows[-1] = flipped[-1]
    mi.Bitmap(rows.astype(np.float32)).write(out_path)
    # l = to_world^-1 d = (-d.z, d.y, d.x)
    m = mi.ScalarTransform4f([[0, 0, 1, 0], [0, 1, 0, 0], [-1, 0, 0, 0], [0, 0, 0, 1]])
    return {"type": "envmap", "filename": out_path, "to_world": m, "scale": 1.0}


# Rows of the hemisphere light's map, odd: Mitsuba's lookup puts row j at theta = pi j/(R - 1),
# so the middle row lies on the horizon.
HEMISPHERE_ROWS = 131073


def hemisphere_envmap(radiance, out_path):
    """Our hemisphere light (radiance L for y > 0, none below) as a Mitsuba envmap: rows down
    to the horizon's own row are L, the rest 0 (16 columns: it does not vary with phi). Looked
    up bilinearly between rows, every direction above the horizon gets exactly L; below it a
    band one row high (pi/131072, 0.0014 degrees) ramps from L to 0: a pixel just under a
    horizon in view reads at most about that band's share of it, light on surfaces a relative
    1e-5 at most."""
    import mitsuba as mi

    rows = np.zeros((HEMISPHERE_ROWS, 16, 3), dtype=np.float32)
    rows[: (HEMISPHERE_ROWS - 1) // 2 + 1] = np.array([float(x) for x in radiance], dtype=np.float32)
    mi.Bitmap(rows).write(out_path)
    # As `mitsuba_envmap`: local y is our y, so the rows run from +y to -y.
    m = mi.ScalarTransform4f([[0, 0, 1, 0], [0, 1, 0, 0], [-1, 0, 0, 0], [0, 0, 0, 1]])
    return {"type": "envmap", "filename": out_path, "to_world": m, "scale": 1.0}


def check_hemisphere(scene, radiance):
    """Mitsuba's lookup of the hemisphere map against ours (L above the horizon, 0 below) in
    4096 directions outside the band under the horizon; a mismatch refuses the scene."""
    import mitsuba as mi

    env = scene.environment()
    band = np.sin(np.pi / (HEMISPHERE_ROWS - 1))
    rng = np.random.default_rng(6)
    d = rng.normal(size=(4096, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[0] = [0.6, 1e-9, 0.8]  # just above the horizon: exactly L
    L = np.array([float(x) for x in radiance])
    for k in range(len(d)):
        if -band <= d[k, 1] <= 0:
            continue
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*(-d[k]))
        got = np.array(env.eval(si), dtype=np.float64)[:3]
        want = L if d[k, 1] > 0 else 0 * L
        if np.abs(got - want).max() > 1e-5 * max(L.max(), 1e-30):
            refuse(f"Mitsuba's hemisphere map gives {got.tolist()} in direction {d[k].tolist()}, ours {want.tolist()}")


def check_envmap(scene, tex):
    import mitsuba as mi

    env = scene.environment()
    rng = np.random.default_rng(5)
    d = rng.normal(size=(4096, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    ours = cs184_lookup(tex.astype(np.float64), d)
    theirs = np.empty_like(ours)
    for k in range(len(d)):
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*(-d[k]))
        theirs[k] = np.array(env.eval(si), dtype=np.float64)[:3]
    err = np.abs(theirs - ours) / (np.abs(ours) + 1e-3)
    if err.max() > 1e-3:
        k = int(np.argmax(err.max(axis=1)))
        refuse(f"Mitsuba's envmap lookup differs from ours by {err.max():.3g} (direction {d[k].tolist()}: {theirs[k].tolist()} vs {ours[k].tolist()})")


def bsdf_of(s):
    b = s.get("bsdf", {"type": "diffuse"})
    t = b["type"]
    if t in ("diffuse", "emission"):
        if not s.get("bsdf_two_sided", False):
            refuse(f"shape {s['id']}: one-sided diffuse")
        return {"type": "twosided", "material": {"type": "diffuse", "reflectance": rgb(s["albedo"])}}
    if t == "mirror":
        return {"type": "twosided", "material": {"type": "conductor", "material": "none", "specular_reflectance": rgb(b["reflectance"])}}
    if t == "glass":
        if b["roughness"] != 0:
            refuse(f"shape {s['id']}: rough glass")
        return {"type": "dielectric", "int_ior": float(b["ior"]), "ext_ior": 1.0, "specular_reflectance": rgb(b["reflectance"]),
                "specular_transmittance": rgb(b["transmittance"])}
    if t == "microfacet":
        return {"type": "roughconductor", "distribution": "beckmann", "alpha": float(b["alpha"]), "eta": rgb(b["eta"]), "k": rgb(b["k"])}
    refuse(f"shape {s['id']}: {t} (CS184's refraction transmits everything with no Fresnel term; no Mitsuba BSDF does)")


def scene_dict(spec, folder, max_depth, integrator="path"):
    import mitsuba as mi

    cam = spec["camera"]
    origin = cam["origin"]
    target = [o + f for o, f in zip(origin, cam["forward"])]
    d = {
        "type": "scene",
        "integrator": {"type": integrator, "max_depth": max_depth + 1, "rr_depth": 5, "hide_emitters": False},
        "sensor": {
            "type": "thinlens" if cam.get("lens_radius", 0) > 0 else "perspective",
            "fov": cam["fov_x_deg"],
            "fov_axis": "x",
            "near_clip": max(cam["near"], 1e-4),
            "far_clip": min(float("inf") if cam["far"] is None else cam["far"], 1e7),  # null: no far plane
            "to_world": mi.ScalarTransform4f().look_at(origin=origin, target=target, up=cam["up"]),
            "sampler": {"type": "independent"},
            "film": {
                "type": "hdrfilm",
                "width": cam["width"],
                "height": cam["height"],
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
                "component_format": "float32",
            },
        },
    }
    if cam.get("lens_radius", 0) > 0:
        d["sensor"]["aperture_radius"] = float(cam["lens_radius"])
        d["sensor"]["focus_distance"] = float(cam["focal_distance"])
    for s in spec["shapes"]:
        if not s.get("emission_one_sided", False):
            refuse(f"shape {s['id']}: only one-sided emission is modelled")
        bsdf = bsdf_of(s)
        if s["type"] == "mesh":
            path = os.path.join(folder, s["file"])
            _, normals, _ = read_obj(path)
            zero = sum(1 for n in normals if not (n[0] * n[0] + n[1] * n[1] + n[2] * n[2] > 0.25))
            if zero:
                refuse(f"shape {s['id']}: {zero} vertex normals of zero length (vertices of degenerate triangles only, "
                       "where ours interpolates the others): Mitsuba's OBJ loader rejects the mesh")
            shape = {"type": "obj", "filename": path, "face_normals": False, "bsdf": bsdf}
        elif s["type"] == "sphere":
            shape = {"type": "sphere", "center": s["center"], "radius": s["radius"], "bsdf": bsdf}
        else:
            refuse(f"shape type {s['type']}")
        if max(s["emission"]) > 0:
            shape["emitter"] = {"type": "area", "radiance": rgb(s["emission"])}
        d[f"shape{s['id']}"] = shape
    for i, l in enumerate(spec["lights"]):
        t = l["type"]
        if t == "emissive_shape":
            continue
        if t == "point":
            d[f"light{i}"] = {"type": "point", "position": l["position"], "intensity": rgb(l["intensity"])}
        elif t == "directional":
            d[f"light{i}"] = {"type": "directional", "direction": [-x for x in l["to_light"]], "irradiance": rgb(l["irradiance"])}
        elif t == "hemisphere":
            if [float(x) for x in l["up"]] != [0.0, 1.0, 0.0]:
                refuse("hemisphere light around an axis other than +y")
            if "_env_texels" in d or "_hemisphere" in d:
                refuse("a hemisphere light and an environment map together (Mitsuba takes one environment)")
            d[f"light{i}"] = hemisphere_envmap(l["radiance"], os.path.join(folder, "hemisphere_mitsuba.exr"))
            d["_hemisphere"] = l["radiance"]
        elif t == "rect":
            refuse("rectangle light that rays cannot hit: every Mitsuba emitter shape also occludes")
        elif t == "environment":
            if "_env_texels" in d or "_hemisphere" in d:
                refuse("a hemisphere light and an environment map together (Mitsuba takes one environment)")
            tex = np.array(mi.Bitmap(os.path.join(folder, l["file"])), dtype=np.float64)[..., :3]
            d[f"light{i}"] = mitsuba_envmap(tex, os.path.join(folder, "environment_mitsuba.exr"))
            d["_env_texels"] = tex
        else:
            refuse(f"light type {t}")
    return d


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("scene", help="folder with scene.json")
    ap.add_argument("--max-depth", type=int, required=True, help="our -m")
    ap.add_argument("--spp", type=int, required=True, help="samples per pixel per render")
    ap.add_argument("--renders", type=int, default=16, help="independent renders (for the variance)")
    ap.add_argument("--out", required=True, help="output prefix: <out>.exr, <out>_var.exr, <out>.json")
    ap.add_argument("--ladder", default="", help="also time single renders at these spp (comma-separated): <out>_spp<N>_k<K>.exr")
    ap.add_argument("--integrator", choices=["path", "ptracer"], default="path", help="Mitsuba's path tracer, or its particle tracer")
    ap.add_argument("--ladder-seeds", type=int, default=1, help="independent renders per ladder rung (their spread is the rung's error, their median time its time)")
    args = ap.parse_args()
    import time

    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    with open(os.path.join(args.scene, "scene.json")) as f:
        spec = json.load(f)
    sd = scene_dict(spec, args.scene, args.max_depth, args.integrator)
    tex = sd.pop("_env_texels", None)
    hemisphere = sd.pop("_hemisphere", None)
    scene = mi.load_dict(sd)
    if tex is not None:
        check_envmap(scene, tex)
    if hemisphere is not None:
        check_hemisphere(scene, hemisphere)
    # The first render of a loaded scene pays one-time costs (thread pool, caches): an
    # untimed 1-spp render first, so neither the renders nor the ladder carry them.
    mi.render(scene, spp=1, seed=0)
    t0 = time.time()
    images = []
    for k in range(args.renders):
        images.append(np.array(mi.render(scene, spp=args.spp, seed=1 + k), dtype=np.float64))
    seconds = time.time() - t0
    if images:
        stack = np.stack(images)
        mean = stack.mean(axis=0)
        var_of_mean = stack.var(axis=0, ddof=1) / args.renders
        mi.Bitmap(mean.astype(np.float32)).write(args.out + ".exr")
        mi.Bitmap(var_of_mean.astype(np.float32)).write(args.out + "_var.exr")
        with open(args.out + ".json", "w") as f:
            json.dump({"renderer": f"mitsuba {mi.__version__} scalar_rgb" + (" ptracer" if args.integrator == "ptracer" else ""), "spp": args.spp * args.renders, "renders": args.renders, "seconds": seconds,
                       "image_means": [float(i.mean()) for i in images]}, f)
        print(f"mitsuba: {args.renders} x {args.spp} spp in {seconds:.1f} s")
    # The ladder: rung by rung, seed by seed, each render timed on its own (scene
    # loading excluded, as for every renderer).
    ladder = []
    for n in [int(x) for x in args.ladder.split(",") if x]:
        for k in range(args.ladder_seeds):
            t0 = time.time()
            img = np.array(mi.render(scene, spp=n, seed=1000 + n + 7919 * k), dtype=np.float32)
            ladder.append({"spp": n, "seed_index": k, "seconds": time.time() - t0, "file": f"{args.out}_spp{n}_k{k}.exr"})
            mi.Bitmap(img).write(ladder[-1]["file"])
    if ladder:
        with open(args.out + "_ladder.json", "w") as f:
            json.dump(ladder, f)


if __name__ == "__main__":
    main()
