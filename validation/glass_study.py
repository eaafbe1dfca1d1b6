#!/usr/bin/env python3
"""Glass against its closed form, in our renderer and in each reference: which part of a
smooth dielectric a reference renders differently, if any.

Scenes (written here as CS184 COLLADA, Le = 1 everywhere, no other light, a black world),
each seen through a narrow field of view (rays within about 1 degree of the axis):

  slab_clear        an untinted glass slab (ior 1.45) face-on, an emissive wall behind it:
                    T^2 (1 - F) / (1 + F), F the exact Fresnel reflectance at the ray's angle
                    (every internal reflection summed; the front reflection sees black)
  slab_tinted       the same slab with transmittance (1, 0.75, 0.75) per crossing
  slab_grazing      the tinted slab turned 70 degrees: the front reflection and every
                    internal reflection land on the emissive wall too, so the pixel is
                    F + (1 - F) T^2 (reflectance 1)
  prism_tir         a tinted 45-degree prism, seen face-on: the ray enters, is totally
                    reflected by the hypotenuse (45 > 43.6 degrees, the critical angle), and
                    leaves through the other face onto an emissive wall at its side:
                    T^2 (1 - F) / (1 + F), with F at normal incidence (the pixels whose ray
                    meets the hypotenuse past the critical angle by a margin)
  prism_smooth      the same prism with its vertices shared, so that its shading normals are
                    interpolated across its edges (as the loader, like CS184, does for every
                    mesh, CBgems' gems among them): no closed form; each image's mean
                    against ours
  gem_smooth        a smooth-shaded octahedron before an emissive wall, the same way

(The scenes' faces are flat unless said: no vertex is shared between triangles.) For each
scene with a closed form: the ratio of the image to the closed form over the pixels where the closed form
holds, per channel, as mean +- standard error over independent renders, for ours, Mitsuba 3 and
Cycles (each through the harness's exporter; Cycles with --smooth-glass, which renders the
smooth-shaded glass its exporter otherwise refuses). Run after validation/setup:

  validation/.venv/bin/python validation/glass_study.py [--spp 256] [--renders 4] [--out DIR]
"""
import argparse
import json
import math
import os
import shutil
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
from images import read_exr  # noqa: E402
from run_cases import cycles_ref_command  # noqa: E402

IOR = 1.45
TINT = (1.0, 0.75, 0.75)
W, H = 64, 48
DEPTH = 10


def fresnel(cos_i, eta=IOR):
    """Unpolarised Fresnel reflectance of a smooth dielectric, light arriving from outside."""
    cos_i = abs(cos_i)
    sin_t2 = (1 - cos_i * cos_i) / (eta * eta)
    if sin_t2 >= 1:
        return 1.0
    cos_t = math.sqrt(1 - sin_t2)
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 0.5 * (rs * rs + rp * rp)


# ---- the scenes ----

def rot_y(deg):
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return lambda p: (c * p[0] + s * p[2], p[1], -s * p[0] + c * p[2])


def flat(mesh):
    """The mesh with no vertex shared between triangles: the loader (as CS184) gives each
    vertex the area-weighted mean of its triangles' normals, so only unshared vertices keep
    flat faces."""
    v, t = mesh
    return [v[i] for tri in t for i in tri], [(3 * k, 3 * k + 1, 3 * k + 2) for k in range(len(t))]


def box(sx, sy, sz, xf=lambda p: p):
    """A closed box centred at the origin, 12 outward-wound triangles with flat faces."""
    v = [xf((((i & 1) * 2 - 1) * sx / 2, ((i >> 1 & 1) * 2 - 1) * sy / 2, ((i >> 2 & 1) * 2 - 1) * sz / 2)) for i in range(8)]
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    return flat((v, [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]))


def octahedron(r, centre):
    """A closed octahedron with shared vertices: smooth shading normals, as a CS184 gem."""
    c = np.array(centre, float)
    v = [tuple(c + r * np.array(d, float)) for d in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))]
    tris = [(0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4), (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)]
    return v, tris


def prism(shared=False):
    """The right-angle prism: entry face z = 0 (x in [-1, 1]), exit face x = 1, hypotenuse from
    (1, -2) to (-1, 0) in (x, z); y in [-3, 3]. Flat faces unless `shared` (smooth normals)."""
    xz = [(-1, 0), (1, 0), (1, -2)]
    v = [(x, y, z) for y in (-3, 3) for (x, z) in xz]
    # 0..2 at y = -3, 3..5 at y = 3
    tris = [(0, 2, 1), (3, 4, 5), (0, 1, 4), (0, 4, 3), (1, 2, 5), (1, 5, 4), (2, 0, 3), (2, 3, 5)]
    return (v, tris) if shared else flat((v, tris))


