"""Render an exported scene (scene.json from `pathtracer export`) with Blender Cycles, as
independent renders (one EXR each; the harness takes their mean and variance).

Run by Blender's own Python, which has no numpy:
  blender -b --factory-startup --python-exit-code 1 -P cycles_ref.py -- SCENE_DIR --mode M ...

Conventions (docs/validation/README.md, measured with Blender 3.4.1):
an empty scene and a black world; CPU, fixed threads, no adaptive sampling, no denoising, no
clamping, no light threshold, no guiding; a box pixel filter one pixel wide; bounces
= our -m minus 1 for every ray type; Standard view transform; float32 linear EXR. Camera from
our camera frame with the horizontal field of view. Diffuse BSDF with roughness 0 (Lambert).

Emitters: Cycles 3.4 is biased low near the plane of an emissive *mesh* (measured: a wall
near the light's plane reads up to 5 % dark, the same with every sampling option; an AREA lamp
of the same size is exact), so an emissive rectangle becomes an AREA lamp (power 4·L·A, one-sided like ours)
plus a black stand-in quad just behind it that shows the emission to camera rays only and
occludes like the emitter. Any other emissive shape is refused, not approximated. Point lamps
have power 4π·I and radius 0; our directional light is a SUN lamp of angle 0 with strength =
irradiance; our hemisphere light is a world shader that is L above the horizon (y > 0) and
black below, refused where its horizon is in view (Cycles draws it 0.0015 px low, measured on
bunny.dae). Smooth-shaded meshes get the object's Shadow Terminator offsets 0 (Cycles' default
moves their shadow rays off the surface). Spheres are exact spheres (a one-point cloud of that radius).

Materials: mirror = Glossy BSDF, Sharp (two-sided,
weight exactly the colour); CS184's refraction = Refraction BSDF, Sharp (no Fresnel, total
internal reflection ends the path, as ours); glass = Mix Shader(Fac = Fresnel node with the
ior, Refraction Sharp × transmittance, Glossy Sharp × reflectance): exact Fresnel (the node
inverts the ior on backfaces) with separate colours; Cycles scales no radiance by eta^2, which
cancels for closed objects lit from outside (the only kind the harness renders). Glass and
refraction on meshes with smooth shading normals (CS184 interpolates every mesh's vertex
normals; CBgems' gems) are refused: validation/glass_study.py measures flat glass, tinted and
clear, face-on, grazing and by total internal reflection, equal to its closed form and to
Mitsuba 3 within 0.06 % in Cycles, but a prism with interpolated normals 3.6-4.7 % brighter in
Cycles than in ours and Mitsuba (which agree within 0.5 %). Microfacet is
refused: Cycles 3.4 has no conductor Fresnel. Environment maps are refused: Cycles 3.4's light
from a world map depends on its importance map, which an unbiased estimator's mean cannot
(validation/env_study.py: a flat diffuse square under studio.exr against the closed form of its
radiance reads -4.4 / -2.7 / +1.8e-4 in R / G / B with the default map, -1.5 % with a map of 256,
where ours and Mitsuba 3 agree with it and the map seen directly agrees with ours to 1e-5).
With --environment-map it is rendered anyway, for that study: a world shader that computes our
lat-long (u, v) with Math nodes from the ray direction and looks up our texels, padded with a
copy of the first and last rows, through an Image Texture (Linear, Repeat): texel-centred
bilinear, wrapping horizontally and clamped vertically, as ours. Depth of field:
the camera's disk aperture of our lens radius (f-stop = lens mm / 2000 / radius), focused on
the plane at our focal distance.

Modes other than `radiance` check intersection only: `object-id` paints every object its
exported `id_colour` as emission, `depth` emits the distance from the camera (Camera Data →
View Distance), `normal` writes Cycles' normal pass through the compositor. Like every
Cycles pass they are averages over the pixel's samples (box filter), compared with our
averages statistically. (A 0.01-px filter does not make Cycles sample the pixel centre: at
Cycles' minimum width, side-wall depths still differed from the centre value by 0.03 at
64x48, and at 1 spp the renders did not depend on the seed.)
"""
import json
import math
import os
import struct
import sys
import time

import bpy
from mathutils import Matrix, Vector

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from mesh_io import Unrepresentable, read_obj, rectangle_of, smooth_faces  # noqa: E402


