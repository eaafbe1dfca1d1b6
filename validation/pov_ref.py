#!/usr/bin/env python3
"""Render an exported scene (scene.json from `pathtracer export`) with POV-Ray 3.7, for the
intersection checks: a flat colour per object (`object-id`) or the distance from the camera
(`depth`), one ray through each pixel centre (no anti-aliasing), as ours at -s 1.

Conventions (../shared/notes/references.md, measured): `#version 3.7`, assumed_gamma 1,
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


def refuse(msg):
    print(f"pov_ref: cannot represent exactly: {msg}", file=sys.stderr)
    sys.exit(3)


def vec(v):
    return "<{:.9g},{:.9g},{:.9g}>".format(*v)


def read_obj(path):
    verts, faces = [], []
    with open(path) as f:
        for line in f:
            if line.startswith("v "):
                verts.append(tuple(float(x) for x in line.split()[1:4]))
            elif line.startswith("f "):
                faces.append(tuple(int(w.split("/")[0]) - 1 for w in line.split()[1:]))
    return verts, faces


def pov_scene(spec, folder, mode):
    cam = spec["camera"]
    o = cam["origin"]
    w, h = cam["width"], cam["height"]
    tx = math.tan(math.radians(cam["fov_x_deg"]) / 2)
    ty = tx * h / w
    right = [2 * tx * c for c in cam["right"]]
    up = [2 * ty * c for c in cam["up"]]
    lines = [
        "#version 3.7;",
        "global_settings { assumed_gamma 1.0 ambient_light 0 max_trace_level 1 }",
        "background { rgb 0 }",
        f"camera {{ perspective location {vec(o)} direction {vec(cam['forward'])} right {vec(right)} up {vec(up)} }}",
    ]
    # The farthest any visible point can be: bounds of every shape, from the camera.
    far = 0.0
    for s in spec["shapes"]:
        if s["type"] == "mesh":
            verts, faces = read_obj(os.path.join(folder, s["file"]))
            if not faces:
                refuse(f"shape {s['id']}: empty mesh")
            far = max(far, max(math.dist(o, v) for v in verts))
        elif s["type"] == "sphere":
            far = max(far, math.dist(o, s["center"]) + s["radius"])
    dmax = far * 1.01 + 1e-6
    for s in spec["shapes"]:
        if mode == "object-id":
            tex = f"texture {{ pigment {{ rgb {vec(s['id_colour'])} }} finish {{ emission 1 diffuse 0 ambient 0 }} }}"
        else:
            # The pigment function must stay in [0, 1]; the colour map scales it back.
            f = f"sqrt(pow(x-({o[0]:.9g}),2)+pow(y-({o[1]:.9g}),2)+pow(z-({o[2]:.9g}),2))/{dmax:.9g}"
            tex = (f"texture {{ pigment {{ function {{ {f} }} color_map {{ [0 rgb 0] [1 rgb {dmax:.9g}] }} }} "
                   "finish { emission 1 diffuse 0 ambient 0 } }")
        if s["type"] == "mesh":
            verts, faces = read_obj(os.path.join(folder, s["file"]))
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


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("scene", help="folder with scene.json")
    ap.add_argument("--mode", choices=["object-id", "depth"], required=True)
    ap.add_argument("--out", required=True, help="output EXR")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    with open(os.path.join(args.scene, "scene.json")) as f:
        spec = json.load(f)
    text, w, h = pov_scene(spec, args.scene, args.mode)
    pov = args.out[:-4] + ".pov" if args.out.endswith(".exr") else args.out + ".pov"
    with open(pov, "w") as f:
        f.write(text)
    cmd = ["povray", f"+I{pov}", f"+O{args.out}", "+FE", f"+W{w}", f"+H{h}", f"+WT{args.threads}", "-A", "-D", "-V", "-GA"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0 or not os.path.exists(args.out):
        sys.exit(f"pov_ref: {' '.join(cmd)} failed (rc {r.returncode}):\n{r.stderr[-2000:]}")


if __name__ == "__main__":
    main()
