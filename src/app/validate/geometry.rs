//! Every backend of this build finds the same hits as native: closest hits
//! compared ray by ray (`accel::agreement`: the same primitive with t and
//! the barycentrics within the contract's tolerance, or a tie at the same
//! distance), the shading normal each hit describes, and occlusion along
//! the whole ray and up to just before its hit. Rays: camera rays, random
//! rays, and hard rays made from the scene — grazing along its triangles'
//! edges, leaving its surfaces (a diffuse bounce off the camera's hits),
//! through its vertices. Brute force, the oracle, checks native on a
//! sample sized to the scene.

use super::{Check, Status};
use crate::accel::agreement::{self, Agreement};
use crate::accel::embree::{self, Major};
use crate::accel::workloads::{camera_rays, diffuse_rays, random_rays};
use crate::accel::{self, BackendKind, Hit, Traversal};
use crate::camera::Camera;
use crate::error::Result;
use crate::ray::Ray;
use crate::rng::Rng;
use crate::scene::{Interaction, Scene, Shape};
use glam::Vec3;
use rayon::prelude::*;
use std::collections::{HashMap, HashSet};
use std::time::{Duration, Instant};

/// Brute force checks at most this many triangle tests (rays × primitives).
const BRUTE_TESTS: f64 = 4e8;

/// The rays checked, by kind: camera, random, and the hard ones. `n` is the
/// count of each kind but the camera's frame.
pub fn ray_sets(scene: &Scene, camera: &Camera, native: &dyn Traversal, n: usize) -> Vec<(&'static str, Vec<Ray>)> {
    let (w, h) = ((n as f32 * 4.0 / 3.0).sqrt().max(8.0) as u32, (n as f32 * 0.75).sqrt().max(6.0) as u32);
    let cam = camera_rays(camera, w, h);
    let leaving = diffuse_rays(scene, native, &cam, 17);
    let (grazing, vertices) = hard_rays(scene, n, 23);
    vec![("camera", cam), ("random", random_rays(scene, n, 19)), ("grazing along edges", grazing), ("leaving surfaces", leaving), ("through vertices", vertices)]
}

/// Rays grazing the scene's inner triangle edges (through an edge's
/// midpoint, along the edge, tilted by 1/1000 rad towards the inside of
/// both triangles' planes, so that it crosses each there: the watertight
/// test must hit one of the edge's two triangles) and rays through its
/// inner vertices from outside, each inside the vertex's normal cone (at
/// more than 5° from every face around the vertex, so that it crosses the
/// surface there rather than touching a corner): up to `n` of each, from
/// edges and vertices picked with a fixed seed. Only edges two triangles
/// share (by position) and vertices all of whose edges are such: at a
/// mesh's border a ray through the edge may hit or miss by rounding.
fn hard_rays(scene: &Scene, n: usize, seed: u64) -> (Vec<Ray>, Vec<Ray>) {
    let key = |p: Vec3| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
    // Every edge by its positions, with its triangles' third vertex, and
    // every vertex position with the unit normals of the faces around it.
    let mut edges: HashMap<([u32; 3], [u32; 3]), Vec<(Vec3, Vec3, Vec3)>> = HashMap::new();
    let mut around: HashMap<[u32; 3], (Vec3, Vec<Vec3>)> = HashMap::new();
    for s in &scene.shapes {
        let Shape::Mesh(m) = s else { continue };
        for t in &m.triangles {
            let p = t.map(|v| m.positions[v as usize]);
            let face = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
            for k in 0..3 {
                let (a, c, third) = (p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
                let id = if key(a) < key(c) { (key(a), key(c)) } else { (key(c), key(a)) };
                edges.entry(id).or_default().push((a, c, third));
                around.entry(key(a)).or_insert_with(|| (a, Vec::new())).1.push(face);
            }
        }
    }
    let mut border: HashSet<[u32; 3]> = HashSet::new();
    for (id, tris) in &edges {
        if tris.len() != 2 {
            border.insert(id.0);
            border.insert(id.1);
        }
    }
    // Each inner edge with the sum of its two triangles' unit normals.
    let normal = |(a, c, third): (Vec3, Vec3, Vec3)| (c - a).cross(third - a).normalize_or_zero();
    let mut inner: Vec<(Vec3, Vec3, Vec3)> = edges.values().filter(|t| t.len() == 2).map(|t| (t[0].0, t[0].1, normal(t[0]) + normal(t[1]))).collect();
    // Each inner vertex whose faces all face one way, with their normals.
    let mut cones: Vec<(Vec3, Vec<Vec3>)> = around.into_iter().filter(|(k, (_, f))| !border.contains(k) && !f.contains(&Vec3::ZERO)).map(|(_, v)| v).collect();
    // A fixed order whatever the hash maps'.
    inner.sort_by(|x, y| key(x.0).cmp(&key(y.0)).then(key(x.1).cmp(&key(y.1))));
    cones.sort_by_key(|c| key(c.0));
    let b = scene.bounds();
    let diagonal = b.extent().length().max(1e-6);
    let mut rng = Rng::new(seed, 0xE06E);
    let (mut grazing, mut vertices) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for _ in 0..n {
        if !inner.is_empty() {
            let (a, c, normals) = inner[(rng.uniform() * inner.len() as f32) as usize % inner.len()];
            let e = c - a;
            let tilt = normals.normalize_or_zero();
            if tilt != Vec3::ZERO {
                let dir = e - tilt * (1e-3 * e.length());
                grazing.push(Ray::new((a + c) * 0.5 - dir * 0.5, dir));
            }
        }
        if !cones.is_empty() {
            let (v, faces) = &cones[(rng.uniform() * cones.len() as f32) as usize % cones.len()];
            let axis = faces.iter().copied().sum::<Vec3>().normalize_or_zero();
            let jitter = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) - Vec3::splat(0.5);
            let d = -(axis + 0.3 * jitter).normalize_or_zero();
            // sin 5° = 0.087: the ray crosses every face's plane at more than 5°.
            if faces.iter().all(|f| f.dot(d) < -0.087) {
                let back = diagonal * (0.05 + 0.25 * rng.uniform());
                vertices.push(Ray::new(*v - d * back, d * back));
            }
        }
    }
    (grazing, vertices)
}