def refuse(msg):
    print(f"cycles_ref: cannot represent exactly: {msg}", file=sys.stderr)
    sys.exit(3)


def parse_args(argv):
    import argparse

    ap = argparse.ArgumentParser(prog="cycles_ref.py")
    ap.add_argument("scene")
    ap.add_argument("--mode", choices=["radiance", "object-id", "depth", "normal"], default="radiance")
    ap.add_argument("--max-depth", type=int, default=1, help="our -m")
    ap.add_argument("--spp", type=int, required=True)
    ap.add_argument("--renders", type=int, default=1)
    ap.add_argument("--ladder", default="", help="also time single renders at these spp")
    ap.add_argument("--ladder-seeds", type=int, default=1, help="independent renders per ladder rung")
    ap.add_argument("--threads", type=int, default=0, help="0: all cores")
    ap.add_argument("--smooth-glass", action="store_true", help="render smooth-shaded glass instead of refusing it (glass_study.py measures it)")
    ap.add_argument("--environment-map", action="store_true", help="render an environment map instead of refusing it (env_study.py measures it)")
    ap.add_argument("--out", required=True, help="prefix: <out>_r<k>.exr, <out>_spp<N>.exr, <out>_cycles.json")
    return ap.parse_args(argv)


def node_tree(mat):
    mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    return nt, out


def diffuse_material(name, albedo):
    mat = bpy.data.materials.new(name)
    nt, out = node_tree(mat)
    d = nt.nodes.new("ShaderNodeBsdfDiffuse")
    d.inputs["Color"].default_value = (*albedo, 1.0)
    d.inputs["Roughness"].default_value = 0.0  # Lambert, not Oren-Nayar
    nt.links.new(d.outputs["BSDF"], out.inputs["Surface"])
    return mat


def sharp(nt, kind, colour, ior=None):
    n = nt.nodes.new(kind)
    n.distribution = "SHARP"
    n.inputs["Color"].default_value = (*colour, 1.0)
    if ior is not None:
        n.inputs["IOR"].default_value = ior
    return n


def scattering_material(name, s):
    """The shape's BSDF as Cycles nodes, exactly, or a refusal."""
    b = s.get("bsdf", {"type": "diffuse"})
    t = b["type"]
    if t == "diffuse":
        return diffuse_material(name, s["albedo"])
    if t in ("glass", "refraction") and s["type"] == "sphere":
        # Measured: CBspheres' glass sphere (a point of that radius) rendered up to 3x
        # brighter through the sphere than ours and Mitsuba's, with Cycles' own Glass BSDF
        # as with the node recipe; glass meshes (CBgems) agree. Refraction needs the ray
        # to find the sphere again from inside, which Cycles' point primitives do not give.
        refuse(f"shape {s['id']}: a refracting sphere (Cycles 3.4's exact spheres are point-cloud points, not found again from inside)")
    mat = bpy.data.materials.new(name)
    nt, out = node_tree(mat)
    if t == "mirror":
        g = sharp(nt, "ShaderNodeBsdfGlossy", b["reflectance"])
        nt.links.new(g.outputs["BSDF"], out.inputs["Surface"])
    elif t == "refraction":
        if b["roughness"] != 0:
            refuse(f"shape {s['id']}: rough refraction")
        r = sharp(nt, "ShaderNodeBsdfRefraction", b["transmittance"], b["ior"])
        nt.links.new(r.outputs["BSDF"], out.inputs["Surface"])
    elif t == "glass":
        if b["roughness"] != 0:
            refuse(f"shape {s['id']}: rough glass")
        r = sharp(nt, "ShaderNodeBsdfRefraction", b["transmittance"], b["ior"])
        g = sharp(nt, "ShaderNodeBsdfGlossy", b["reflectance"])
        f = nt.nodes.new("ShaderNodeFresnel")
        f.inputs["IOR"].default_value = b["ior"]
        mix = nt.nodes.new("ShaderNodeMixShader")
        nt.links.new(f.outputs["Fac"], mix.inputs["Fac"])
        nt.links.new(r.outputs["BSDF"], mix.inputs[1])
        nt.links.new(g.outputs["BSDF"], mix.inputs[2])
        nt.links.new(mix.outputs["Shader"], out.inputs["Surface"])
    else:
        refuse(f"shape {s['id']}: {t} (Cycles 3.4 has no conductor Fresnel; its closure weights cannot depend on the light direction)")
    return mat


