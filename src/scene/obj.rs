//! Wavefront OBJ scenes, read with the `tobj` crate: `v`, `vn` and `f`
//! (polygons fan-triangulated, negative indices allowed), one mesh per `o`/`g`
//! group. Geometry only: materials, light and camera are
//! [`mesh_scene`]'s defaults. `mtllib`/`usemtl` are not
//! read — the loader says so on stderr rather than dropping them silently.
//! Points and lines are skipped (they have no surface to render).

use super::mesh_scene::{self, NamedMesh};
use super::{Scene, TriangleMesh};
use crate::error::{Error, Result};
use glam::Vec3;
use std::cell::Cell;
use std::path::Path;

pub fn load_file(path: &Path) -> Result<Scene> {
    let file = std::fs::File::open(path).map_err(|e| Error::new(format!("{}: cannot read: {e}", path.display())))?;
    let name = super::name_of(path);
    parse(&mut std::io::BufReader::new(file), &name, &path.display().to_string())
}

/// Parse OBJ text from `reader`; `source` names it in messages.
pub fn parse(reader: &mut impl std::io::BufRead, name: &str, source: &str) -> Result<Scene> {
    let options = tobj::LoadOptions { single_index: true, triangulate: false, ignore_points: true, ignore_lines: true };
    // The material loader is never asked to read a file: it only notes that
    // the OBJ names one.
    let mtllib: Cell<Option<String>> = Cell::new(None);
    let (models, _) = tobj::load_obj_buf(reader, &options, |p| {
        mtllib.set(Some(p.display().to_string()));
        Err(tobj::LoadError::GenericFailure)
    })
    .map_err(|e| {
        let why = match e {
            tobj::LoadError::ReadError => "a line is not UTF-8 text or cannot be read".to_string(),
            other => other.to_string(),
        };
        Error::new(format!("{source}: not a valid OBJ file: {why}"))
    })?;
    if let Some(lib) = mtllib.take() {
        eprintln!("pathtracer: {source}: OBJ materials ({lib}) are not read; every mesh renders with the default diffuse 0.5");
    }
    let mut meshes = Vec::with_capacity(models.len());
    for (k, model) in models.into_iter().enumerate() {
        let m = model.mesh;
        let label = if model.name.is_empty() || model.name == "unnamed_object" { format!("object {k}") } else { model.name };
        let positions: Vec<Vec3> = m.positions.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
        let normals: Vec<Vec3> = if m.normals.len() == m.positions.len() {
            m.normals.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect()
        } else {
            Vec::new()
        };
        let mut triangles = Vec::with_capacity(m.indices.len() / 3);
        if m.face_arities.is_empty() {
            // tobj leaves the arities empty when every face is a triangle.
            triangles.extend(m.indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
        } else {
            let mut at = 0usize;
            for (f, &n) in m.face_arities.iter().enumerate() {
                let n = n as usize;
                if n < 3 {
                    crate::bail!("{source}: mesh '{label}': face {f} has {n} vertices");
                }
                mesh_scene::fan(&m.indices[at..at + n], &mut triangles);
                at += n;
            }
        }
        meshes.push(NamedMesh { name: label, mesh: TriangleMesh { positions, triangles, normals } });
    }
    mesh_scene::from_meshes(name, source, meshes)
}
