#!/usr/bin/env python3
"""Render an exported scene (scene.json from `pathtracer export`) with POV-Ray 3.7:

* `object-id`, `depth`: the intersection checks, a flat colour per object or the distance
  from the camera, one ray through each pixel centre (no anti-aliasing), as ours at -s 1;
* `radiance`: direct lighting (our -m 1) from point lights and emissive rectangles, as
  independent renders (--renders K) for the harness's statistics. POV-Ray has no seed, so
  the randomness is ours: each render places the rectangle's N×N lightlets (cosine
  spotlights, docs/validation/README.md) jittered in their strata with its own seed, and shifts the
  whole camera grid by a random sub-pixel offset while rendering S×S rays per pixel (one
  ray per sub-pixel, no POV-Ray anti-aliasing) that the harness box-averages: a randomly
  shifted stratified estimate of the box-filtered pixel. Each render is thus an unbiased
  estimate of the direct-lighting image, up to POV-Ray's half-float output.

Conventions (docs/validation/README.md, measured): `#version 3.7`, assumed_gamma 1,
no ambient; objects finish { emission 1 diffuse 0 } so the pixel is the pigment; OpenEXR
output (+FE), which POV-Ray writes as *half* floats (11-bit mantissa: the harness allows
2^-11 relative for depth; the id colours are multiples of 1/8, exact in half). The camera is
given as explicit direction/right/up vectors (no look_at, which would re-derive them
left-handed): the ray through image point (s, t) in [-1/2, 1/2]² is
direction + s·right + t·up, as ours. Meshes become mesh2 (POV-Ray drops degenerate
triangles, as we never hit them), spheres exact spheres.
"""
import argparse
import json
import math
import os
import subprocess
import sys

from mesh_io import Unrepresentable, cross, dot, norm, read_obj, rectangle_of, sub


def refuse(msg):
    print(f"pov_ref: cannot represent exactly: {msg}", file=sys.stderr)
    sys.exit(3)


def vec(v):
    return "<{:.9g},{:.9g},{:.9g}>".format(*v)