def environment_world(wnt, bg, path):
    """Our lat-long lookup as a world shader (see the module doc)."""
    src = bpy.data.images.load(path)
    w, h = src.size
    px = list(src.pixels[:])  # RGBA, row 0 at the bottom
    row = 4 * w
    padded = px[:row] + px + px[-row:]
    img = bpy.data.images.new("environment_padded", w, h + 2, alpha=False, float_buffer=True)
    img.colorspace_settings.name = "Non-Color"
    img.pixels.foreach_set(padded)
    img.pack()
    coord = wnt.nodes.new("ShaderNodeTexCoord")
    norm = wnt.nodes.new("ShaderNodeVectorMath")
    norm.operation = "NORMALIZE"
    wnt.links.new(coord.outputs["Generated"], norm.inputs[0])
    sep = wnt.nodes.new("ShaderNodeSeparateXYZ")
    wnt.links.new(norm.outputs["Vector"], sep.inputs["Vector"])

    def op(name, a, b=None):
        m = wnt.nodes.new("ShaderNodeMath")
        m.operation = name
        for k, v in enumerate((a, b)):
            if v is None:
                continue
            if isinstance(v, (int, float)):
                m.inputs[k].default_value = v
            else:
                wnt.links.new(v, m.inputs[k])
        return m.outputs["Value"]

    # u = (atan2(-z, x) + pi) / 2pi; v = (h + 1 - theta h / pi) / (h + 2), theta = acos(y)
    negz = op("MULTIPLY", sep.outputs["Z"], -1.0)
    phi = op("ADD", op("ARCTAN2", negz, sep.outputs["X"]), float(math.pi))
    u = op("DIVIDE", phi, 2.0 * math.pi)
    theta = op("ARCCOSINE", sep.outputs["Y"])
    v = op("DIVIDE", op("SUBTRACT", float(h + 1), op("MULTIPLY", theta, h / math.pi)), float(h + 2))
    comb = wnt.nodes.new("ShaderNodeCombineXYZ")
    wnt.links.new(u, comb.inputs["X"])
    wnt.links.new(v, comb.inputs["Y"])
    tex = wnt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.interpolation = "Linear"
    tex.extension = "REPEAT"
    wnt.links.new(comb.outputs["Vector"], tex.inputs["Vector"])
    wnt.links.new(tex.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = 1.0


def emission_material(name, colour, strength_from_distance=False):
    mat = bpy.data.materials.new(name)
    nt, out = node_tree(mat)
    e = nt.nodes.new("ShaderNodeEmission")
    e.inputs["Color"].default_value = (*colour, 1.0)
    e.inputs["Strength"].default_value = 1.0
    if strength_from_distance:
        cam = nt.nodes.new("ShaderNodeCameraData")
        nt.links.new(cam.outputs["View Distance"], e.inputs["Strength"])
    nt.links.new(e.outputs["Emission"], out.inputs["Surface"])
    return mat


def camera_only_emitter(name, radiance):
    """Seen by camera rays from the front: radiance; otherwise a black diffuse surface
    (the stand-in behind an AREA lamp: the lamp lights, the stand-in shows and occludes)."""
    mat = bpy.data.materials.new(name)
    nt, out = node_tree(mat)
    black = nt.nodes.new("ShaderNodeBsdfDiffuse")
    black.inputs["Color"].default_value = (0, 0, 0, 1)
    e = nt.nodes.new("ShaderNodeEmission")
    e.inputs["Color"].default_value = (*radiance, 1.0)
    e.inputs["Strength"].default_value = 1.0
    geo = nt.nodes.new("ShaderNodeNewGeometry")
    path = nt.nodes.new("ShaderNodeLightPath")
    # visible = is camera ray AND not backfacing
    inv = nt.nodes.new("ShaderNodeMath")
    inv.operation = "SUBTRACT"
    inv.inputs[0].default_value = 1.0
    nt.links.new(geo.outputs["Backfacing"], inv.inputs[1])
    both = nt.nodes.new("ShaderNodeMath")
    both.operation = "MULTIPLY"
    nt.links.new(path.outputs["Is Camera Ray"], both.inputs[0])
    nt.links.new(inv.outputs["Value"], both.inputs[1])
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(both.outputs["Value"], mix.inputs["Fac"])
    nt.links.new(black.outputs["BSDF"], mix.inputs[1])
    nt.links.new(e.outputs["Emission"], mix.inputs[2])
    nt.links.new(mix.outputs["Shader"], out.inputs["Surface"])
    return mat


def split_normal_deviation(me, normals):
    """How far Blender's corner normals are from ours: it stores custom split normals compressed
    (two 16-bit angles per corner in a per-fan space), so they come back off by up to a few
    1e-4 (bunny_unlit: 6.7e-4 at most, 5e-5 on average). The normal check allows this much."""
    me.calc_normals_split()
    got = [0.0] * (3 * len(me.loops))
    me.loops.foreach_get("normal", got)
    vi = [0] * len(me.loops)
    me.loops.foreach_get("vertex_index", vi)
    worst = 0.0
    for k, v in enumerate(vi):
        n = normals[v]
        length = math.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) or 1.0
        d = sum((got[3 * k + a] - n[a] / length) ** 2 for a in range(3))
        worst = max(worst, d)
    return math.sqrt(worst)


