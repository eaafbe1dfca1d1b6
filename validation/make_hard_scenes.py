#!/usr/bin/env python3
"""Write the numerical-stability scenes of the validation harness into validation/scenes/,
all derived from scenes/cs184/sky/CBspheres_lambertian.dae (the built-in scene), so that every
reference renders exactly what our loader makes of them:

  hard_offset.dae   the whole scene (camera and lights too) moved by 8192 along every axis:
                    f32 spacing there is 2^-10, the light 1 cm under the ceiling is 10 ulps away
  hard_tiny.dae     scaled by 1e-3 (a 2 mm box; the camera's clip planes scaled with it)
  hard_huge.dae     scaled by 1e3 (a 2 km box)
  hard_grazing.dae  the light 1e-4 under the ceiling instead of 1e-2: the walls' top rows are lit
                    at grazing angles from a light almost in the ceiling's plane
  hard_slab.dae     a 1e-4-thick plate (0.5 x 0.5) under the light: light leaking through a thin
                    slab, or a self-shadowing slab, shows on the floor below

Run it after changing the base scene; the outputs are committed.
"""
import os
import re

HERE = os.path.dirname(os.path.abspath(__file__))
BASE = os.path.join(os.path.dirname(HERE), "scenes", "CBspheres_lambertian.dae")


def wrap(text, matrix, clip_scale=1.0):
    """Put every node of the visual scene but the camera's under one parent node with `matrix`
    (row-major). The camera stays: CS184 places it around the scene's bounds, in the direction
    normalize(T·(0,0,-1,1)) of its node (w = 1, so a moved camera node would also turn the
    view), so the moved or scaled scene is seen exactly as the base scene."""
    start = text.index(">", text.index("<visual_scene")) + 1
    end = text.index("</visual_scene>")
    body = text[start:end]
    c0 = body.index('<node id="Camera"')
    c1 = body.index("</node>", c0) + len("</node>")
    camera, body = body[c0:c1], body[:c0] + body[c1:]
    m = " ".join(f"{v:.9g}" for v in matrix)
    out = (text[:start] + f'\n      <node id="hard_case_root" name="hard_case_root" type="NODE">\n        <matrix sid="transform">{m}</matrix>' + body
           + "  </node>\n      " + camera + "\n    " + text[end:])
    if clip_scale != 1.0:
        out = re.sub(r'(<znear sid="znear">)([^<]+)(<)', lambda g: f"{g.group(1)}{float(g.group(2)) * clip_scale:.9g}{g.group(3)}", out)
        out = re.sub(r'(<zfar sid="zfar">)([^<]+)(<)', lambda g: f"{g.group(1)}{float(g.group(2)) * clip_scale:.9g}{g.group(3)}", out)
    return out


def translate(d):
    return [1, 0, 0, d, 0, 1, 0, d, 0, 0, 1, d, 0, 0, 0, 1]


def scale(s):
    return [s, 0, 0, 0, 0, s, 0, 0, 0, 0, s, 0, 0, 0, 0, 1]


def grazing(text):
    # The light quad (mesh, local y = height) and its area-light twin (node z translation).
    a = text.replace('<float_array id="light-mesh-positions-array" count="12">0.4 1.49 -0.3 0.4 1.49 0.3 -0.4 1.49 0.3 -0.4 1.49 -0.3</float_array>',
                     '<float_array id="light-mesh-positions-array" count="12">0.4 1.4999 -0.3 0.4 1.4999 0.3 -0.4 1.4999 0.3 -0.4 1.4999 -0.3</float_array>')
    b = a.replace('<matrix sid="transform">0.6 0 0 0 0 0.8 0 0 0 0 1 1.49 0 0 0 1</matrix>', '<matrix sid="transform">0.6 0 0 0 0 0.8 0 0 0 0 1 1.4999 0 0 0 1</matrix>')
    assert a != text and b != a, "base scene changed: light quad or area light not found"
    return b


def xyz_source(sid, values):
    """A COLLADA <source> of XYZ triples."""
    n = len(values) // 3
    return f"""        <source id="{sid}">
          <float_array id="{sid}-array" count="{len(values)}">{' '.join(values)}</float_array>
          <technique_common>
            <accessor source="#{sid}-array" count="{n}" stride="3">
              <param name="X" type="float"/>
              <param name="Y" type="float"/>
              <param name="Z" type="float"/>
            </accessor>
          </technique_common>
        </source>
"""


def slab(text):
    """A closed box 0.5 x 0.5 x 1e-4 (Z up, as the file) centred at (0, 0, 1.0), lambertian."""
    h, t, zc = 0.25, 0.5e-4, 1.0
    v = [(x, y, z) for z in (zc - t, zc + t) for y in (-h, h) for x in (-h, h)]
    # Outward-wound quads: bottom, top, -y, +y, -x, +x.
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    normals = [(0, 0, -1), (0, 0, 1), (0, -1, 0), (0, 1, 0), (-1, 0, 0), (1, 0, 0)]
    tris, p = [], []
    for qi, q in enumerate(quads):
        for tri in ((q[0], q[1], q[2]), (q[0], q[2], q[3])):
            for vi in tri:
                p += [vi, qi]
            tris.append(tri)
    geom = f"""    <geometry id="slab-mesh" name="slab">
      <mesh>
{xyz_source("slab-mesh-positions", [f'{c:.9g}' for pt in v for c in pt])}{xyz_source("slab-mesh-normals", [str(c) for n in normals for c in n])}        <vertices id="slab-mesh-vertices">
          <input semantic="POSITION" source="#slab-mesh-positions"/>
        </vertices>
        <polylist material="lambertian" count="{len(tris)}">
          <input semantic="VERTEX" source="#slab-mesh-vertices" offset="0"/>
          <input semantic="NORMAL" source="#slab-mesh-normals" offset="1"/>
          <vcount>{' '.join('3' for _ in tris)} </vcount>
          <p>{' '.join(str(i) for i in p)}</p>
        </polylist>
      </mesh>
    </geometry>
"""
    node = """      <node id="slab" name="slab" type="NODE">
        <matrix sid="transform">1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1</matrix>
        <instance_geometry url="#slab-mesh">
          <bind_material>
            <technique_common>
              <instance_material symbol="lambertian" target="#lambertian"/>
            </technique_common>
          </bind_material>
        </instance_geometry>
      </node>
"""
    i = text.index("</library_geometries>")
    text = text[:i] + geom + "  " + text[i:]
    j = text.index("</visual_scene>")
    return text[:j] + node + "    " + text[j:]


def main():
    with open(BASE) as f:
        base = f.read()
    os.makedirs(os.path.join(HERE, "scenes"), exist_ok=True)
    scenes = {
        "hard_offset.dae": wrap(base, translate(8192.0)),
        "hard_tiny.dae": wrap(base, scale(1e-3), clip_scale=1e-3),
        "hard_huge.dae": wrap(base, scale(1e3), clip_scale=1e3),
        "hard_grazing.dae": grazing(base),
        "hard_slab.dae": slab(base),
    }
    for name, text in scenes.items():
        with open(os.path.join(HERE, "scenes", name), "w") as f:
            f.write(text)
        print(f"wrote validation/scenes/{name}")


if __name__ == "__main__":
    main()
