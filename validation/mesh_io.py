"""Reading what `pathtracer export` wrote, shared by the reference exporters (`cycles_ref.py`
runs in Blender's Python, `pov_ref.py` in the plain one: no numpy here), so that both see the
same meshes and agree on which emitters are rectangles."""
import math


class Unrepresentable(Exception):
    """The scene has something a reference renderer cannot represent exactly."""


def read_obj(path):
    """Vertices, per-vertex normals and faces (0-based) of an OBJ as `pathtracer export`
    writes it: `f a//a b//b c//c`, one normal per vertex."""
    verts, normals, faces = [], [], []
    with open(path) as f:
        for line in f:
            if line.startswith("v "):
                verts.append(tuple(float(x) for x in line.split()[1:4]))
            elif line.startswith("vn "):
                normals.append(tuple(float(x) for x in line.split()[1:4]))
            elif line.startswith("f "):
                idx = [w.split("/") for w in line.split()[1:]]
                # Our exporter writes the normal index equal to the position index.
                if any(len(i) != 3 or i[0] != i[2] for i in idx):
                    raise Unrepresentable(f"{path}: face '{line.strip()}' is not 'f v//v ...' as `pathtracer export` writes")
                faces.append(tuple(int(i[0]) - 1 for i in idx))
    if len(normals) != len(verts):
        raise Unrepresentable(f"{path}: {len(normals)} normals for {len(verts)} vertices")
    return verts, normals, faces


def sub(a, b):
    return [x - y for x, y in zip(a, b)]


def dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def norm(a):
    return math.sqrt(dot(a, a))


def smooth_faces(verts, normals, faces, tol=1e-4):
    """How many faces have a vertex whose shading normal is not the face's own (by more than
    `tol` in the cosine): faces shaded as part of a curved surface."""
    count = 0
    for f in faces:
        a, b, c = (verts[i] for i in f[:3])
        n = cross(sub(b, a), sub(c, a))
        ln = norm(n)
        if ln == 0:
            continue
        if any(dot(n, normals[i]) / (ln * max(norm(normals[i]), 1e-30)) < 1 - tol for i in f):
            count += 1
    return count


def rectangle_of(verts, faces):
    """(corner, u, v, unit winding normal) of a mesh that is one rectangle of two triangles
    facing the same way, else None."""
    if len(faces) != 2 or len(verts) not in (4, 6):
        return None
    uniq = []
    for p in verts:
        if all(norm(sub(p, q)) > 1e-7 * (1 + norm(p)) for q in uniq):
            uniq.append(p)
    if len(uniq) != 4:
        return None
    a, b, c = (verts[i] for i in faces[0])
    n = cross(sub(b, a), sub(c, a))
    if norm(n) == 0:
        return None
    n = [x / norm(n) for x in n]
    a2, b2, c2 = (verts[i] for i in faces[1])
    if dot(cross(sub(b2, a2), sub(c2, a2)), n) <= 0:
        return None
    centre = [sum(p[i] for p in uniq) / 4 for i in range(3)]
    ax = sub(uniq[0], centre)
    ax = [x / norm(ax) for x in ax]
    ay = cross(n, ax)
    ring = sorted(uniq, key=lambda p: math.atan2(dot(sub(p, centre), ay), dot(sub(p, centre), ax)))
    u, v = sub(ring[1], ring[0]), sub(ring[3], ring[0])
    scale = max(norm(u), norm(v))
    if abs(dot(u, v)) > 1e-5 * scale * scale or norm(sub(sub(ring[2], ring[1]), v)) > 1e-5 * scale or abs(dot(sub(ring[2], ring[0]), n)) > 1e-5 * scale:
        return None
    return ring[0], u, v, n
