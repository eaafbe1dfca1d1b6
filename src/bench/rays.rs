//! The ray sets the benchmark times, public so that the cross-check tests
//! trace exactly these: camera rays through pixel centres, incoherent
//! random rays, and shadow rays from the camera rays' hits towards one
//! point above the scene.

use crate::accel::{Hit, Traversal};
use crate::camera::Camera;
use crate::ray::Ray;
use crate::rng::Rng;
use crate::scene::Scene;
use glam::Vec3;
use rayon::prelude::*;

/// Camera rays through the pixel centres of a `w x h` frame, scanline order.
pub fn camera_rays(camera: &Camera, w: u32, h: u32) -> Vec<Ray> {
    let mut rays = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            rays.push(camera.generate_ray((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32));
        }
    }
    rays
}

/// Incoherent rays: origins uniform in the scene bounds grown by 10 % on
/// every side (so some start outside), directions uniform on the sphere.
pub fn random_rays(scene: &Scene, n: usize, seed: u64) -> Vec<Ray> {
    let b = scene.bounds();
    let grow = b.extent() * 0.1 + Vec3::splat(1e-3);
    let (lo, size) = (b.min - grow, b.extent() + 2.0 * grow);
    let mut rng = Rng::new(seed, 0xB0B);
    (0..n)
        .map(|_| {
            let o = lo + size * Vec3::new(rng.uniform(), rng.uniform(), rng.uniform());
            let z = 1.0 - 2.0 * rng.uniform();
            let phi = 2.0 * std::f32::consts::PI * rng.uniform();
            let r = (1.0 - z * z).max(0.0).sqrt();
            Ray::new(o, Vec3::new(r * phi.cos(), r * phi.sin(), z))
        })
        .collect()
}

/// Shadow rays from the first hits of `primary` towards a point above the
/// scene's bounding box, stopping just short of it.
pub fn shadow_rays(scene: &Scene, accel: &dyn Traversal, primary: &[Ray]) -> Vec<Ray> {
    let b = scene.bounds();
    let light = Vec3::new(b.center().x, b.max.y - 0.02 * b.extent().y, b.center().z);
    primary
        .par_iter()
        .filter_map(|r| accel.intersect(r).map(|h| (r, h)))
        .map(|(r, h): (&Ray, Hit)| {
            let p = r.at(h.t);
            let d = light - p;
            // Start a hair off the surface so the ray does not re-hit it.
            Ray::with_range(p, d, 1e-4, 1.0 - 1e-4)
        })
        .collect()
}
