//! The loaded scene: shapes for the backends, and everything shared code needs
//! to describe a hit (normals, materials), light and camera.

pub mod builtin;
pub mod collada;
pub mod generated;
pub mod interaction;
pub mod material;
pub mod mesh_scene;
pub mod obj;
pub mod ply;

pub use interaction::Interaction;
pub use material::{Material, Surface};

use crate::geometry::Aabb;
use glam::{Mat4, Vec3};

/// A triangle mesh in world space. `normals` are per-vertex, area-weighted
/// (CS184's rule), computed by the loader; backends only read positions.
#[derive(Clone, Debug, Default)]
pub struct TriangleMesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
    pub normals: Vec<Vec3>,
}

/// What `TriangleMesh::prefetch` starts loading for a triangle: a step at
/// a time, because the vertices' addresses are read from the indices.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFetch {
    /// Its vertex indices.
    Indices,
    /// Its three positions (once the indices are near): what a build reads.
    Positions,
    /// Its three positions and normals: what describing a hit reads.
    PositionsAndNormals,
}

impl TriangleMesh {
    /// Start loading triangle `t`'s data, `step` of it, ahead of its use.
    /// A hint: it changes nothing, does nothing for an index out of range
    /// (the vertex indices are checked before their vertices are named),
    /// and nothing off x86-64.
    #[inline]
    pub fn prefetch(&self, t: usize, step: MeshFetch) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let Some(tri) = self.triangles.get(t) else { return };
            // SAFETY: prefetching reads nothing; every address is in bounds.
            unsafe {
                if step == MeshFetch::Indices {
                    return _mm_prefetch::<_MM_HINT_T0>(tri.as_ptr() as *const i8);
                }
                for &k in tri {
                    let k = k as usize;
                    if k < self.positions.len() {
                        _mm_prefetch::<_MM_HINT_T0>(self.positions.as_ptr().add(k) as *const i8);
                    }
                    if step == MeshFetch::PositionsAndNormals && k < self.normals.len() {
                        _mm_prefetch::<_MM_HINT_T0>(self.normals.as_ptr().add(k) as *const i8);
                    }
                }
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = (t, step);
    }

    /// Area-weighted vertex normals: each face adds its (unnormalised) cross
    /// product to its three vertices. Vertices with no non-degenerate face get
    /// a zero normal, which `Interaction` replaces by the face normal.
    /// Summed in f64, so that neither the cross products nor their squared
    /// lengths overflow or underflow at any f32 scale (see
    /// `geometry::face_normal`).
    pub fn compute_normals(&mut self) {
        let mut n = vec![glam::DVec3::ZERO; self.positions.len()];
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.positions[i as usize]);
            let f = crate::geometry::triangle::edge_cross(a, b, c);
            for &i in t {
                n[i as usize] += f;
            }
        }
        self.normals = n.into_iter().map(|v| v.normalize_or_zero().as_vec3()).collect();
    }
}

/// The largest coordinate magnitude (sphere extents included) a scene may
/// have; see [`Scene::check_extents`].
pub const MAX_COORDINATE: f32 = 1.0e12;
/// The smallest size (largest side of the bounding box) a scene may have.
pub const MIN_EXTENT: f32 = 1.0e-9;

/// A scene's name: its file's base name without the extension (CS184's
/// `pathtracer_filename`).
pub(crate) fn name_of(path: &std::path::Path) -> String {
    path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "scene".into())
}

/// The scene formats `load_file` reads, for error messages.
pub const FORMATS: &str = "scenes are COLLADA (.dae), Wavefront OBJ (.obj) or PLY (.ply) files";

/// Load a scene file by its extension: `.dae` (CS184 COLLADA), `.obj`, `.ply`.
pub fn load_file(path: &std::path::Path) -> crate::error::Result<Scene> {
    let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("obj") => obj::load_file(path),
        Some("ply") => ply::load_file(path),
        Some("dae" | "xml") => collada::load_file(path),
        Some(other) => crate::bail!("{}: unknown scene format '.{other}': {FORMATS}", path.display()),
        None => crate::bail!("{}: no file extension to tell its format: {FORMATS}", path.display()),
    }
}

/// Geometry a backend can intersect. Its index in `Scene::shapes` is the
/// geometry id in `Hit::geom_id`.
#[derive(Clone, Debug)]
pub enum Shape {
    Mesh(TriangleMesh),
    Sphere { center: Vec3, radius: f32 },
}

impl Shape {
    pub fn primitive_count(&self) -> usize {
        match self {
            Shape::Mesh(m) => m.triangles.len(),
            Shape::Sphere { .. } => 1,
        }
    }

    pub fn bounds(&self) -> Aabb {
        match self {
            Shape::Mesh(m) => {
                let mut b = Aabb::EMPTY;
                for &p in &m.positions {
                    b.grow(p);
                }
                b
            }
            Shape::Sphere { center, radius } => Aabb { min: *center - Vec3::splat(*radius), max: *center + Vec3::splat(*radius) },
        }
    }
}