/// `other` against `reference` on every ray of `rays`: one check.
/// `cracks`: brute force, where `other` is Embree, whose robust mode has
/// known cracks at vertices (a ray through a vertex can pass between the
/// triangles around it; RenderKit/embree#174, #181, #381): a ray
/// through a vertex that `other` passes while brute force and `reference`
/// hit there is counted apart, and named, rather than failed.
pub fn compare_backends(name: &str, scene: &Scene, reference: &dyn Traversal, other: &dyn Traversal, rays: &[(&str, Vec<Ray>)], cracks: Option<&dyn Traversal>) -> Check {
    let start = Instant::now();
    let mut details = Vec::new();
    let (mut total, mut ties, mut widened, mut wrong, mut cracked, mut open_edges) = (0usize, 0usize, 0usize, 0usize, 0usize, 0usize);
    for (kind, set) in rays {
        let per: Vec<(Agreement, Option<String>)> = set
            .par_iter()
            .map(|r| {
                let (a, b) = (reference.intersect(r), other.intersect(r));
                let mut verdict = agreement::compare(scene, r, a, b);
                // Through a vertex (at t = 1), `other` passing where the oracle hits.
                if let (Agreement::Differ(_), Some(oracle), Some(x)) = (&verdict, cracks, a) {
                    let passes = b.is_none_or(|y| y.t > x.t);
                    let at_vertex = (x.t - 1.0).abs() < 1e-3;
                    if *kind == "through vertices" && passes && at_vertex && !matches!(agreement::compare(scene, r, oracle.intersect(r), a), Agreement::Differ(_)) {
                        verdict = Agreement::Crack;
                    }
                }
                // A hit on the edge of an open surface against a pass.
                if let Agreement::Differ(_) = verdict {
                    let open = |x: Option<Hit>, y: Option<Hit>| x.is_some_and(|x| y.is_none_or(|y| y.t > x.t) && agreement::on_open_edge(scene, r, &x));
                    if open(a, b) || open(b, a) {
                        verdict = Agreement::OpenEdge;
                    }
                }
                let extra = match (&verdict, a, b) {
                    (Agreement::Same | Agreement::Widened, Some(x), Some(y)) => {
                        let (p, q) = (Interaction::with_barycentrics(scene, r, &x, reference.exact_barycentrics()), Interaction::with_barycentrics(scene, r, &y, other.exact_barycentrics()));
                        (p.ns.dot(q.ns) < 1.0 - 1e-4).then(|| format!("shading normals differ: {} against {}", p.ns, q.ns))
                    }
                    _ => None,
                };
                let extra = extra.or_else(|| agreement::compare_occlusion(scene, r, a, reference, other, agreement::OccluderTies::Allowed));
                (verdict, extra)
            })
            .collect();
        for (i, (verdict, extra)) in per.into_iter().enumerate() {
            total += 1;
            let why = match verdict {
                Agreement::Tie => {
                    ties += 1;
                    extra
                }
                Agreement::Widened => {
                    widened += 1;
                    extra
                }
                Agreement::Same => extra,
                Agreement::Crack => {
                    cracked += 1;
                    if details.len() < 20 {
                        details.push(format!("{kind} ray {i} {:?}: passes through the vertex (brute force hits it), Embree's known crack", set[i]));
                    }
                    None
                }
                Agreement::OpenEdge => {
                    open_edges += 1;
                    if details.len() < 20 {
                        details.push(format!("{kind} ray {i} {:?}: one backend hits within f32 of an edge no other triangle shares, the other passes it", set[i]));
                    }
                    extra
                }
                Agreement::Differ(w) => Some(w),
            };
            if let Some(w) = why {
                wrong += 1;
                if details.len() < 20 {
                    details.push(format!("{kind} ray {i} {:?}: {w}", set[i]));
                }
            }
        }
    }
    let status = if wrong == 0 { Status::Pass } else { Status::Fail };
    let summary = match status {
        Status::Pass => format!(
            "{total} rays, the same hits ({ties} ties at equal distance, {widened} within the f32 bound of small far triangles{}{})",
            if cracked > 0 { format!("; {cracked} rays through vertices pass through Embree's known cracks there, which native and brute force hit") } else { String::new() },
            if open_edges > 0 { format!("; {open_edges} rays at an edge of an open surface, hit by one and passed by the other within f32") } else { String::new() }
        ),
        _ => format!("{wrong} of {total} rays differ; first: {}", details.first().map(String::as_str).unwrap_or("")),
    };
    Check { name: name.into(), status, summary, details, seconds: start.elapsed().as_secs_f64() }
}

