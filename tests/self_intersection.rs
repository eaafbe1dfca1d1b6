//! Spawned rays never re-hit the surface they leave (pbrt-v4's Reintersect
//! test), and shadow rays between two facing surfaces are never falsely
//! occluded (Mitsuba's spawn_ray_to test), at extreme scales and offsets, on
//! every backend.

mod common;

use glam::Vec3;
use pathtracer::ray::Ray;
use pathtracer::rng::Rng;
use pathtracer::sampling::uniform_sphere;
use pathtracer::scene::{CameraDesc, Interaction, Material, Object, Scene, Shape, TriangleMesh};

fn scene_of(shapes: Vec<Shape>) -> Scene {
    let n = shapes.len();
    Scene {
        name: "t".into(),
        source: "<test>".into(),
        shapes,
        objects: (0..n).map(|i| Object { name: format!("s{i}"), material: 0 }).collect(),
        materials: vec![Material::default_diffuse()],
        lights: vec![],
        camera: CameraDesc::default(),
    }
}

/// Log-uniform in 10^[lo, hi], random sign.
fn log_uniform(rng: &mut Rng, lo: f32, hi: f32) -> f32 {
    let x = 10f32.powf(lo + (hi - lo) * rng.uniform());
    if rng.uniform() < 0.5 {
        -x
    } else {
        x
    }
}

fn tri_mesh(v: [Vec3; 3]) -> Shape {
    let mut m = TriangleMesh { positions: v.to_vec(), triangles: vec![[0, 1, 2]], normals: vec![] };
    m.compute_normals();
    Shape::Mesh(m)
}

#[test]
fn spawned_rays_never_rehit_their_own_primitive() {
    let mut rng = Rng::new(77, 1);
    let mut shapes = Vec::new();
    for _ in 0..300 {
        // A random triangle somewhere between 1e-4 and 1e4 from the origin,
        // of a size between 1e-4 and 1e4.
        let c = Vec3::new(log_uniform(&mut rng, -4.0, 4.0), log_uniform(&mut rng, -4.0, 4.0), log_uniform(&mut rng, -4.0, 4.0));
        let size = 10f32.powf(-4.0 + 8.0 * rng.uniform());
        let v = [0, 1, 2].map(|_| c + size * uniform_sphere(rng.uniform(), rng.uniform()));
        shapes.push(tri_mesh(v));
    }
    for _ in 0..100 {
        let c = Vec3::new(log_uniform(&mut rng, -4.0, 4.0), log_uniform(&mut rng, -4.0, 4.0), log_uniform(&mut rng, -4.0, 4.0));
        let r = 10f32.powf(-4.0 + 8.0 * rng.uniform());
        shapes.push(Shape::Sphere { center: c, radius: r });
    }
    let scene = scene_of(shapes);
    for kind in common::backends() {
        if kind == pathtracer::accel::BackendKind::Brute {
            continue; // same primitive tests as native; too slow for no gain here
        }
        let accel = common::build(kind, &scene.shapes);
        let (mut spawned, mut self_hits, mut hits) = (0usize, 0usize, 0usize);
        for (g, shape) in scene.shapes.iter().enumerate() {
            // Aim at a random interior point of the primitive.
            let (target, scale) = match shape {
                Shape::Mesh(m) => {
                    let (u, v) = (0.001 + 0.998 * rng.uniform(), rng.uniform());
                    let (u, v) = (u * (1.0 - v), u * v);
                    let [a, b, c] = [0, 1, 2].map(|i| m.positions[i]);
                    (a * (1.0 - u - v) + b * u + c * v, (b - a).length().max((c - a).length()))
                }
                Shape::Sphere { center, radius } => (*center + *radius * uniform_sphere(rng.uniform(), rng.uniform()), *radius),
            };
            let origin = target + 3.0 * scale * uniform_sphere(rng.uniform(), rng.uniform());
            let ray = Ray::new(origin, target - origin);
            let Some(hit) = accel.intersect(&ray) else { continue };
            if hit.geom_id != g as u32 {
                continue; // another primitive is in the way
            }
            hits += 1;
            let it = Interaction::new(&scene, &ray, &hit);
            for _ in 0..200 {
                let wi = uniform_sphere(rng.uniform(), rng.uniform());
                // Spheres: only directions away from the surface make sense.
                if matches!(shape, Shape::Sphere { .. }) && wi.dot(it.ng) < 0.0 {
                    continue;
                }
                spawned += 1;
                if accel.intersect(&it.spawn_ray(wi)).is_some_and(|h| h.geom_id == g as u32) {
                    self_hits += 1;
                }
            }
        }
        assert!(hits >= 200, "{kind}: only {hits} primitives hit");
        assert_eq!(self_hits, 0, "{kind}: {self_hits} self-hits in {spawned} spawned rays");
        eprintln!("{kind}: 0 self-hits in {spawned} spawned rays from {hits} hit points");
    }
}

