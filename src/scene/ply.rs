//! PLY ("Stanford triangle format") scenes, ASCII and binary of either byte
//! order, read with the `ply-rs-bw` crate: `vertex` elements (`x y z`, and
//! `nx ny nz` when present), `face` elements (a `vertex_indices` or
//! `vertex_index` list, polygons fan-triangulated). Other elements and
//! properties (colours, confidence, edges) are skipped. Geometry only:
//! materials, light and camera are [`mesh_scene`]'s
//! defaults.

use super::mesh_scene::{self, NamedMesh};
use super::{Scene, TriangleMesh};
use crate::error::{Error, Result};
use glam::Vec3;
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{Property, PropertyAccess, PropertyAccessResult};
use std::path::Path;

pub fn load_file(path: &Path) -> Result<Scene> {
    let bytes = std::fs::read(path).map_err(|e| Error::new(format!("{}: cannot read: {e}", path.display())))?;
    let name = super::name_of(path);
    parse(bytes.as_slice(), &name, &path.display().to_string())
}

/// The fewest bytes one entry of `element` can take in the payload: its
/// scalars' sizes and its lists' length fields in binary, a character and
/// a separator per property in ASCII; at least one.
fn min_entry_bytes(element: &ply_rs_bw::ply::ElementDef, encoding: ply_rs_bw::ply::Encoding) -> u64 {
    use ply_rs_bw::ply::{Encoding, PropertyType, ScalarType};
    let size = |t: &ScalarType| match t {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    };
    let bytes: u64 = element
        .properties
        .values()
        .map(|p| match (&p.data_type, encoding) {
            (_, Encoding::Ascii) => 2,
            (PropertyType::Scalar(t), _) | (PropertyType::List(t, _), _) => size(t),
        })
        .sum();
    bytes.max(1)
}

/// One `vertex` element: position and, when the file has them, a normal.
struct Vertex {
    p: [f64; 3],
    n: [f64; 3],
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Vertex { p: [f64::NAN; 3], n: [0.0; 3] }
    }
    fn set_property(&mut self, key: &str, value: Property) -> PropertyAccessResult {
        let slot = match key {
            "x" => &mut self.p[0],
            "y" => &mut self.p[1],
            "z" => &mut self.p[2],
            "nx" => &mut self.n[0],
            "ny" => &mut self.n[1],
            "nz" => &mut self.n[2],
            _ => return PropertyAccessResult::Ignored,
        };
        match scalar(&value) {
            Some(v) => {
                *slot = v;
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::UnsupportedType,
        }
    }
}

fn scalar(v: &Property) -> Option<f64> {
    Some(match *v {
        Property::Char(x) => x as f64,
        Property::UChar(x) => x as f64,
        Property::Short(x) => x as f64,
        Property::UShort(x) => x as f64,
        Property::Int(x) => x as f64,
        Property::UInt(x) => x as f64,
        Property::Float(x) => x as f64,
        Property::Double(x) => x,
        _ => return None,
    })
}

/// One `face` element: its vertex indices, any integer type; a negative
/// index is kept as such so the loader can name it.
#[derive(Default)]
struct Face {
    indices: Vec<i64>,
}