/// What a shape is made of, parallel to `Scene::shapes`.
#[derive(Clone, Debug)]
pub struct Object {
    /// The COLLADA node name, for messages.
    pub name: String,
    /// Index into `Scene::materials`.
    pub material: usize,
}

/// A light as the file describes it. `transform` is the node's world matrix
/// (up-axis fix included); the light-transport code derives positions and
/// directions from it.
#[derive(Clone, Debug)]
pub struct LightDesc {
    pub name: String,
    pub kind: LightKind,
    pub radiance: Vec3,
    pub transform: Mat4,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightKind {
    Ambient,
    Directional,
    Area,
    Point,
    Spot,
}

impl LightKind {
    pub fn as_str(&self) -> &'static str {
        match self {
            LightKind::Ambient => "ambient",
            LightKind::Directional => "directional",
            LightKind::Area => "area",
            LightKind::Point => "point",
            LightKind::Spot => "spot",
        }
    }
}

/// The file's camera, before CS184's placement rule moves it (see `camera`).
#[derive(Clone, Copy, Debug)]
pub struct CameraDesc {
    pub hfov_deg: f32,
    pub vfov_deg: f32,
    pub znear: f32,
    pub zfar: f32,
    /// CS184's `c_dir = normalize((T * (0,0,-1,1)).xyz)`: with w = 1 the
    /// node's translation is included. The camera is placed on this side of
    /// the scene's bounding-box centre.
    pub c_dir: Vec3,
}

impl Default for CameraDesc {
    fn default() -> Self {
        CameraDesc { hfov_deg: 50.0, vfov_deg: 35.0, znear: 0.001, zfar: 1000.0, c_dir: Vec3::Z }
    }
}

#[derive(Clone, Debug)]
pub struct Scene {
    /// Base name of the file without `.dae` (CS184's `pathtracer_filename`).
    pub name: String,
    /// Where it came from, for messages: a path or `<built-in>`.
    pub source: String,
    pub shapes: Vec<Shape>,
    pub objects: Vec<Object>,
    pub materials: Vec<Material>,
    pub lights: Vec<LightDesc>,
    pub camera: CameraDesc,
}

impl Scene {
    pub fn primitive_count(&self) -> usize {
        self.shapes.iter().map(Shape::primitive_count).sum()
    }

    pub fn triangle_count(&self) -> usize {
        self.shapes.iter().map(|s| if let Shape::Mesh(m) = s { m.triangles.len() } else { 0 }).sum()
    }

    pub fn sphere_count(&self) -> usize {
        self.shapes.iter().filter(|s| matches!(s, Shape::Sphere { .. })).count()
    }

    /// Bounds of all shapes (lights excluded), as CS184 computes them.
    pub fn bounds(&self) -> Aabb {
        self.shapes.iter().fold(Aabb::EMPTY, |b, s| b.union(&s.bounds()))
    }

    /// Refuses a scene whose size the f32 ray arithmetic cannot carry,
    /// rather than render it wrong. The watertight triangle test computes
    /// the hit distance as a sum of products of *three* coordinate
    /// differences over a sum of products of two, so the cube of the
    /// scene's size must stay inside f32's normal range. Measured by
    /// rendering the bunny scaled by powers of ten against the unscaled one:
    /// identical images with coordinates from about 1e-11 to 1.7e13 (native;
    /// Embree to 1.7e13), black or wrong pixels outside (t = inf at 1e15,
    /// 7 % dark at 1e-12). The bounds below keep a factor of 10–100 inside that.
    pub fn check_extents(&self) -> crate::error::Result<()> {
        let mut all = Aabb::EMPTY;
        for (i, s) in self.shapes.iter().enumerate() {
            let b = s.bounds();
            all = all.union(&b);
            let far = b.min.abs().max(b.max.abs()).max_element();
            if !(far <= MAX_COORDINATE) {
                let what = match s {
                    Shape::Mesh(_) => "mesh",
                    Shape::Sphere { .. } => "sphere",
                };
                crate::bail!(
                    "{what} '{}' reaches {far:e}, beyond the ±{MAX_COORDINATE:e} that f32 ray arithmetic can carry (rescale the scene)",
                    self.objects.get(i).map_or("?", |o| o.name.as_str())
                );
            }
        }
        let size = all.extent().max_element();
        if !(size >= MIN_EXTENT) {
            crate::bail!("the whole scene is {size:e} across, below the {MIN_EXTENT:e} that f32 ray arithmetic can resolve (rescale the scene)");
        }
        Ok(())
    }

    pub fn material_of(&self, geom_id: u32) -> &Material {
        &self.materials[self.objects[geom_id as usize].material]
    }
}