def add_mesh(name, verts, normals, faces, mat):
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    me.validate(clean_customdata=False)
    me.polygons.foreach_set("use_smooth", [True] * len(me.polygons))
    # Our shading normals (CS184's area-weighted vertex normals), not Blender's.
    me.use_auto_smooth = True
    me.normals_split_custom_set_from_vertices(normals)
    me.materials.append(mat)
    ob = bpy.data.objects.new(name, me)
    # Cycles moves the shadow rays of smooth-shaded triangles off the surface towards where
    # the interpolated normals put it, near the shading terminator (the object's "Shadow
    # Terminator: Geometry Offset", 0.1 by default in Blender 3.4), which neither we nor
    # Mitsuba do. Off (and the shading offset, 0 by default), a shadow ray leaves the hit point.
    ob.cycles.shadow_terminator_geometry_offset = 0.0
    ob.cycles.shadow_terminator_offset = 0.0
    bpy.context.scene.collection.objects.link(ob)
    return ob


def add_sphere(name, centre, radius, mat):
    """An exact sphere: a one-vertex mesh turned into a point of that radius."""
    me = bpy.data.meshes.new(name)
    me.from_pydata([(0.0, 0.0, 0.0)], [], [])
    ob = bpy.data.objects.new(name, me)
    ob.location = centre
    bpy.context.scene.collection.objects.link(ob)
    group = bpy.data.node_groups.new(name + "_points", "GeometryNodeTree")
    group.inputs.new("NodeSocketGeometry", "Geometry")
    group.outputs.new("NodeSocketGeometry", "Geometry")
    gi = group.nodes.new("NodeGroupInput")
    go = group.nodes.new("NodeGroupOutput")
    m2p = group.nodes.new("GeometryNodeMeshToPoints")
    m2p.inputs["Radius"].default_value = radius
    sm = group.nodes.new("GeometryNodeSetMaterial")
    sm.inputs["Material"].default_value = mat
    group.links.new(gi.outputs["Geometry"], m2p.inputs["Mesh"])
    group.links.new(m2p.outputs["Points"], sm.inputs["Geometry"])
    group.links.new(sm.outputs["Geometry"], go.inputs["Geometry"])
    mod = ob.modifiers.new("points", "NODES")
    mod.node_group = group
    return ob


def add_area_lamp(name, corner, u, v, n, radiance, cam_visible):
    L = max(radiance)
    if L <= 0:
        return
    area = u.cross(v).length
    lamp = bpy.data.lights.new(name, "AREA")
    lamp.shape = "RECTANGLE"
    lamp.size, lamp.size_y = u.length, v.length
    lamp.color = tuple(c / L for c in radiance)
    lamp.energy = 4.0 * L * area  # measured: 4·L·A gives radiance L
    lamp.spread = math.pi
    lamp.cycles.cast_shadow = True
    lamp.use_shadow = True
    ob = bpy.data.objects.new(name, lamp)
    # A Blender area lamp emits along its local -Z, with size along local X and Y.
    x = u.normalized()
    z = -n
    y = z.cross(x)
    centre = corner + 0.5 * u + 0.5 * v
    ob.matrix_world = Matrix((
        (x.x, y.x, z.x, centre.x),
        (x.y, y.y, z.y, centre.y),
        (x.z, y.z, z.z, centre.z),
        (0, 0, 0, 1)))
    ob.visible_camera = cam_visible
    bpy.context.scene.collection.objects.link(ob)


