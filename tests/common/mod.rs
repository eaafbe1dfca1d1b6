//! Helpers shared by the integration tests.
#![allow(dead_code)]

use pathtracer::accel::{self, BackendKind, Traversal};
use glam::{Mat3, Vec3};
use pathtracer::camera::Camera;
use pathtracer::render::path::specular_guide::{self, SpecularGuide};
use pathtracer::scene::{collada, Surface, CameraDesc, LightDesc, Material, Object, Scene, Shape, TriangleMesh};
use statrs::distribution::{ChiSquared, ContinuousCDF, Normal};
use std::path::{Path, PathBuf};

/// The Embree majors `PATHTRACER_REQUIRE_EMBREE` makes mandatory (set by
/// CI): `1` or `all` both, else a list such as `3,4` or `4`.
fn required_embree() -> Vec<u32> {
    match std::env::var("PATHTRACER_REQUIRE_EMBREE") {
        Err(_) => Vec::new(),
        Ok(v) if v == "1" || v == "all" => vec![3, 4],
        Ok(v) => v.split(',').filter_map(|m| m.trim().parse().ok()).collect(),
    }
}

/// The Embree backends that load here (`embree3`, `embree4`), in that
/// order; a missing one is reported loudly, and fails the test when
/// `PATHTRACER_REQUIRE_EMBREE` names it.
pub fn embree_backends() -> Vec<BackendKind> {
    use pathtracer::accel::embree::{self, Major};
    let mut v = Vec::new();
    for (major, kind) in [(Major::V3, BackendKind::Embree3), (Major::V4, BackendKind::Embree4)] {
        if embree::available(major) {
            v.push(kind);
        } else {
            assert!(
                !required_embree().contains(&major.number()),
                "PATHTRACER_REQUIRE_EMBREE names Embree {} but it cannot be used here: {}",
                major.number(),
                embree::unavailable_reason(major)
            );
            eprintln!("NOTE: the {kind} backend cannot be used here ({}); its cases are skipped", embree::unavailable_reason(major));
        }
    }
    v
}

/// Every backend that can be used here: native, brute force, and each
/// Embree that loads (see `embree_backends`).
pub fn backends() -> Vec<BackendKind> {
    let mut v = vec![BackendKind::Native, BackendKind::Brute];
    v.extend(embree_backends());
    v
}

/// The path tracer's guide toward `scene`'s mirror, glass and metal objects
/// at its default share (`--specular-guide`), as the command line builds it.
#[allow(dead_code)]
pub fn guide(scene: &Scene) -> Option<SpecularGuide> {
    SpecularGuide::of_scene(scene, specular_guide::DEFAULT_FRACTION).0
}

pub fn build(kind: BackendKind, shapes: &[Shape]) -> Box<dyn Traversal> {
    accel::build(kind, shapes, 0).unwrap_or_else(|e| panic!("building {kind}: {e}")).accel
}

/// The 20 CS184 scenes the repository carries (`scenes/cs184`). Missing
/// data is a failure, not a pass.
pub fn cs184_scene_dir() -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cs184");
    assert!(dir.is_dir(), "test data missing: CS184 scenes not found at {}", dir.display());
    dir
}

/// Every shipped `.dae`, sorted, with the scenes the project carries itself.
pub fn shipped_scenes() -> Vec<PathBuf> {
    let mut v = Vec::new();
    for sub in ["meshedit", "simple", "sky"] {
        let d = cs184_scene_dir().join(sub);
        for e in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "dae") {
                v.push(p);
            }
        }
    }
    v.sort();
    assert_eq!(v.len(), 20, "expected the 20 CS184 scenes in {}", cs184_scene_dir().display());
    v
}

pub fn load(p: &Path) -> Scene {
    collada::load_file(p).unwrap_or_else(|e| panic!("{e}"))
}

pub fn scene_path(sub: &str, name: &str) -> PathBuf {
    let p = cs184_scene_dir().join(sub).join(format!("{name}.dae"));
    assert!(p.exists(), "test data missing: {}", p.display());
    p
}

/// Two-sided critical z for family-wise `alpha` over `m` tests (Šidák).
pub fn z_crit(alpha: f64, m: usize) -> f64 {
    let a = 1.0 - (1.0 - alpha).powf(1.0 / m as f64);
    Normal::new(0.0, 1.0).unwrap().inverse_cdf(1.0 - a / 2.0)
}

pub fn sidak(alpha: f64, m: usize) -> f64 {
    1.0 - (1.0 - alpha).powf(1.0 / m as f64)
}


/// Pearson chi-square p-value of `counts` against `expected`, pooling cells
/// with expected count below 5 (Mitsuba/pbrt practice).
pub fn chi2_p(counts: &[f64], expected: &[f64]) -> f64 {
    let (mut chi2, mut dof) = (0.0, 0usize);
    let (mut pool_c, mut pool_e) = (0.0, 0.0);
    for (&c, &e) in counts.iter().zip(expected) {
        assert!(e > 0.0 || c == 0.0, "samples in a zero-pdf cell");
        if e < 5.0 {
            pool_c += c;
            pool_e += e;
            continue;
        }
        chi2 += (c - e) * (c - e) / e;
        dof += 1;
    }
    if pool_e >= 5.0 {
        chi2 += (pool_c - pool_e) * (pool_c - pool_e) / pool_e;
        dof += 1;
    }
    1.0 - ChiSquared::new((dof - 1) as f64).unwrap().cdf(chi2)
}