def quad(centre, u, v):
    """A rectangle, wound so that its normal is u x v."""
    c = np.array(centre, float)
    u, v = np.array(u, float), np.array(v, float)
    return [tuple(c - u - v), tuple(c + u - v), tuple(c + u + v), tuple(c - u + v)], [(0, 1, 2), (0, 2, 3)]


def collada(meshes, xfov):
    """meshes: [(name, (vertices, triangles), cgl_material_xml)]; the camera looks along -z."""
    fx = lambda xs: " ".join(f"{x:.9g}" for x in xs)
    effects, materials, geometries, nodes = [], [], [], []
    for name, (v, t), cgl in meshes:
        effects.append(f'<effect id="{name}-effect"><profile_COMMON><technique sid="common"><phong><diffuse><color sid="diffuse">0 0 0 1</color></diffuse></phong></technique></profile_COMMON>'
                       f'<extra><technique profile="CGL">{cgl}</technique></extra></effect>')
        materials.append(f'<material id="{name}-material" name="{name}"><instance_effect url="#{name}-effect"/></material>')
        pos = [c for p in v for c in p]
        idx = [i for tri in t for i in tri]
        geometries.append(
            f'<geometry id="{name}-mesh" name="{name}"><mesh><source id="{name}-pos"><float_array id="{name}-pos-array" count="{len(pos)}">{fx(pos)}</float_array>'
            f'<technique_common><accessor source="#{name}-pos-array" count="{len(v)}" stride="3"><param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/></accessor></technique_common></source>'
            f'<vertices id="{name}-vtx"><input semantic="POSITION" source="#{name}-pos"/></vertices>'
            f'<triangles material="{name}-material" count="{len(t)}"><input semantic="VERTEX" source="#{name}-vtx" offset="0"/><p>{" ".join(map(str, idx))}</p></triangles></mesh></geometry>')
        nodes.append(f'<node id="{name}" name="{name}" type="NODE"><matrix sid="transform">1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1</matrix>'
                     f'<instance_geometry url="#{name}-mesh"><bind_material><technique_common><instance_material symbol="{name}-material" target="#{name}-material"/></technique_common></bind_material></instance_geometry></node>')
    camera = (f'<camera id="cam" name="cam"><optics><technique_common><perspective><xfov sid="xfov">{xfov:.9g}</xfov><aspect_ratio>{W / H:.9g}</aspect_ratio>'
              f'<znear sid="znear">0.01</znear><zfar sid="zfar">10000</zfar></perspective></technique_common></optics></camera>')
    nodes.append('<node id="Camera" name="Camera" type="NODE"><matrix sid="transform">1 0 0 0 0 1 0 0 0 0 1 10 0 0 0 1</matrix><instance_camera url="#cam"/></node>')
    return ('<?xml version="1.0" encoding="utf-8"?>\n<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">'
            '<asset><unit name="meter" meter="1"/><up_axis>Y_UP</up_axis></asset>'
            f'<library_cameras>{camera}</library_cameras><library_effects>{"".join(effects)}</library_effects>'
            f'<library_materials>{"".join(materials)}</library_materials><library_geometries>{"".join(geometries)}</library_geometries>'
            f'<library_visual_scenes><visual_scene id="Scene" name="Scene">{"".join(nodes)}</visual_scene></library_visual_scenes>'
            '<scene><instance_visual_scene url="#Scene"/></scene></COLLADA>\n')


def glass(tint):
    t = " ".join(f"{c:g}" for c in tint)
    return f"<glass><reflectance>1 1 1</reflectance><transmittance>{t}</transmittance><roughness>0</roughness><ior>{IOR:g}</ior></glass>"


EMITTER = "<emission><radiance>1 1 1</radiance></emission>"


