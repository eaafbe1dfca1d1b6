//! Batch calls (plain and coherent) give exactly the single-ray answers, on
//! the backends whose batch paths are our own code (Embree's are checked in
//! embree_crosscheck.rs).

mod common;

use pathtracer::accel::{BackendKind, Hit};
use pathtracer::accel::workloads::{camera_rays, random_rays, shadow_rays};
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

/// The renderer's batched path (camera rays per tile round, then every
/// bounce's shadow and continuation rays as batches) gives the same image,
/// bit for bit, and the same ray count as tracing every ray on its own, in
/// every mode of the path tracer.
#[test]
fn batched_rendering_equals_ray_at_a_time() {
    use pathtracer::light::Lights;
    use pathtracer::render::{self, path::PathTracer, Adaptive, RenderSettings};
    // (scene, max depth, accumulate, hemisphere, light samples, roulette, adaptive)
    let cases = [
        ("CBspheres_lambertian", 5, true, false, 1, true, false),
        ("CBspheres_lambertian", 3, true, true, 1, false, false),
        ("CBspheres_lambertian", 3, false, false, 4, false, false),
        ("CBspheres_lambertian", 0, true, false, 1, false, false),
        ("CBempty", 2, true, false, 2, true, true),
        ("bunny", 3, true, false, 1, true, false),
        ("bunny", 2, true, true, 1, false, false),
    ];
    for (name, m, accumulate, hemisphere, light_samples, russian_roulette, adaptive) in cases {
        let scene = common::load(&common::scene_path("sky", name));
        let accel = common::build(BackendKind::Native, &scene.shapes);
        let lights = Lights::from_scene(&scene).unwrap();
        let guide = common::guide(&scene);
        let integ = PathTracer { scene: &scene, lights: &lights, guide: guide.as_ref(), max_depth: m, accumulate, hemisphere, light_samples, russian_roulette };
        let camera = Camera::from_scene(&scene);
        let mut settings = RenderSettings::new(96, 72, 8, 7);
        if adaptive {
            settings.adaptive = Some(Adaptive { batch: 4, tolerance: 0.2, pilot: false });
        }
        settings.batch_rays = true;
        let batched = render::render(&camera, accel.as_ref(), &integ, &settings);
        settings.batch_rays = false;
        let single = render::render(&camera, accel.as_ref(), &integ, &settings);
        let what = format!("{name} -m {m} accumulate={accumulate} -H={hemisphere} -l {light_samples} rr={russian_roulette} adaptive={adaptive}");
        assert!(batched.image.pixels.iter().any(|p| *p != glam::Vec3::ZERO), "{what}: black image");
        let differ = batched.image.pixels.iter().zip(&single.image.pixels).filter(|(a, b)| a.to_array().map(f32::to_bits) != b.to_array().map(f32::to_bits)).count();
        assert_eq!(differ, 0, "{what}: {differ} pixels differ between batched and ray-at-a-time rendering");
        assert_eq!(batched.samples, single.samples, "{what}: sample counts differ");
        assert_eq!(batched.rays, single.rays, "{what}: ray counts differ");
    }
}

/// Backends that claim `exact_barycentrics` (native, brute) return hits
/// whose barycentrics describing the hit would recompute bit for bit, so
/// the renderer may skip the recomputation and still render the image every
/// backend renders.
#[test]
fn exact_barycentrics_claims_hold() {
    use pathtracer::scene::interaction::Interaction;
    for (sub, name) in [("sky", "CBbunny"), ("meshedit", "cow"), ("sky", "CBspheres_lambertian")] {
        let scene = common::load(&common::scene_path(sub, name));
        let mut rays = camera_rays(&Camera::from_scene(&scene), 80, 60);
        rays.extend(random_rays(&scene, 5_000, 9));
        for kind in [BackendKind::Native, BackendKind::Brute] {
            let accel = common::build(kind, &scene.shapes);
            assert!(accel.exact_barycentrics(), "{kind}: expected to claim exact barycentrics");
            let mut checked = 0;
            for r in &rays {
                let Some(h) = accel.intersect(r) else { continue };
                let (a, b) = (Interaction::new(&scene, r, &h), Interaction::with_barycentrics(&scene, r, &h, true));
                let bits = |i: &Interaction| [i.p, i.ng, i.ns].map(|v| v.to_array().map(f32::to_bits));
                assert_eq!(bits(&a), bits(&b), "{name} {kind}: trusting the hit's barycentrics changes the interaction");
                checked += 1;
            }
            assert!(checked > 2000, "{name} {kind}: only {checked} hits");
        }
    }
}