def horizon_in_view(cam):
    """Whether the camera's frame holds directions on both sides of y = 0, the horizon of a
    hemisphere light (a direction's y is linear across the frame: its corners bound it)."""
    tx, ty = math.tan(math.radians(cam["fov_x_deg"]) / 2), math.tan(math.radians(cam["fov_y_deg"]) / 2)
    r, u, f = (Vector(cam[k]) for k in ("right", "up", "forward"))
    ys = [(f + sx * tx * r + sy * ty * u).y for sx in (-1, 1) for sy in (-1, 1)]
    return min(ys) < 0 < max(ys)


def build(spec, folder, mode, smooth_glass=False, environment_map=False):
    scene = bpy.context.scene
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob, do_unlink=True)
    world = bpy.data.worlds.new("world")
    scene.world = world
    world.use_nodes = True
    wnt = world.node_tree
    bg = wnt.nodes["Background"]
    bg.inputs["Strength"].default_value = 0.0

    shadow_blind = []
    # For the normal pass: the largest distance between our vertex normals and the corner
    # normals Blender keeps for them (split_normal_deviation).
    normal_deviation = 0.0
    for s in spec["shapes"]:
        if not s.get("emission_one_sided", False):
            refuse(f"shape {s['id']}: only one-sided emission is modelled")
        name = f"shape{s['id']}"
        emissive = max(s["emission"]) > 0
        rect = None
        if s["type"] == "mesh":
            verts, normals, faces = read_obj(os.path.join(folder, s["file"]))
            if not faces:
                refuse(f"shape {s['id']}: empty mesh")
        if mode == "object-id":
            mat = emission_material(name, s["id_colour"])
        elif mode == "depth":
            mat = emission_material(name, (1.0, 1.0, 1.0), strength_from_distance=True)
        elif mode == "normal":
            mat = diffuse_material(name, s["albedo"])
        elif not emissive:
            b = s.get("bsdf", {"type": "diffuse"})
            if b["type"] in ("glass", "refraction") and s["type"] == "mesh" and not smooth_glass and (k := smooth_faces(verts, normals, faces)):
                # Measured (validation/glass_study.py): flat glass agrees with the closed form
                # and with Mitsuba 3 to 0.06 %; a prism whose normals are interpolated across
                # its edges renders 3.6-4.7 % brighter in Cycles 3.4 than ours and Mitsuba's.
                refuse(f"shape {s['id']} ({s['name']}): {b['type']} with shading normals interpolated across {k} of its {len(faces)} faces "
                       "(Cycles 3.4 renders smooth-shaded glass 4-5 % brighter than ours and Mitsuba 3: validation/glass_study.py)")
            mat = scattering_material(name, s)
        else:
            if max(s["albedo"]) > 0:
                refuse(f"shape {s['id']}: an emitter that also reflects")
            if s["type"] != "mesh" or (rect := rectangle_of(verts, faces)) is None:
                refuse(f"shape {s['id']} ({s['name']}): an emissive {s['type']} that is not one rectangle "
                       "(Cycles 3.4 is biased near emissive meshes; only rectangles go through the exact AREA lamp)")
            corner, u, v, n = (Vector(x) for x in rect)
            add_area_lamp(name + "_lamp", corner, u, v, n, s["emission"], cam_visible=False)
            # The stand-in sits behind the lamp by 1e-4 of its size: the lamp lights the
            # scene, the stand-in shows the emission to the camera and occludes.
            delta = 1e-4 * max(u.length, v.length)
            moved = [tuple(Vector(p) - n * delta) for p in verts]
            # Blender stores f32: far from the origin the step can round away, and the
            # stand-in would then coincide with the lamp (measured at +8192: 30 % dark).
            f32 = lambda t: struct.unpack("3f", struct.pack("3f", *t))
            if any(f32(a) == f32(b) for a, b in zip(moved, verts)):
                refuse(f"shape {s['id']}: the stand-in step {delta:.3g} behind the emissive rectangle rounds away in f32 at its coordinates")
            verts = moved
            mat = camera_only_emitter(name, s["emission"])
            # A point light in the emitter's plane (CBempty's lies in it, at its centre) is
            # not occluded by our rectangle from either side, but would be by a stand-in
            # moved behind it: the stand-in then stops no shadow ray, which is exact as long
            # as no light lies further behind the plane (those our rectangle would shadow).
            behind = [(Vector(l["position"]) - corner).dot(n) for l in spec["lights"] if l["type"] == "point"]
            if any(abs(d) <= 2 * delta for d in behind):
                if any(d < -2 * delta for d in behind):
                    refuse(f"shape {s['id']}: point lights both in the plane of the emissive rectangle and behind it")
                shadow_blind.append(name)
        if s["type"] == "mesh":
            ob = add_mesh(name, verts, normals, faces, mat)
            if mode == "normal":
                normal_deviation = max(normal_deviation, split_normal_deviation(ob.data, normals))
            if name in shadow_blind:
                ob.visible_shadow = False
        elif s["type"] == "sphere":
            add_sphere(name, s["center"], s["radius"], mat)
        else:
            refuse(f"shape type {s['type']}")

    if mode == "radiance":
        for i, l in enumerate(spec["lights"]):
            t = l["type"]
            if t == "emissive_shape":
                continue
            if t == "point":
                I = max(l["intensity"])
                lamp = bpy.data.lights.new(f"light{i}", "POINT")
                lamp.color = tuple(c / I for c in l["intensity"]) if I > 0 else (0, 0, 0)
                lamp.energy = 4.0 * math.pi * I  # measured: power 4π·I gives intensity I
                lamp.shadow_soft_size = 0.0
                ob = bpy.data.objects.new(f"light{i}", lamp)
                ob.location = l["position"]
                scene.collection.objects.link(ob)
            elif t == "directional":
                E = max(l["irradiance"])
                lamp = bpy.data.lights.new(f"light{i}", "SUN")
                lamp.color = tuple(c / E for c in l["irradiance"]) if E > 0 else (0, 0, 0)
                lamp.energy = E
                lamp.angle = 0.0
                ob = bpy.data.objects.new(f"light{i}", lamp)
                # The sun shines along its local -Z; to_light is +Z.
                z = Vector(l["to_light"]).normalized()
                ob.rotation_euler = z.to_track_quat("Z", "Y").to_euler()
                scene.collection.objects.link(ob)
            elif t == "hemisphere":
                # Radiance L for directions with y > 0 (the upper hemisphere), 0 below.
                up = Vector(l["up"])
                if (up - Vector((0, 1, 0))).length > 0:
                    refuse("hemisphere light around an axis other than +y")
                if horizon_in_view(spec["camera"]):
                    refuse("the hemisphere light's horizon is in view: Cycles 3.4 draws it 0.0015 px below where the exported camera puts it "
                           "(bunny.dae at 256x192: the image row it crosses is 0.66816 +- 0.00005 sky against the projected 0.66664; "
                           "ours 0.66655 +- 0.00012, Mitsuba 3 0.66721 +- 0.0005)")
                coord = wnt.nodes.new("ShaderNodeTexCoord")
                sep = wnt.nodes.new("ShaderNodeSeparateXYZ")
                gt = wnt.nodes.new("ShaderNodeMath")
                gt.operation = "GREATER_THAN"
                gt.inputs[1].default_value = 0.0
                wnt.links.new(coord.outputs["Generated"], sep.inputs["Vector"])
                wnt.links.new(sep.outputs["Y"], gt.inputs[0])
                bg.inputs["Color"].default_value = (*l["radiance"], 1.0)
                wnt.links.new(gt.outputs["Value"], bg.inputs["Strength"])
            elif t == "environment":
                if not environment_map:
                    refuse("an environment map: Cycles 3.4's light from a world map depends on its importance map (a flat diffuse square "
                           "against its closed form: -4.4 / -2.7 / +1.8e-4 in R / G / B at the default resolution, -1.5 % at 256; "
                           "ours and Mitsuba 3 agree with it; validation/env_study.py)")
                environment_world(wnt, bg, os.path.join(folder, l["file"]))
            elif t == "rect":
                corner, u, v, n = (Vector(l[k]) for k in ("corner", "ex", "ey", "normal"))
                if l.get("visible", False):
                    refuse("a visible rectangle light without a shape")
                # Ours: light-sampled only, not seen by any ray, not occluding.
                add_area_lamp(f"light{i}", corner, u, v, n, l["radiance"], cam_visible=False)
                # Light sampling only: no MIS, so no ray can hit the lamp. (Turning off its
                # diffuse/glossy/transmission ray visibility instead turns off its light on
                # those surfaces altogether: CBcoil's second light was missing, measured.)
                bpy.data.lights[f"light{i}"].cycles.use_multiple_importance_sampling = False
            else:
                refuse(f"light type {t}")

    cam = spec["camera"]
    cd = bpy.data.cameras.new("camera")
    cd.sensor_fit = "HORIZONTAL"
    cd.angle = math.radians(cam["fov_x_deg"])
    cd.clip_start = max(cam["near"], 1e-6)
    cd.clip_end = min(float("inf") if cam["far"] is None else cam["far"], 1e10)  # null: no far plane
    if cam.get("lens_radius", 0) > 0:
        cd.dof.use_dof = True
        cd.dof.focus_distance = cam["focal_distance"]
        cd.dof.aperture_blades = 0
        cd.dof.aperture_ratio = 1.0
        cd.dof.aperture_fstop = cd.lens * 1e-3 / (2.0 * cam["lens_radius"])
    co = bpy.data.objects.new("camera", cd)
    r, u, f, o = (Vector(cam[k]) for k in ("right", "up", "forward", "origin"))
    co.matrix_world = Matrix(((r.x, u.x, -f.x, o.x), (r.y, u.y, -f.y, o.y), (r.z, u.z, -f.z, o.z), (0, 0, 0, 1)))
    scene.collection.objects.link(co)
    scene.camera = co
    return cam["width"], cam["height"], normal_deviation