def scenes():
    """name -> (meshes, xfov, closed form: f(origin, dir) -> (rgb or None where it does not hold))."""
    out = {}
    slab = box(6, 6, 0.1)
    wall = quad((0, 0, -3), (40, 0, 0), (0, 40, 0))

    def face_on(tint, half):
        def f(o, d):
            t = -o[2] / d[2]  # the plane z = 0
            x, y = o[0] + t * d[0], o[1] + t * d[1]
            if abs(x) > half or abs(y) > half:
                return None
            fr = fresnel(-d[2] / np.linalg.norm(d))
            return [c * c * (1 - fr) / (1 + fr) for c in tint]
        return f

    out["slab_clear"] = ([("slab", slab, glass((1, 1, 1))), ("wall", wall, EMITTER)], 4.0, face_on((1, 1, 1), 2.0))
    out["slab_tinted"] = ([("slab", slab, glass(TINT)), ("wall", wall, EMITTER)], 4.0, face_on(TINT, 2.0))
    turn = rot_y(70)
    long_slab = box(12, 6, 0.1, turn)
    far_wall = quad((0, 0, -12), (80, 0, 0), (0, 80, 0))
    n = np.array(turn((0, 0, 1)))

    def grazing(o, d):
        # The turned slab's front face: the plane through n * 0.05 with normal n.
        t = (0.05 - np.dot(n, o)) / np.dot(n, d)
        p = np.asarray(o) + t * np.asarray(d)
        u = np.array(turn((1, 0, 0)))
        if abs(np.dot(p, u)) > 4.0 or abs(p[1]) > 2.0:
            return None
        fr = fresnel(np.dot(n, d) / np.linalg.norm(d))
        return [fr + (1 - fr) * c * c for c in TINT]

    out["slab_grazing"] = ([("slab", long_slab, glass(TINT)), ("wall", far_wall, EMITTER)], 4.0, grazing)
    # Facing -x, towards the prism: (0, 0, 2.5) x (0, 4, 0) = (-10, 0, 0).
    side_wall = quad((3, 0, -1), (0, 0, 2.5), (0, 4, 0))

    def tir(o, d):
        t = -o[2] / d[2]
        x, y = o[0] + t * d[0], o[1] + t * d[1]
        if abs(x) > 0.95 or abs(y) > 2.0:
            return None
        # Only rays totally reflected at the hypotenuse, by a margin: the camera's rays
        # diverge, and those tilted towards -x meet it below 45 degrees, near the critical
        # angle.
        u = np.asarray(d, float) / np.linalg.norm(d)
        inside = np.array([u[0] / IOR, u[1] / IOR, -math.sqrt(1 - (u[0] ** 2 + u[1] ** 2) / IOR ** 2)])
        cos_h = abs(np.dot(inside, np.array([-1.0, 0.0, -1.0]) / math.sqrt(2)))
        if math.sqrt(1 - cos_h * cos_h) < 1 / IOR + 0.01:
            return None
        fr = fresnel(-d[2] / np.linalg.norm(d))
        return [c * c * (1 - fr) / (1 + fr) for c in TINT]

    out["prism_tir"] = ([("prism", prism(), glass(TINT)), ("wall", side_wall, EMITTER)], 6.0, tir)
    # No closed form: shared vertices, so smooth shading normals across sharp edges (as every
    # CS184 mesh, CBgems' gems among them); the references against ours.
    out["prism_smooth"] = ([("prism", prism(shared=True), glass(TINT)), ("wall", side_wall, EMITTER)], 6.0, None)
    out["gem_smooth"] = ([("gem", octahedron(1.0, (0, 0, 0)), glass(TINT)), ("wall", wall, EMITTER)], 30.0, None)
    return out


# ---- renders ----

def sh(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"glass_study: {' '.join(cmd)} failed:\n{r.stdout[-2000:]}{r.stderr[-2000:]}")
    return r


def camera_rays(cam):
    """Pixel-centre rays of the exported camera (as validation/geometry_checks.py)."""
    tx = math.tan(math.radians(cam["fov_x_deg"]) / 2)
    ty = tx * H / W
    o = np.asarray(cam["origin"], float)
    rays = {}
    for y in range(H):
        for x in range(W):
            d = (np.asarray(cam["forward"]) + ((x + 0.5) / W * 2 - 1) * tx * np.asarray(cam["right"]) + (1 - (y + 0.5) / H * 2) * ty * np.asarray(cam["up"]))
            rays[(y, x)] = (o, d / np.linalg.norm(d))
    return rays


def stack(images):
    """The mean image of independent renders and the variance of that mean."""
    a = np.asarray(images)
    return a.mean(axis=0), a.var(axis=0, ddof=1) / len(a)