pub fn diffuse(name: &str, albedo: f32, emission: f32) -> Material {
    Material { name: name.into(), surface: Surface::Diffuse { albedo: Vec3::splat(albedo) }, emission: Vec3::splat(emission) }
}

/// Smooth glass of index 1.45 that reflects and transmits everything
/// (CS184's `<glass>` with reflectance and transmittance 1).
pub fn lossless_glass() -> Material {
    Material { name: "glass".into(), surface: Surface::Glass { reflectance: Vec3::ONE, transmittance: Vec3::ONE, roughness: 0.0, ior: 1.45 }, emission: Vec3::ZERO }
}

/// A welded cube [-h,h]^3 (shared vertices), every triangle wound to face
/// `inward` or outward. Its vertex normals are CS184's area-weighted ones,
/// diagonal at the corners.
pub fn cube_mesh(h: f32, center: Vec3, inward: bool) -> TriangleMesh {
    let v: Vec<Vec3> = (0..8).map(|i| center + h * Vec3::new(if i & 1 == 0 { -1.0 } else { 1.0 }, if i & 2 == 0 { -1.0 } else { 1.0 }, if i & 4 == 0 { -1.0 } else { 1.0 })).collect();
    let quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
    let mut triangles = Vec::new();
    for q in quads {
        for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
            let [a, b, c] = t.map(|i: u32| v[i as usize]);
            let n = (b - a).cross(c - a);
            let faces_in = n.dot(center - a) > 0.0;
            triangles.push(if faces_in == inward { t } else { [t[0], t[2], t[1]] });
        }
    }
    let mut m = TriangleMesh { positions: v, triangles, normals: vec![] };
    m.compute_normals();
    m
}

/// The same cube with each face's vertices its own, so vertex normals equal
/// face normals: flat shading, which the furnace's closed forms assume.
/// Shared edges still have bit-identical coordinates: it stays watertight.
pub fn flat_cube_mesh(h: f32, center: Vec3, inward: bool) -> TriangleMesh {
    let welded = cube_mesh(h, center, inward);
    let mut m = TriangleMesh::default();
    for t in &welded.triangles {
        let base = m.positions.len() as u32;
        m.positions.extend(t.map(|i| welded.positions[i as usize]));
        m.triangles.push([base, base + 1, base + 2]);
    }
    m.compute_normals();
    m
}

pub fn scene_of(shapes: Vec<(Shape, Material)>, lights: Vec<LightDesc>) -> Scene {
    let mut scene = Scene {
        name: "test".into(),
        source: "<test>".into(),
        shapes: vec![],
        objects: vec![],
        materials: vec![],
        lights,
        camera: CameraDesc::default(),
    };
    for (i, (s, m)) in shapes.into_iter().enumerate() {
        scene.shapes.push(s);
        scene.materials.push(m);
        scene.objects.push(Object { name: format!("shape{i}"), material: i });
    }
    scene
}

/// A camera at `pos` looking down -z with a 60-degree field of view.
pub fn camera_at(scene: &Scene, pos: Vec3, w: u32, h: u32) -> Camera {
    let mut c = Camera::from_scene(scene);
    c.pos = pos;
    c.c2w = Mat3::IDENTITY;
    c.near = 0.0;
    c.far = f32::INFINITY;
    c.hfov_deg = 60.0;
    c.vfov_deg = (2.0 * ((30f32).to_radians().tan() * h as f32 / w as f32).atan()).to_degrees();
    c
}


/// A test's scratch folder under the system's temp folder, emptied when
/// made and removed when the test passes; a failing test keeps it (and says
/// where) so its files can be looked at. Without the removal every run of the
/// suites left about a hundred folders behind.
pub struct Scratch(PathBuf);

impl Scratch {
    pub fn new(suite: &str, name: &str) -> Scratch {
        let d = std::env::temp_dir().join(format!("pathtracer-{suite}-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap_or_else(|e| panic!("cannot make {}: {e}", d.display()));
        Scratch(d)
    }
}

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if std::thread::panicking() {
            eprintln!("test failed: its files are kept in {}", self.0.display());
        } else {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// A 64×32 sky map: a gradient above the horizon, a dark ground, and a
/// small "sun" of two texels of radiance `sun`.
pub fn sun_sky(sun: Vec3) -> std::sync::Arc<pathtracer::light::environment::EnvMap> {
    let (w, h) = (64usize, 32usize);
    let mut t = Vec::with_capacity(w * h);
    for j in 0..h {
        for i in 0..w {
            let sky = if j < h / 2 { Vec3::new(0.3, 0.5, 0.9) * (1.0 - j as f32 / h as f32) } else { Vec3::new(0.05, 0.04, 0.03) };
            let disc = if (i, j) == (40, 9) || (i, j) == (41, 9) { sun } else { Vec3::ZERO };
            t.push(sky + disc);
        }
    }
    std::sync::Arc::new(pathtracer::light::environment::EnvMap::from_texels("sun sky".into(), w, h, t))
}

/// Every file under `dir`, at any depth, sorted (for checks that walk the
/// repository: its modules, its scenes).
pub fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}