#[test]
fn shadow_rays_between_facing_surfaces_are_not_falsely_occluded() {
    for (offset, scale) in [(0.0f32, 1.0f32), (1e3, 1.0), (0.0, 1e-3), (1e4, 1e3), (-3e4, 1e2)] {
        let o = Vec3::new(offset, -offset * 0.5, offset * 0.25);
        // Two parallel quads facing each other, `scale` apart.
        let quad = |y: f32| {
            let p = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)].map(|(x, z)| o + scale * Vec3::new(x, y, z));
            let mut m = TriangleMesh { positions: p.to_vec(), triangles: vec![[0, 1, 2], [0, 2, 3]], normals: vec![] };
            m.compute_normals();
            Shape::Mesh(m)
        };
        let scene = scene_of(vec![quad(0.0), quad(1.0)]);
        let mut rng = Rng::new(3, 4);
        for kind in common::backends() {
            let accel = common::build(kind, &scene.shapes);
            let mut blocked = 0;
            for _ in 0..2000 {
                let a = o + scale * Vec3::new(1.8 * rng.uniform() - 0.9, 2.0, 1.8 * rng.uniform() - 0.9);
                let ray = Ray::new(a, o + scale * Vec3::new(1.8 * rng.uniform() - 0.9, 0.0, 1.8 * rng.uniform() - 0.9) - a);
                let Some(h) = accel.intersect(&ray) else { continue };
                let it = Interaction::new(&scene, &ray, &h);
                // A point on the upper quad, stepped off it towards the lower one.
                let q = o + scale * Vec3::new(1.8 * rng.uniform() - 0.9, 1.0, 1.8 * rng.uniform() - 0.9);
                let target = pathtracer::sampling::offset_ray_origin(q, -Vec3::Y, q.abs().max_element().max(o.abs().max_element() + scale));
                if accel.occluded(&it.spawn_ray_to(target)) {
                    blocked += 1;
                }
            }
            assert_eq!(blocked, 0, "{kind}: {blocked} false occlusions (offset {offset}, scale {scale})");
        }
    }
}

/// Shadow segments much longer than their target's distance from the origin:
/// the target is stepped off the light's quad by a few ulps of its (small)
/// position, while `t` is rounded to a few ulps of 1, so a segment that ended
/// exactly at the target hit the light's own quad at `t == 1.0` for some rays
/// (and differently per backend). `spawn_ray_to` ends short by
/// `SHADOW_EPSILON` of the length; no backend may report such a ray occluded.
#[test]
fn long_shadow_segments_do_not_hit_the_light_they_end_on() {
    // A small quad at the origin facing down (the light), a large one 50
    // below it facing up (the receiver), tilted so rays arrive obliquely.
    let quad = |c: Vec3, s: f32| {
        let p = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)].map(|(x, z)| c + s * Vec3::new(x, 0.02 * x, z));
        let mut m = TriangleMesh { positions: p.to_vec(), triangles: vec![[0, 1, 2], [0, 2, 3]], normals: vec![] };
        m.compute_normals();
        Shape::Mesh(m)
    };
    let scene = scene_of(vec![quad(Vec3::ZERO, 0.05), quad(Vec3::new(0.0, -50.0, 0.0), 60.0)]);
    let mut rng = Rng::new(5, 6);
    for kind in common::backends() {
        let accel = common::build(kind, &scene.shapes);
        let (mut blocked, mut tried) = (0, 0);
        for _ in 0..20000 {
            let a = Vec3::new(100.0 * rng.uniform() - 50.0, 10.0, 100.0 * rng.uniform() - 50.0);
            let ray = Ray::new(a, Vec3::new(100.0 * rng.uniform() - 50.0, -60.0, 100.0 * rng.uniform() - 50.0) - a);
            let Some(h) = accel.intersect(&ray) else { continue };
            let it = Interaction::new(&scene, &ray, &h);
            if it.p.y > -40.0 {
                continue;
            }
            let (x, z) = (0.09 * rng.uniform() - 0.045, 0.09 * rng.uniform() - 0.045);
            let q = Vec3::new(x, 0.02 * x, z);
            let target = pathtracer::sampling::offset_ray_origin(q, -Vec3::Y, q.abs().max_element());
            tried += 1;
            if accel.occluded(&it.spawn_ray_to(target)) {
                blocked += 1;
            }
        }
        assert!(tried > 5000, "{kind}: only {tried} segments");
        assert_eq!(blocked, 0, "{kind}: {blocked} of {tried} segments occluded by the light they end on");
    }
}
