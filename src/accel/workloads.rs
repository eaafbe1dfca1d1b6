//! Ray workloads for the traversals: the sets the benchmark times and the
//! cross-check tests trace — camera rays through pixel centres, incoherent
//! random rays, shadow rays from the camera rays' hits towards one point
//! above the scene, and diffuse rays leaving those hits in
//! cosine-distributed directions (the rays a path tracer traces most).

use crate::accel::{Hit, Traversal};
use crate::camera::Camera;
use crate::geometry::Aabb;
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
    random_rays_in(&scene.bounds(), n, seed)
}

/// `random_rays` about the box `b`.
pub fn random_rays_in(b: &Aabb, n: usize, seed: u64) -> Vec<Ray> {
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

/// The rays of a `w x h` scanline-ordered frame (`camera_rays`) reordered
/// tile by tile, `tile x tile` pixels each (scanlines inside a tile, tiles
/// in scanline order): the order a path tracer's batches come in.
pub fn tile_order(rays: &[Ray], w: u32, h: u32, tile: u32) -> Vec<Ray> {
    assert_eq!(rays.len(), (w * h) as usize);
    let mut out = Vec::with_capacity(rays.len());
    for ty in (0..h).step_by(tile as usize) {
        for tx in (0..w).step_by(tile as usize) {
            for y in ty..(ty + tile).min(h) {
                for x in tx..(tx + tile).min(w) {
                    out.push(rays[(y * w + x) as usize]);
                }
            }
        }
    }
    out
}

/// Diffuse bounce rays: from the first hits of `primary`, in their order
/// (given in tile order, neighbouring rays leave neighbouring points, as a
/// path tracer's batch of a tile's bounce rays does), each in a cosine-distributed
/// direction about the geometric normal on the side the camera ray came
/// from, its origin stepped off the surface as the renderer's are
/// (`Interaction::spawn_ray`). Fixed seed: the same rays every run.
pub fn diffuse_rays(scene: &Scene, accel: &dyn Traversal, primary: &[Ray], seed: u64) -> Vec<Ray> {
    use crate::sampling::{cosine_hemisphere, Frame};
    use crate::scene::Interaction;
    let hits: Vec<(usize, Hit)> = primary.par_iter().enumerate().filter_map(|(i, r)| accel.intersect(r).map(|h| (i, h))).collect();
    hits.par_iter()
        .map(|&(i, h)| {
            let r = &primary[i];
            let it = Interaction::new(scene, r, &h);
            let n = if it.ng.dot(r.dir) < 0.0 { it.ng } else { -it.ng };
            let mut rng = Rng::new(seed, i as u64);
            let local = cosine_hemisphere(rng.uniform(), rng.uniform());
            it.spawn_ray(Frame::new(n).to_world(local))
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