def window_ratio(mean, var, expected, mask):
    """The mean over the mask of image / expected per channel, and its standard error (pixels
    are independent: a box filter one pixel wide)."""
    n = mask.sum()
    m = np.array([np.mean(mean[..., c][mask] / expected[..., c][mask]) for c in range(3)])
    se = np.array([math.sqrt(np.sum(var[..., c][mask] / expected[..., c][mask] ** 2)) / n for c in range(3)])
    return m, se


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--pathtracer", default=os.path.join(ROOT, "target", "release", "pathtracer"))
    ap.add_argument("--out", default=os.path.join(HERE, "out", "glass_study"))
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--renders", type=int, default=4)
    ap.add_argument("--refs", default="mitsuba,cycles")
    ap.add_argument("--only", default="")
    args = ap.parse_args()
    refs = [r for r in args.refs.split(",") if r]
    blender = shutil.which("blender")
    os.makedirs(args.out, exist_ok=True)
    rows = []
    for name, (meshes, xfov, closed) in scenes().items():
        if args.only and args.only not in name:
            continue
        d = os.path.join(args.out, name)
        os.makedirs(d, exist_ok=True)
        dae = os.path.join(d, f"{name}.dae")
        with open(dae, "w") as f:
            f.write(collada(meshes, xfov))
        view = ["-r", str(W), str(H), "--keep-fov"]
        sh([args.pathtracer, "export", dae, *view, "--out", os.path.join(d, "scene")])
        with open(os.path.join(d, "scene", "scene.json")) as f:
            cam = json.load(f)["camera"]
        expected = np.zeros((H, W, 3))
        mask = np.zeros((H, W), bool)
        if closed is not None:
            for (y, x), (o, dd) in camera_rays(cam).items():
                e = closed(o, dd)
                if e is not None:
                    expected[y, x] = e
                    mask[y, x] = True
            if mask.sum() < 50:
                sys.exit(f"glass_study: {name}: only {mask.sum()} pixels where the closed form holds")
        images = {}
        ours = []
        for k in range(args.renders):
            exr = os.path.join(d, f"ours_{k}.exr")
            sh([args.pathtracer, dae, *view, "-s", str(args.spp), "-m", str(DEPTH), "--seed", str(11 + k), "-f", os.path.join(d, f"ours_{k}.png"), "--exr", exr])
            ours.append(read_exr(exr))
        images["ours"] = stack(ours)
        if "mitsuba" in refs:
            prefix = os.path.join(d, "mitsuba")
            r = subprocess.run([sys.executable, os.path.join(HERE, "mitsuba_ref.py"), os.path.join(d, "scene"), "--max-depth", str(DEPTH), "--spp", str(args.spp),
                                "--renders", str(args.renders), "--out", prefix], capture_output=True, text=True)
            if r.returncode != 0:
                images["mitsuba"] = [l for l in r.stderr.splitlines() if l.strip()][-1]
            else:
                images["mitsuba"] = (read_exr(prefix + ".exr"), read_exr(prefix + "_var.exr"))
        if "cycles" in refs and blender:
            prefix = os.path.join(d, "cycles")
            r = subprocess.run(cycles_ref_command(blender, os.path.join(d, "scene"), "--mode", "radiance", "--smooth-glass", "--max-depth", str(DEPTH), "--spp", str(args.spp),
                                                  "--renders", str(args.renders), "--out", prefix), capture_output=True, text=True)
            if r.returncode != 0:
                images["cycles"] = [l for l in r.stderr.splitlines() if l.strip()][-1]
            else:
                with open(prefix + "_cycles.json") as f:
                    meta = json.load(f)
                images["cycles"] = stack([read_exr(p["file"]) for p in meta["renders"]])
        found = {}
        if closed is not None:
            for r, v in images.items():
                found[r] = v if isinstance(v, str) else window_ratio(*v, expected, mask)
            rows.append((name, int(mask.sum()), "closed form " + ", ".join(f"{c:.4f}" for c in expected[mask].mean(axis=0)), found))
        else:
            # The whole image's mean against ours (pixels independent: box filter).
            def whole(v):
                m, var = v
                return m.reshape(-1, 3).mean(axis=0), np.sqrt(var.reshape(-1, 3).sum(axis=0)) / (H * W)
            mo, so = whole(images["ours"])
            for r, v in images.items():
                if isinstance(v, str):
                    found[r] = v
                elif r == "ours":
                    found[r] = (np.ones(3), so / mo)
                else:
                    m, se = whole(v)
                    q = m / mo
                    found[r] = (q, q * np.sqrt((se / m) ** 2 + (so / mo) ** 2))
            rows.append((name, H * W, "ours' mean " + ", ".join(f"{c:.4f}" for c in mo), found))
    print(f"Image / closed form over the pixels where it holds (where there is none: the whole image's mean / ours'), per channel (R, G, B): mean +- standard error of {args.renders} renders of {args.spp} spp, -m {DEPTH}, {W}x{H}.\n")
    names = ["ours"] + [r for r in refs if r in ("mitsuba", "cycles")]
    print("| scene | pixels | against | " + " | ".join(names) + " |")
    print("|---|---|---|" + "---|" * len(names))
    for name, n, e, found in rows:
        cells = []
        for r in names:
            v = found.get(r)
            if v is None:
                cells.append("not run")
            elif isinstance(v, str):
                cells.append(f"refused: {v}")
            else:
                m, se = v
                cells.append(", ".join(f"{m[c]:.4f} ± {se[c]:.4f}" for c in range(3)))
        print(f"| {name} | {n} | {e} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
