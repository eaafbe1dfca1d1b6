//! A scene made from bare triangle meshes (OBJ and PLY files, the bench's
//! generators): those formats carry geometry only, so everything else is a
//! fixed default, stated here and in `--help`:
//!
//! * **material**: CS184's default diffuse, albedo 0.5, on every mesh (OBJ
//!   `mtllib`/`usemtl` are not read; the loader says so on stderr);
//! * **light**: a hemisphere ("ambient") sky of radiance 1 over +y, the light
//!   of CS184's `bunny.dae` — a sky-lit, ambient-occlusion-like image at
//!   `-m 1`, without guessing where a lamp would belong;
//! * **camera**: CS184's default placement (the view along −z, 50°×35°
//!   field of view, backed off until the bounding sphere fits), with no
//!   near or far clipping plane.
//!
//! Every loader goes through [`from_meshes`], so the checks a mesh must pass
//! are the same whatever the file format: indices in range, finite
//! coordinates, at least one triangle, and extents the ray arithmetic can
//! carry ([`Scene::check_extents`]).

use super::{CameraDesc, LightDesc, LightKind, Material, Object, Scene, Shape, TriangleMesh};
use crate::error::Result;
use glam::{Mat4, Vec3};

/// One mesh as a file describes it: a name for messages, and normals that
/// are either one per position (from the file) or empty (computed here).
pub struct NamedMesh {
    pub name: String,
    pub mesh: TriangleMesh,
}

/// Checks every mesh, fills in missing normals and wraps the meshes in a
/// scene with the defaults of this module's doc comment. An error is one
/// line: `source`, the mesh and the problem.
pub fn from_meshes(name: &str, source: &str, meshes: Vec<NamedMesh>) -> Result<Scene> {
    build(name, source, meshes).map_err(|e| crate::error::Error::new(format!("{source}: {}", e.0)))
}

fn build(name: &str, source: &str, meshes: Vec<NamedMesh>) -> Result<Scene> {
    let mut scene = Scene {
        name: name.to_string(),
        source: source.to_string(),
        shapes: Vec::new(),
        objects: Vec::new(),
        materials: vec![Material::default_diffuse()],
        lights: vec![LightDesc {
            name: "default sky".into(),
            kind: LightKind::Ambient,
            radiance: Vec3::ONE,
            transform: Mat4::IDENTITY,
        }],
        // No clipping planes: COLLADA's default near/far (0.001, 1000)
        // would hide a mesh drawn in millimetres or kilometres.
        camera: CameraDesc { znear: 0.0, zfar: f32::INFINITY, ..CameraDesc::default() },
    };
    for NamedMesh { name: mesh_name, mut mesh } in meshes {
        check_mesh(&mesh, &mesh_name)?;
        if mesh.triangles.is_empty() {
            continue;
        }
        if mesh.normals.len() == mesh.positions.len() {
            // Unit length for shading; a zero normal is kept as zero, which
            // `Interaction` replaces by the face normal (as for computed ones).
            for n in &mut mesh.normals {
                *n = n.normalize_or_zero();
            }
        } else {
            mesh.compute_normals();
        }
        scene.shapes.push(Shape::Mesh(mesh));
        scene.objects.push(Object { name: mesh_name, material: 0 });
    }
    if scene.shapes.is_empty() {
        crate::bail!("no triangles (an empty mesh, or only points and lines)");
    }
    scene.check_extents()?;
    Ok(scene)
}

fn check_mesh(m: &TriangleMesh, name: &str) -> Result<()> {
    if let Some(i) = m.positions.iter().position(|p| !p.is_finite()) {
        crate::bail!("mesh '{name}': vertex {i} has a non-finite coordinate ({})", m.positions[i]);
    }
    if let Some(i) = m.normals.iter().position(|n| !n.is_finite()) {
        crate::bail!("mesh '{name}': normal {i} is not finite ({})", m.normals[i]);
    }
    let n = m.positions.len();
    if let Some((f, t)) = m.triangles.iter().enumerate().find(|(_, t)| t.iter().any(|&i| i as usize >= n)) {
        crate::bail!("mesh '{name}': triangle {f} uses vertex {:?}, but there are {n} vertices", t);
    }
    Ok(())
}

/// Fan triangulation of one polygon (v0, v1, v2), (v0, v2, v3), ...; the
/// OBJ and PLY convention for convex faces. Fewer than 3 vertices is an
/// error the caller reports.
pub fn fan(poly: &[u32], out: &mut Vec<[u32; 3]>) {
    for k in 1..poly.len().saturating_sub(1) {
        out.push([poly[0], poly[k], poly[k + 1]]);
    }
}
