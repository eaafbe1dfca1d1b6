#!/usr/bin/env python3
"""Render a reference for an exported scene (scene.json from `pathtracer export`) with
Mitsuba 3 (scalar_rgb), as R independent renders whose per-pixel mean and variance of the
mean are written as OpenEXR.

Conventions (../shared/notes/references.md, measured): perspective sensor with the horizontal
field of view, box pixel filter, linear float RGB film, `path` integrator with
max_depth = our -m + 1 (Mitsuba counts emitter hits as a depth), diffuse BSDFs wrapped in
`twosided` (ours reflect from both sides), area emitters one-sided along the geometric normal
(ours too). Anything Mitsuba cannot represent exactly is refused, never approximated.
"""
import argparse
import json
import os
import sys

import numpy as np


def refuse(msg):
    print(f"mitsuba_ref: cannot represent exactly: {msg}", file=sys.stderr)
    sys.exit(3)


def rgb(v):
    return {"type": "rgb", "value": [float(x) for x in v]}


def scene_dict(spec, folder, max_depth):
    import mitsuba as mi

    cam = spec["camera"]
    origin = cam["origin"]
    target = [o + f for o, f in zip(origin, cam["forward"])]
    d = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": max_depth + 1, "rr_depth": 5, "hide_emitters": False},
        "sensor": {
            "type": "perspective",
            "fov": cam["fov_x_deg"],
            "fov_axis": "x",
            "near_clip": max(cam["near"], 1e-4),
            "far_clip": min(cam["far"], 1e7),
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
    for s in spec["shapes"]:
        if not s.get("bsdf_two_sided", False) or not s.get("emission_one_sided", False):
            refuse(f"shape {s['id']}: only two-sided diffuse and one-sided emission are modelled")
        bsdf = {"type": "twosided", "material": {"type": "diffuse", "reflectance": rgb(s["albedo"])}}
        if s["type"] == "mesh":
            shape = {"type": "obj", "filename": os.path.join(folder, s["file"]), "face_normals": False, "bsdf": bsdf}
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
            refuse("hemisphere light (radiance over y > 0 only): Mitsuba's constant emitter covers the whole sphere")
        elif t == "rect":
            refuse("rectangle light that rays cannot hit: every Mitsuba emitter shape also occludes")
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
    ap.add_argument("--ladder", default="", help="also time single renders at these spp (comma-separated): <out>_spp<N>.exr")
    args = ap.parse_args()
    import time

    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    with open(os.path.join(args.scene, "scene.json")) as f:
        spec = json.load(f)
    scene = mi.load_dict(scene_dict(spec, args.scene, args.max_depth))
    t0 = time.time()
    images = []
    for k in range(args.renders):
        images.append(np.array(mi.render(scene, spp=args.spp, seed=1 + k), dtype=np.float64))
    seconds = time.time() - t0
    stack = np.stack(images)
    mean = stack.mean(axis=0)
    var_of_mean = stack.var(axis=0, ddof=1) / args.renders
    mi.Bitmap(mean.astype(np.float32)).write(args.out + ".exr")
    mi.Bitmap(var_of_mean.astype(np.float32)).write(args.out + "_var.exr")
    with open(args.out + ".json", "w") as f:
        json.dump({"renderer": f"mitsuba {mi.__version__} scalar_rgb", "spp": args.spp * args.renders, "renders": args.renders, "seconds": seconds,
                   "image_means": [float(i.mean()) for i in images]}, f)
    ladder = []
    for n in [int(x) for x in args.ladder.split(",") if x]:
        t0 = time.time()
        img = np.array(mi.render(scene, spp=n, seed=1000 + n), dtype=np.float32)
        ladder.append({"spp": n, "seconds": time.time() - t0, "file": f"{args.out}_spp{n}.exr"})
        mi.Bitmap(img).write(ladder[-1]["file"])
    with open(args.out + "_ladder.json", "w") as f:
        json.dump(ladder, f)
    print(f"mitsuba: {args.renders} x {args.spp} spp in {seconds:.1f} s")


if __name__ == "__main__":
    main()