def configure(width, height, mode, max_depth, threads):
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    if threads:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = threads
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1
    scene.render.use_border = False
    scene.render.film_transparent = False
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.use_animated_seed = False
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.caustics_reflective = c.caustics_refractive = True
    c.light_sampling_threshold = 0.0
    c.use_fast_gi = False
    c.min_light_bounces = 0
    c.min_transparent_bounces = 0
    for k in ("use_guiding", "use_light_tree"):
        if hasattr(c, k):
            setattr(c, k, False)
    c.auto_scrambling_distance = False
    c.scrambling_distance = 1.0
    b = max(max_depth - 1, 0) if mode == "radiance" else 0
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = b
    c.transparent_max_bounces = c.volume_bounces = b
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    im = scene.render.image_settings
    im.file_format = "OPEN_EXR"
    im.color_depth = "32"
    im.color_mode = "RGB"
    im.exr_codec = "ZIP"
    if mode == "normal":
        scene.view_layers[0].use_pass_normal = True
        scene.use_nodes = True
        nt = scene.node_tree
        for n in list(nt.nodes):
            nt.nodes.remove(n)
        rl = nt.nodes.new("CompositorNodeRLayers")
        comp = nt.nodes.new("CompositorNodeComposite")
        comp.use_alpha = False
        nt.links.new(rl.outputs["Normal"], comp.inputs["Image"])


