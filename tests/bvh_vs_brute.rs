//! The native BVH against the brute-force oracle on every shipped scene:
//! camera rays plus random rays from inside and outside the bounds.

mod common;

use pathtracer::accel::BackendKind;
use pathtracer::accel::workloads::{camera_rays, random_rays};
use pathtracer::camera::Camera;
use pathtracer::ray::Ray;
use rayon::prelude::*;

#[test]
fn native_bvh_matches_brute_force_on_every_shipped_scene() {
    let mut total = 0usize;
    let mut seen: Vec<u64> = Vec::new();
    for path in common::shipped_scenes() {
        let scene = common::load(&path);
        let native = common::build(BackendKind::Native, &scene.shapes);
        let brute = common::build(BackendKind::Brute, &scene.shapes);
        let camera = Camera::from_scene(&scene);
        let mut rays = camera_rays(&camera, 320, 160);
        rays.extend(random_rays(&scene, 51_200, 7));
        assert!(rays.len() >= 100_000);
        // Scenes that differ only in materials share their geometry and
        // camera: trace each distinct one once (the brute oracle is slow).
        let key = geometry_key(&scene);
        if seen.contains(&key) {
            eprintln!("{}: same geometry and camera as a scene already checked", path.display());
            continue;
        }
        seen.push(key);
        let mismatches: Vec<String> = rays
            .par_iter()
            .enumerate()
            .filter_map(|(i, r)| {
                let (a, b) = (native.intersect(r), brute.intersect(r));
                let same_hit = match (a, b) {
                    (None, None) => true,
                    (Some(a), Some(b)) => {
                        a.geom_id == b.geom_id && a.prim_id == b.prim_id && (a.t - b.t).abs() <= 1e-6 * b.t.abs()
                    }
                    _ => false,
                };
                // Any-hit: the oracle's answer is whether a closest hit exists;
                // and nothing may be found strictly before the closest hit.
                let shortened = b.map(|h| Ray { tmax: h.t * 0.999, ..*r });
                let same_any = native.occluded(r) == b.is_some() && shortened.map_or(true, |s| !native.occluded(&s));
                (!same_hit || !same_any).then(|| format!("ray {i} {r:?}: native {a:?} brute {b:?}"))
            })
            .collect();
        assert!(mismatches.is_empty(), "{}: {} mismatches, first: {}", path.display(), mismatches.len(), mismatches[0]);
        total += rays.len();
    }
    eprintln!("native == brute on {total} rays over {} distinct scenes", seen.len());
}

fn geometry_key(scene: &pathtracer::scene::Scene) -> u64 {
    use pathtracer::scene::Shape;
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for s in &scene.shapes {
        match s {
            Shape::Mesh(m) => {
                m.positions.iter().for_each(|p| p.to_array().map(f32::to_bits).hash(&mut h));
                m.triangles.hash(&mut h);
            }
            Shape::Sphere { center, radius } => (center.to_array().map(f32::to_bits), radius.to_bits()).hash(&mut h),
        }
    }
    scene.camera.c_dir.to_array().map(f32::to_bits).hash(&mut h);
    h.finish()
}