/// The geometry checks of `scene`: each Embree this build has, and brute
/// force on a sample, against native.
pub fn run(scene: &Scene, camera: &Camera, budget: Duration) -> Result<Vec<Check>> {
    let start = Instant::now();
    let native = accel::build(BackendKind::Native, &scene.shapes, 0)?.accel;
    // About 2 million ray comparisons a second per backend on 2 cores:
    // the rays per kind that fill the share.
    let others = Major::ALL.iter().filter(|&&m| embree::available(m)).count() + 1;
    let n = ((budget.as_secs_f64() * 2e5 / others as f64) as usize).clamp(256, 16_384);
    let rays = ray_sets(scene, camera, native.as_ref(), n);
    let brute = accel::build(BackendKind::Brute, &scene.shapes, 0)?.accel;
    let mut checks = Vec::new();
    for (major, kind) in [(Major::V3, BackendKind::Embree3), (Major::V4, BackendKind::Embree4)] {
        let name = format!("geometry: {kind} against native");
        if !embree::available(major) {
            checks.push(Check::new(name, Status::Skipped, format!("not in this build or not loadable here: {}", embree::unavailable_reason(major))));
            continue;
        }
        let built = accel::build(kind, &scene.shapes, 0)?;
        checks.push(compare_backends(&name, scene, native.as_ref(), built.accel.as_ref(), &rays, Some(brute.as_ref())));
    }
    // Brute force: every ray on small scenes, a sample on large ones.
    let prims = scene.primitive_count().max(1) as f64;
    let keep = ((BRUTE_TESTS / prims) as usize).max(64);
    let sample: Vec<(&str, Vec<Ray>)> = rays.iter().map(|(k, set)| (*k, set.iter().step_by((set.len() / keep.max(1)).max(1)).take(keep / rays.len() + 1).copied().collect())).collect();
    let mut c = compare_backends("geometry: native against brute force", scene, brute.as_ref(), native.as_ref(), &sample, None);
    let sampled: usize = sample.iter().map(|s| s.1.len()).sum();
    if sampled < rays.iter().map(|s| s.1.len()).sum::<usize>() {
        c.summary = format!("(a sample of {sampled} rays) {}", c.summary);
    }
    checks.push(c);
    let total = start.elapsed().as_secs_f64();
    if total > 2.0 * budget.as_secs_f64() {
        checks.last_mut().unwrap().details.push(format!("the geometry checks took {total:.1} s of a {:.1} s share", budget.as_secs_f64()));
    }
    Ok(checks)
}