def pov_scene(spec, folder, mode, shift=(0.0, 0.0), supersample=1, lightlets=None, rng=None):
    cam = spec["camera"]
    o = cam["origin"]
    w, h = cam["width"], cam["height"]
    tx = math.tan(math.radians(cam["fov_x_deg"]) / 2)
    ty = tx * h / w
    right = [2 * tx * c for c in cam["right"]]
    up = [2 * ty * c for c in cam["up"]]
    # A shift of the image plane by (sx, sy) rendered pixels: x right, y down.
    sx, sy = shift[0] / (w * supersample), shift[1] / (h * supersample)
    direction = [f + sx * r - sy * u for f, r, u in zip(cam["forward"], right, up)]
    lines = [
        "#version 3.7;",
        "global_settings { assumed_gamma 1.0 ambient_light 0 max_trace_level 5 adc_bailout 0 }",
        "#default { finish { ambient 0 emission 0 diffuse 1 brilliance 1 specular 0 phong 0 } }",
        "background { rgb 0 }",
        f"camera {{ perspective location {vec(o)} direction {vec(direction)} right {vec(right)} up {vec(up)} }}",
    ]
    if spec["camera"].get("lens_radius", 0) > 0:
        refuse("a thin-lens camera (POV-Ray's focal blur samples its aperture adaptively, not as a uniform disk per ray)")
    if mode == "radiance":
        for s in spec["shapes"]:
            t = s.get("bsdf", {"type": "diffuse"})["type"]
            if t not in ("diffuse", "emission"):
                refuse(f"shape {s['id']}: {t} (POV-Ray validates direct lighting of diffuse surfaces only)")
        lines += radiance_lights(spec, folder, lightlets, rng)
    # The farthest any visible point can be: bounds of every shape, from the camera.
    far = 0.0
    for s in spec["shapes"]:
        if s["type"] == "mesh":
            verts, _, faces = read_obj(os.path.join(folder, s["file"]))
            if not faces:
                refuse(f"shape {s['id']}: empty mesh")
            far = max(far, max(math.dist(o, v) for v in verts))
        elif s["type"] == "sphere":
            far = max(far, math.dist(o, s["center"]) + s["radius"])
    dmax = far * 1.01 + 1e-6
    for s in spec["shapes"]:
        if mode == "radiance":
            if max(s["emission"]) > 0:
                continue  # drawn by radiance_lights
            # POV-Ray's diffuse term has no 1/π; the lights' colours carry it.
            tex = f"texture {{ pigment {{ rgb {vec(s['albedo'])} }} finish {{ diffuse 1 }} }}"
        elif mode == "object-id":
            tex = f"texture {{ pigment {{ rgb {vec(s['id_colour'])} }} finish {{ emission 1 diffuse 0 ambient 0 }} }}"
        else:
            # The pigment function must stay in [0, 1]; the colour map scales it back.
            f = f"sqrt(pow(x-({o[0]:.9g}),2)+pow(y-({o[1]:.9g}),2)+pow(z-({o[2]:.9g}),2))/{dmax:.9g}"
            tex = (f"texture {{ pigment {{ function {{ {f} }} color_map {{ [0 rgb 0] [1 rgb {dmax:.9g}] }} }} "
                   "finish { emission 1 diffuse 0 ambient 0 } }")
        if s["type"] == "mesh":
            verts, _, faces = read_obj(os.path.join(folder, s["file"]))
            body = [f"mesh2 {{ vertex_vectors {{ {len(verts)}"]
            body += ["," + vec(v) for v in verts]
            body += [f"}} face_indices {{ {len(faces)}"]
            for fc in faces:
                if len(fc) != 3:
                    refuse(f"shape {s['id']}: a face with {len(fc)} vertices")
                body.append(",<{},{},{}>".format(*fc))
            body += ["}", tex, "}"]
            lines.append("\n".join(body))
        elif s["type"] == "sphere":
            lines.append(f"sphere {{ {vec(s['center'])}, {s['radius']:.9g} {tex} }}")
        else:
            refuse(f"shape type {s['type']}")
    return "\n".join(lines) + "\n", w, h


FADE = 1e-3  # fade_distance: fade = 2/(1+(d/FADE)^2) = 2·FADE²/d² to a relative 1e-6 at d >= 1