impl PropertyAccess for Face {
    fn new() -> Self {
        Face::default()
    }
    fn set_property(&mut self, key: &str, value: Property) -> PropertyAccessResult {
        if key != "vertex_indices" && key != "vertex_index" {
            return PropertyAccessResult::Ignored;
        }
        self.indices = match value {
            Property::ListChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListInt(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUInt(v) => v.into_iter().map(i64::from).collect(),
            _ => return PropertyAccessResult::UnsupportedType,
        };
        PropertyAccessResult::Set
    }
}

/// An element this loader does not use, read and dropped.
struct Skipped;

impl PropertyAccess for Skipped {
    fn new() -> Self {
        Skipped
    }
}

/// `ply-rs`'s message without its parser's debug dump: the line and what
/// was wrong ("Line 3: Couldn't parse line. String: 'format ascii 9'").
fn ply_error(e: &impl std::fmt::Display) -> String {
    let text = e.to_string();
    let kept: Vec<&str> = text.lines().map(str::trim).filter(|l| !l.is_empty() && !l.contains("ParseError {")).collect();
    kept.join(" ")
}

/// Parse a PLY stream; `source` names it in messages.
pub fn parse(mut input: impl std::io::Read, name: &str, source: &str) -> Result<Scene> {
    let fail = |what: String| Error::new(format!("{source}: {what}"));
    let mut bytes = Vec::new();
    input.read_to_end(&mut bytes).map_err(|e| fail(format!("cannot read: {e}")))?;
    let mut reader = Reader::new(std::io::Cursor::new(bytes.as_slice()));
    let header = Parser::<Skipped>::new().read_header(&mut reader).map_err(|e| fail(format!("not a valid PLY header: {}", ply_error(&e))))?;
    // The reader reserves room for every entry a header announces: a count
    // the file cannot hold (a damaged "element face 4294967296" in 300
    // bytes) is refused before it is believed.
    let mut need = 0u64;
    for (_, element) in &header.elements {
        let per = min_entry_bytes(element, header.encoding);
        need = need.saturating_add((element.count as u64).saturating_mul(per));
        if need > bytes.len() as u64 {
            crate::bail!(
                "{source}: element '{}' announces {} entries of at least {per} bytes each, more than the file's {} bytes can hold (damaged header?)",
                element.name,
                element.count,
                bytes.len()
            );
        }
    }
    for required in ["vertex", "face"] {
        if !header.elements.contains_key(required) {
            crate::bail!("{source}: no '{required}' element (a PLY mesh needs vertices and faces)");
        }
    }
    let has_normals = ["nx", "ny", "nz"].iter().all(|k| header.elements["vertex"].properties.contains_key(*k));
    let mut vertices: Vec<Vertex> = Vec::new();
    let mut faces: Vec<Face> = Vec::new();
    // Elements come in header order; each is read (or skipped) in turn.
    for (_, element) in &header.elements {
        let what = |e: ply_rs_bw::parser::ParseError| fail(format!("bad '{}' data: {}", element.name, ply_error(&e)));
        match element.name.as_str() {
            "vertex" => vertices = Parser::<Vertex>::new().read_payload_for_element(&mut reader, element, &header).map_err(what)?,
            "face" => faces = Parser::<Face>::new().read_payload_for_element(&mut reader, element, &header).map_err(what)?,
            _ => {
                Parser::<Skipped>::new().read_payload_for_element(&mut reader, element, &header).map_err(what)?;
            }
        }
    }
    let mut positions = Vec::with_capacity(vertices.len());
    let mut normals = Vec::with_capacity(if has_normals { vertices.len() } else { 0 });
    for (i, v) in vertices.iter().enumerate() {
        let p = Vec3::new(v.p[0] as f32, v.p[1] as f32, v.p[2] as f32);
        if !p.is_finite() {
            crate::bail!("{source}: vertex {i} has a missing or non-finite coordinate ({}, {}, {})", v.p[0], v.p[1], v.p[2]);
        }
        positions.push(p);
        if has_normals {
            normals.push(Vec3::new(v.n[0] as f32, v.n[1] as f32, v.n[2] as f32));
        }
    }
    let n = positions.len() as i64;
    let mut triangles = Vec::with_capacity(faces.len());
    let mut poly = Vec::new();
    for (f, face) in faces.iter().enumerate() {
        if face.indices.len() < 3 {
            crate::bail!("{source}: face {f} has {} vertices (needs at least 3)", face.indices.len());
        }
        if let Some(&bad) = face.indices.iter().find(|&&i| i < 0 || i >= n) {
            crate::bail!("{source}: face {f} uses vertex {bad}, but there are {n} vertices");
        }
        poly.clear();
        poly.extend(face.indices.iter().map(|&i| i as u32));
        mesh_scene::fan(&poly, &mut triangles);
    }
    mesh_scene::from_meshes(name, source, vec![NamedMesh { name: name.to_string(), mesh: TriangleMesh { positions, triangles, normals } }])
}