def render(path, spp, seed):
    scene = bpy.context.scene
    scene.cycles.samples = spp
    scene.cycles.seed = seed
    scene.render.filepath = path
    t0 = time.time()
    bpy.ops.render.render(write_still=True)
    return time.time() - t0


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    args = parse_args(argv)
    with open(os.path.join(args.scene, "scene.json")) as f:
        spec = json.load(f)
    w, h, normal_deviation = build(spec, args.scene, args.mode, args.smooth_glass, args.environment_map)
    configure(w, h, args.mode, args.max_depth, args.threads)
    meta = {"renderer": f"cycles (blender {bpy.app.version_string})", "mode": args.mode, "spp_per_render": args.spp, "renders": [], "ladder": [],
            "normal_deviation": normal_deviation}
    # The first render in a Blender process pays one-time costs (kernel and image set-up): one
    # untimed 1-spp render first, so neither the renders nor the ladder carry them.
    render(f"{args.out}_warmup.exr", 1, 0)
    os.remove(f"{args.out}_warmup.exr")
    for k in range(args.renders):
        p = f"{args.out}_r{k}.exr"
        meta["renders"].append({"file": p, "seconds": render(p, args.spp, 1 + k)})
    for n in [int(x) for x in args.ladder.split(",") if x]:
        for k in range(args.ladder_seeds):
            p = f"{args.out}_spp{n}_k{k}.exr"
            meta["ladder"].append({"spp": n, "seed_index": k, "file": p, "seconds": render(p, n, 1000 + n + 7919 * k)})
    with open(args.out + "_cycles.json", "w") as f:
        json.dump(meta, f)


try:
    main()
except Unrepresentable as e:
    refuse(str(e))