def radiance_lights(spec, folder, n, rng):
    """Point lights and emissive rectangles as POV-Ray lights (measured): a
    light of colour C gives pigment·cosθ·C·fade, so intensity I becomes colour I/(2π·FADE²);
    a rectangle of radiance L and area A becomes n×n cosine spotlights of colour
    L·A/(2π·FADE²·n²) at jittered stratified points, plus a no_shadow polygon that shows L
    to the camera."""
    out = []
    k = 1.0 / (2 * math.pi * FADE * FADE)
    emitters = []
    for s in spec["shapes"]:
        if max(s["emission"]) <= 0:
            continue
        if s["type"] != "mesh":
            refuse(f"shape {s['id']}: an emissive {s['type']} (only rectangles become POV-Ray lights)")
        verts, _, faces = read_obj(os.path.join(folder, s["file"]))
        rect = rectangle_of(verts, faces)
        if rect is None:
            refuse(f"shape {s['id']} ({s['name']}): an emissive mesh that is not one rectangle")
        emitters.append((s, rect))
    for l in spec["lights"]:
        if l["type"] == "emissive_shape":
            continue
        if l["type"] != "point":
            refuse(f"{l['type']} light (POV-Ray direct lighting is validated for point lights and rectangles only)")
        out.append(f"light_source {{ {vec(l['position'])} color rgb {vec([c * k for c in l['intensity']])} fade_distance {FADE} fade_power 2 }}")
    cam = spec["camera"]["origin"]
    for s, (c, u, v, nrm) in emitters:
        if dot(sub(cam, c), nrm) <= 0:
            refuse(f"shape {s['id']}: the camera sees the emitter from behind (POV-Ray's polygon would show it)")
        for l in spec["lights"]:
            if l["type"] == "point" and dot(sub(l["position"], c), nrm) < -1e-6 * norm(u):
                refuse(f"shape {s['id']}: a point light behind the emitter (its no_shadow polygon would not shadow it)")
        area = norm(cross(u, v))
        col = [L * area * k / (n * n) for L in s["emission"]]
        for i in range(n):
            for j in range(n):
                a, b = (i + rng.random()) / n, (j + rng.random()) / n
                p = [c0 + a * u0 + b * v0 for c0, u0, v0 in zip(c, u, v)]
                out.append(f"light_source {{ {vec(p)} color rgb {vec(col)} spotlight point_at {vec([p0 + n0 for p0, n0 in zip(p, nrm)])} "
                           f"radius 90 falloff 90 tightness 1 fade_distance {FADE} fade_power 2 }}")
        corners = [c, [a + b for a, b in zip(c, u)], [a + b + d for a, b, d in zip(c, u, v)], [a + d for a, d in zip(c, v)]]
        out.append(f"polygon {{ 5, {', '.join(vec(q) for q in corners + [c])} texture {{ pigment {{ rgb {vec(s['emission'])} }} "
                   "finish { emission 1 diffuse 0 ambient 0 } } no_shadow }")
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("scene", help="folder with scene.json")
    ap.add_argument("--mode", choices=["object-id", "depth", "radiance"], required=True)
    ap.add_argument("--out", required=True, help="output EXR (radiance: prefix of <out>_r<k>.exr and <out>_pov.json)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--renders", type=int, default=16, help="radiance: independent renders")
    ap.add_argument("--supersample", type=int, default=4, help="radiance: rays per pixel along each axis")
    ap.add_argument("--lightlets", type=int, default=8, help="radiance: lightlets per rectangle along each edge")
    args = ap.parse_args()
    with open(os.path.join(args.scene, "scene.json")) as f:
        spec = json.load(f)
    if args.mode != "radiance":
        text, w, h = pov_scene(spec, args.scene, args.mode)
        render(text, args.out, w, h, args.threads)
        return
    import random
    import time

    meta = {"renderer": "POV-Ray 3.7 (direct lighting, lightlet grid)", "supersample": args.supersample, "lightlets": args.lightlets, "renders": []}
    for k in range(args.renders):
        rng = random.Random(1 + k)
        # Sub-pixel k of a pixel is then sampled at (k + U)/S, U uniform in [0, 1).
        shift = (rng.random() - 0.5, rng.random() - 0.5)
        text, w, h = pov_scene(spec, args.scene, "radiance", shift, args.supersample, args.lightlets, rng)
        out = f"{args.out}_r{k}.exr"
        t0 = time.time()
        render(text, out, w * args.supersample, h * args.supersample, args.threads)
        meta["renders"].append({"file": out, "seconds": time.time() - t0})
    with open(args.out + "_pov.json", "w") as f:
        json.dump(meta, f)


def render(text, out, w, h, threads):
    pov = out[:-4] + ".pov" if out.endswith(".exr") else out + ".pov"
    with open(pov, "w") as f:
        f.write(text)
    cmd = ["povray", f"+I{pov}", f"+O{out}", "+FE", f"+W{w}", f"+H{h}", f"+WT{threads}", "-A", "-D", "-V", "-GA"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0 or not os.path.exists(out):
        sys.exit(f"pov_ref: {' '.join(cmd)} failed (rc {r.returncode}):\n{r.stderr[-2000:]}")


if __name__ == "__main__":
    try:
        main()
    except Unrepresentable as e:
        refuse(str(e))
