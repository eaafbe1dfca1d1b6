//! Batch calls (plain and coherent) give exactly the single-ray answers, on
//! the backends whose batch paths are our own code (Embree's are checked in
//! embree_crosscheck.rs).

mod common;

use pathtracer::accel::{BackendKind, Hit};
use pathtracer::bench::{camera_rays, random_rays, shadow_rays};
use pathtracer::camera::Camera;

#[test]
fn native_batches_equal_single_rays() {
    for (sub, name) in [("sky", "CBbunny"), ("meshedit", "cow"), ("sky", "CBspheres_lambertian")] {
        let scene = common::load(&common::scene_path(sub, name));
        let accel = common::build(BackendKind::Native, &scene.shapes);
        let mut rays = camera_rays(&Camera::from_scene(&scene), 160, 120);
        rays.extend(random_rays(&scene, 20_000, 3));
        let shadows = shadow_rays(&scene, accel.as_ref(), &rays[..19_200]);
        rays.extend(shadows);
        // Invalid rays in the middle of packets must not disturb their neighbours.
        for i in (5..rays.len()).step_by(997) {
            rays[i].dir = glam::Vec3::ZERO;
        }
        rays[1234].origin.y = f32::NAN;
        let single: Vec<Option<Hit>> = rays.iter().map(|r| accel.intersect(r)).collect();
        let single_occ: Vec<bool> = rays.iter().map(|r| accel.occluded(r)).collect();
        let mut hits = vec![None; rays.len()];
        let mut occ = vec![false; rays.len()];
        accel.intersect_coherent(&rays, &mut hits);
        accel.occluded_coherent(&rays, &mut occ);
        let bad_hits = hits.iter().zip(&single).filter(|(a, b)| a != b).count();
        let bad_occ = occ.iter().zip(&single_occ).filter(|(a, b)| a != b).count();
        assert_eq!((bad_hits, bad_occ), (0, 0), "{name}: coherent batches differ from single rays");
        accel.intersect_batch(&rays, &mut hits);
        accel.occluded_batch(&rays, &mut occ);
        assert!(hits == single && occ == single_occ, "{name}: plain batches differ from single rays");
    }
}
