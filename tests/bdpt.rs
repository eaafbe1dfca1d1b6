//! Bidirectional path tracing and light tracing, against the path tracer
//! (an independent estimator of the same integral: the two share nothing but
//! the BSDFs and lights), against closed forms, and against themselves.
//!
//! Splats make neighbouring pixels' errors correlated (one light subpath
//! lands on many pixels), so the per-pixel variances do not give the
//! variance of a region's mean. Every comparison here therefore renders
//! independent replicates (seeds) and tests the difference of the replicate
//! means with Welch's t: the spread is measured, not modelled. Each test's
//! family of comparisons shares alpha = 0.01 (Šidák), and checks its power
//! (the standard error must resolve a few per cent).

mod common;

use common::{camera_at, diffuse, flat_cube_mesh, lossless_glass, scene_of, sidak, Scratch};
use glam::Vec3;
use pathtracer::accel::BackendKind;
use pathtracer::camera::Camera;
use pathtracer::light::environment::EnvMap;
use pathtracer::light::Lights;
use pathtracer::render::bdpt::{Bdpt, LightPaths, Technique};
use pathtracer::render::path::PathTracer;
use pathtracer::render::{self, Integrator, Region, RenderSettings};
use pathtracer::scene::{LightDesc, LightKind, Scene, Shape};
use statrs::distribution::{ContinuousCDF, StudentsT};
use std::path::Path;
use std::sync::Arc;
use std::process::Command;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Estimator {
    Path,
    Bdpt(Technique),
    /// BDPT with `--bdpt-light-paths specular`.
    BdptSpecular(Technique),
}

/// A render's image (luminance as the channel mean, row 0 at the top).
fn render_image(scene: &Scene, cam: &Camera, backend: BackendKind, est: Estimator, m: u32, accumulate: bool, spp: u32, seed: u64) -> Vec<f64> {
    render_image_env(scene, None, cam, backend, est, m, accumulate, spp, seed)
}

/// `render_image` with an environment map (`-e`) among the lights.
#[allow(clippy::too_many_arguments)]
fn render_image_env(scene: &Scene, env: Option<Arc<EnvMap>>, cam: &Camera, backend: BackendKind, est: Estimator, m: u32, accumulate: bool, spp: u32, seed: u64) -> Vec<f64> {
    let lights = Lights::with_environment(scene, env).unwrap();
    let accel = common::build(backend, &scene.shapes);
    let (w, h) = (cam.screen_w, cam.screen_h);
    let guide = common::guide(scene);
    let integ: Box<dyn Integrator> = match est {
        Estimator::Path => Box::new(PathTracer { scene, lights: &lights, guide: guide.as_ref(), max_depth: m, accumulate, hemisphere: false, light_samples: 1, russian_roulette: true }),
        Estimator::Bdpt(t) => Box::new(Bdpt::new(scene, &lights, cam, w, h, Region { x: 0, y: 0, w, h }, m, accumulate, t).unwrap()),
        Estimator::BdptSpecular(t) => Box::new(Bdpt::new(scene, &lights, cam, w, h, Region { x: 0, y: 0, w, h }, m, accumulate, t).unwrap().with_light_paths(LightPaths::Specular)),
    };
    let out = render::render(cam, accel.as_ref(), integ.as_ref(), &RenderSettings::new(w, h, spp, seed));
    assert!(out.image.pixels.iter().all(|p| p.is_finite()), "{est:?}: a non-finite pixel");
    out.image.pixels.iter().map(|p| (p.x as f64 + p.y as f64 + p.z as f64) / 3.0).collect()
}

/// Per replicate: the image mean and the means of a 4x4 grid of blocks.
fn replicate_means(img: &[f64], w: u32, h: u32) -> Vec<f64> {
    let mut out = vec![img.iter().sum::<f64>() / img.len() as f64];
    let (bw, bh) = (w / 4, h / 4);
    for by in 0..4 {
        for bx in 0..4 {
            let mut s = 0.0;
            for y in by * bh..(by + 1) * bh {
                for x in bx * bw..(bx + 1) * bw {
                    s += img[(y * w + x) as usize];
                }
            }
            out.push(s / (bw * bh) as f64);
        }
    }
    out
}

/// `k` replicates' region means.
#[allow(clippy::too_many_arguments)]
fn replicates(scene: &Scene, cam: &Camera, backend: BackendKind, est: Estimator, m: u32, accumulate: bool, spp: u32, k: u64, seed: u64) -> Vec<Vec<f64>> {
    (0..k).map(|i| replicate_means(&render_image(scene, cam, backend, est, m, accumulate, spp, seed + 1000 * i), cam.screen_w, cam.screen_h)).collect()
}

/// `replicates` (paths of every length up to `m`) with an environment map.
#[allow(clippy::too_many_arguments)]
fn replicates_env(scene: &Scene, env: Option<Arc<EnvMap>>, cam: &Camera, backend: BackendKind, est: Estimator, m: u32, spp: u32, k: u64, seed: u64) -> Vec<Vec<f64>> {
    (0..k).map(|i| replicate_means(&render_image_env(scene, env.clone(), cam, backend, est, m, true, spp, seed + 1000 * i), cam.screen_w, cam.screen_h)).collect()
}

fn mean_var(xs: impl Iterator<Item = f64> + Clone) -> (f64, f64, f64) {
    let n = xs.clone().count() as f64;
    let mean = xs.clone().sum::<f64>() / n;
    let var = xs.map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0);
    (mean, var / n, n)
}

/// Welch's t-test of every region mean (image, then 16 blocks; blocks
/// darker than 2 % of the image are left to the image test) between two
/// sets of replicates, at family-wise `alpha`; `power`: the image's
/// standard error must be below this share of its mean.
fn assert_agree(a: &[Vec<f64>], b: &[Vec<f64>], what: &str, power: f64) {
    let regions = a[0].len();
    let alpha = sidak(0.01, regions);
    let image = a.iter().map(|r| r[0]).sum::<f64>() / a.len() as f64;
    for j in 0..regions {
        let (ma, va, na) = mean_var(a.iter().map(|r| r[j]));
        let (mb, vb, nb) = mean_var(b.iter().map(|r| r[j]));
        if j > 0 && ma < 0.02 * image {
            continue;
        }
        let se = (va + vb).sqrt();
        if se == 0.0 {
            // A region of directly seen sky: every sample the same.
            assert!(ma == mb, "{what}: region {j}: {ma} vs {mb}, both without variance");
            continue;
        }
        if j == 0 {
            assert!(se < power * ma, "{what}: underpowered: image mean {ma:.5} with standard error {se:.5}");
        }
        // Welch–Satterthwaite degrees of freedom.
        let df = (va + vb).powi(2) / (va * va / (na - 1.0) + vb * vb / (nb - 1.0));
        let crit = StudentsT::new(0.0, 1.0, df.max(1.0)).unwrap().inverse_cdf(1.0 - alpha / 2.0);
        let t = (ma - mb) / se;
        let region = if j == 0 { "image".to_string() } else { format!("block {}", j - 1) };
        assert!(t.abs() <= crit, "{what}: {region}: {ma:.5} vs {mb:.5} (se {se:.5}, t {t:.2} > {crit:.2})");
    }
}

/// CS184's Cornell box with two diffuse spheres (the built-in scene), at
/// the 800x600 view scaled down.
fn cornell(w: u32, h: u32) -> (Scene, Camera) {
    let scene = pathtracer::scene::builtin::load().unwrap();
    shrunk(scene, w, h)
}

fn shrunk(scene: Scene, w: u32, h: u32) -> (Scene, Camera) {
    let mut cam = Camera::from_scene(&scene);
    cam.screen_dist *= w as f32 / 800.0;
    cam.set_screen_size(w, h);
    (scene, cam)
}

#[test]
fn bdpt_and_light_tracing_agree_with_the_path_tracer_on_the_cornell_box() {
    let (w, h) = (32, 24);
    let (scene, cam) = cornell(w, h);
    for m in [1u32, 4] {
        let path = replicates(&scene, &cam, BackendKind::Native, Estimator::Path, m, true, 64, 12, 1);
        let bdpt = replicates(&scene, &cam, BackendKind::Native, Estimator::Bdpt(Technique::Bidirectional), m, true, 32, 12, 2);
        assert_agree(&path, &bdpt, &format!("-m {m}: bdpt vs path"), 0.01);
        let light = replicates(&scene, &cam, BackendKind::Native, Estimator::Bdpt(Technique::LightTracing), m, true, 64, 12, 3);
        assert_agree(&path, &light, &format!("-m {m}: light tracing vs path"), 0.02);
        let specular = replicates(&scene, &cam, BackendKind::Native, Estimator::BdptSpecular(Technique::Bidirectional), m, true, 32, 12, 4);
        assert_agree(&path, &specular, &format!("-m {m}: bdpt, specular light paths, vs path"), 0.01);
    }
}

#[test]
fn bdpt_agrees_with_the_path_tracer_on_every_backend() {
    let (w, h) = (32, 24);
    let (scene, cam) = cornell(w, h);
    let path = replicates(&scene, &cam, BackendKind::Native, Estimator::Path, 3, true, 64, 12, 4);
    for backend in common::backends() {
        let bdpt = replicates(&scene, &cam, backend, Estimator::Bdpt(Technique::Bidirectional), 3, true, 32, 12, 5);
        assert_agree(&path, &bdpt, &format!("{backend}: bdpt vs path"), 0.01);
    }
}

/// A shipped scene from scenes/cs184 (missing data fails loudly).
fn shipped(name: &str, w: u32, h: u32) -> (Scene, Camera) {
    shrunk(common::load(&common::scene_path("sky", name)), w, h)
}

#[test]
fn bdpt_agrees_with_the_path_tracer_through_mirror_and_glass() {
    let (w, h) = (32, 24);
    let (scene, cam) = shipped("CBspheres", w, h);
    let path = replicates(&scene, &cam, BackendKind::Native, Estimator::Path, 5, true, 128, 12, 6);
    let bdpt = replicates(&scene, &cam, BackendKind::Native, Estimator::Bdpt(Technique::Bidirectional), 5, true, 64, 12, 7);
    assert_agree(&path, &bdpt, "CBspheres -m 5: bdpt vs path", 0.02);
    let specular = replicates(&scene, &cam, BackendKind::Native, Estimator::BdptSpecular(Technique::Bidirectional), 5, true, 64, 12, 17);
    assert_agree(&path, &specular, "CBspheres -m 5: bdpt, specular light paths, vs path", 0.02);
}

#[test]
fn bdpt_agrees_with_the_path_tracer_on_caustics_through_gems() {
    let (w, h) = (32, 24);
    let (scene, cam) = shipped("CBgems", w, h);
    let path = replicates(&scene, &cam, BackendKind::Native, Estimator::Path, 5, true, 128, 12, 8);
    let bdpt = replicates(&scene, &cam, BackendKind::Native, Estimator::Bdpt(Technique::Bidirectional), 5, true, 64, 12, 9);
    assert_agree(&path, &bdpt, "CBgems -m 5: bdpt vs path", 0.02);
    let specular = replicates(&scene, &cam, BackendKind::Native, Estimator::BdptSpecular(Technique::Bidirectional), 5, true, 64, 12, 19);
    assert_agree(&path, &specular, "CBgems -m 5: bdpt, specular light paths, vs path", 0.02);
}

#[test]
fn bdpt_matches_the_furnace_closed_form() {
    // A closed room whose walls emit Le and reflect rho: radiance
    // Le (1 - rho^(k+1)) / (1 - rho) everywhere at -m k.
    let (le, rho) = (1.0f32, 0.5f32);
    let scene = scene_of(vec![(Shape::Mesh(flat_cube_mesh(1.0, Vec3::ZERO, true)), diffuse("wall", rho, le))], vec![]);
    let mut cam = camera_at(&scene, Vec3::new(0.1, -0.2, 0.3), 16, 16);
    (cam.screen_w, cam.screen_h) = (16, 16);
    let ks = [1u32, 3];
    let alpha = sidak(0.01, 2 * ks.len());
    for k in ks {
        let expect = le as f64 * (1.0 - (rho as f64).powi(k as i32 + 1)) / (1.0 - rho as f64);
        for tech in [Technique::Bidirectional, Technique::LightTracing] {
            let means: Vec<f64> = (0..12).map(|i| {
                let img = render_image(&scene, &cam, BackendKind::Native, Estimator::Bdpt(tech), k, true, 16, 40 + i);
                img.iter().sum::<f64>() / img.len() as f64
            }).collect();
            let (m, v, n) = mean_var(means.iter().copied());
            let se = v.sqrt();
            assert!(se < 0.01 * expect, "{tech:?} -m {k}: underpowered (se {se})");
            let crit = StudentsT::new(0.0, 1.0, n - 1.0).unwrap().inverse_cdf(1.0 - alpha / 2.0);
            assert!((m - expect).abs() <= crit * se, "{tech:?} -m {k}: {m:.5} ± {se:.5} vs {expect:.5}");
        }
    }
}

#[test]
fn weighted_strategies_sum_to_the_full_image_and_each_alone_estimates_it() {
    let (w, h) = (16, 12);
    let (scene, cam) = cornell(w, h);
    assert_eq!(assert_weighted_strategies_sum(&scene, &cam, 2, 77, "Cornell box"), 1 + 3 + 4);
    // The same through mirror and glass, where specular chains change the
    // densities' measure (`vertex`): the weights must still sum to 1.
    let (scene, cam) = shipped("CBspheres", w, h);
    assert_weighted_strategies_sum(&scene, &cam, 4, 78, "CBspheres");
    // With only the light subpaths whose first bounce is specular: the
    // strategy images still decompose the render (that the weights then sum
    // to 1 is the agreement tests' to show: a weight sum that misses the
    // restriction darkens CBgems by a third, t > 100).
    assert_weighted_strategies_sum_with(&scene, &cam, 4, 79, LightPaths::Specular, "CBspheres, specular light paths");
    // Unweighted, each depth-1 strategy alone estimates all of direct light:
    // NEE (1,2), hitting the light (0,3) and light tracing (2,1).
    let (w, h) = (32, 24);
    let (scene, cam) = cornell(w, h);
    let path = replicates(&scene, &cam, BackendKind::Native, Estimator::Path, 1, false, 64, 12, 11);
    for (s, t, spp) in [(1usize, 2usize, 32u32), (0, 3, 256), (2, 1, 64)] {
        let alone = replicates(&scene, &cam, BackendKind::Native, Estimator::Bdpt(Technique::Strategy { s, t, weighted: false }), 1, false, spp, 12, 12 + s as u64);
        assert_agree(&path, &alone, &format!("strategy ({s},{t}) alone vs path -m 1 -o 0"), 0.03);
    }
}

/// Renders every MIS-weighted strategy image of `-m m` with the same seed as
/// the full render and asserts that they sum to it pixel by pixel: every
/// strategy image is made of the same subpaths and connections, so only the
/// rounding of adding them in another order may differ. Returns how many
/// strategies there were.
fn assert_weighted_strategies_sum(scene: &Scene, cam: &Camera, m: u32, seed: u64, label: &str) -> usize {
    assert_weighted_strategies_sum_with(scene, cam, m, seed, LightPaths::All, label)
}

/// `assert_weighted_strategies_sum` with `light_paths`.
fn assert_weighted_strategies_sum_with(scene: &Scene, cam: &Camera, m: u32, seed: u64, light_paths: LightPaths, label: &str) -> usize {
    let bdpt = |t| match light_paths {
        LightPaths::All => Estimator::Bdpt(t),
        LightPaths::Specular => Estimator::BdptSpecular(t),
    };
    let full = render_image(scene, cam, BackendKind::Native, bdpt(Technique::Bidirectional), m, true, 8, seed);
    let mut sum = vec![0.0; full.len()];
    let mut strategies = 0;
    for depth in 0..=m as usize {
        for t in 1..=depth + 2 {
            let s = depth + 2 - t;
            if (s, t) == (1, 1) {
                continue;
            }
            strategies += 1;
            let img = render_image(scene, cam, BackendKind::Native, bdpt(Technique::Strategy { s, t, weighted: true }), m, true, 8, seed);
            for (a, b) in sum.iter_mut().zip(&img) {
                *a += b;
            }
        }
    }
    for (i, (a, b)) in sum.iter().zip(&full).enumerate() {
        assert!((a - b).abs() <= 1e-4 * b.abs().max(1e-3), "{label} pixel {i}: strategies sum to {a}, the full render has {b}");
    }
    strategies
}

fn pathtracer(dir: &Path, args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_pathtracer")).current_dir(dir).args(args).env("CI", "1").output().expect("run pathtracer")
}

#[test]
fn bdpt_renders_are_the_same_at_any_thread_count() {
    let dir = Scratch::new("bdpt", "threads");
    let mut images = Vec::new();
    for (integrator, threads) in [("bdpt", "1"), ("bdpt", "3"), ("light", "1"), ("light", "2")] {
        let exr = format!("{integrator}-{threads}.exr");
        let out = pathtracer(&dir, &["--integrator", integrator, "-m", "4", "-s", "8", "-r", "40", "30", "-t", threads, "-f", "x.png", "--exr", &exr]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        images.push(std::fs::read(dir.join(&exr)).unwrap());
    }
    assert!(images[0] == images[1], "bdpt: -t 1 and -t 3 differ");
    assert!(images[2] == images[3], "light: -t 1 and -t 2 differ");
    assert!(images[0] != images[2]);
}

#[test]
fn what_bdpt_does_not_support_is_refused_by_name() {
    let dir = Scratch::new("bdpt", "refusals");
    for (args, says) in [
        (vec!["--integrator", "bdpt", "-a", "64", "0.05"], "-a"),
        (vec!["--integrator", "light", "--part", "0/2", "--partial", "p.ptp"], "--part"),
        (vec!["--integrator", "bdpt", "--split", "tiles", "--part", "0/2", "--partial", "p.ptp"], "--split tiles"),
        (vec!["--integrator", "bdpt", "-l", "4"], "-l"),
        (vec!["--integrator", "path", "--bdpt-strategy", "1,2"], "--bdpt-strategy"),
        (vec!["--integrator", "bdpt", "--bdpt-strategy", "1,1"], "--bdpt-strategy 1,1"),
        (vec!["--integrator", "light", "--bdpt-light-paths", "specular"], "--bdpt-light-paths"),
    ] {
        let mut a = args.clone();
        a.extend(["-r", "8", "6", "-s", "1"]);
        let out = pathtracer(&dir, &a);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(says) && err.trim().lines().count() == 1, "{args:?}: {err}");
    }
    assert!(!dir.join("p.ptp").exists() && !dir.join("x.png").exists());
}

/// A diffuse floor, a diffuse box on it and a diffuse sphere beside it.
fn yard(lights: Vec<LightDesc>) -> (Scene, Camera) {
    let mut floor = pathtracer::scene::TriangleMesh {
        positions: vec![Vec3::new(-3.0, 0.0, -3.0), Vec3::new(3.0, 0.0, -3.0), Vec3::new(3.0, 0.0, 3.0), Vec3::new(-3.0, 0.0, 3.0)],
        triangles: vec![[0, 2, 1], [0, 3, 2]],
        normals: vec![],
    };
    floor.compute_normals();
    let scene = scene_of(
        vec![
            (Shape::Mesh(floor), diffuse("floor", 0.6, 0.0)),
            (Shape::Mesh(common::flat_cube_mesh(0.5, Vec3::new(-0.6, 0.5, -0.3), false)), diffuse("box", 0.7, 0.0)),
            (Shape::Sphere { center: Vec3::new(0.8, 0.6, 0.2), radius: 0.6 }, diffuse("ball", 0.5, 0.0)),
        ],
        lights,
    );
    let mut cam = camera_at(&scene, Vec3::new(0.0, 1.2, 4.0), 32, 24);
    (cam.screen_w, cam.screen_h) = (32, 24);
    (scene, cam)
}

fn light_desc(kind: LightKind, radiance: f32, transform: glam::Mat4) -> LightDesc {
    LightDesc { name: format!("{kind:?}"), kind, radiance: Vec3::splat(radiance), transform }
}


#[test]
fn lights_at_infinity_agree_with_the_path_tracer() {
    // Each light at infinity alone and the three together: the hemisphere
    // sky (CS184's ambient light), a directional sun, an environment map.
    let sun = glam::Mat4::from_rotation_x(-0.9) * glam::Mat4::from_rotation_y(0.4);
    let cases: [(&str, Vec<LightDesc>, Option<Arc<EnvMap>>); 4] = [
        ("hemisphere", vec![light_desc(LightKind::Ambient, 1.0, glam::Mat4::IDENTITY)], None),
        ("directional", vec![light_desc(LightKind::Directional, 3.0, sun)], None),
        ("environment map", vec![], Some(common::sun_sky(Vec3::new(60.0, 57.0, 45.0)))),
        ("all three", vec![light_desc(LightKind::Ambient, 0.5, glam::Mat4::IDENTITY), light_desc(LightKind::Directional, 2.0, sun)], Some(common::sun_sky(Vec3::new(60.0, 57.0, 45.0)))),
    ];
    for (what, lights, env) in cases {
        let (scene, cam) = yard(lights);
        let path = replicates_env(&scene, env.clone(), &cam, BackendKind::Native, Estimator::Path, 3, 64, 12, 21);
        for (tech, spp) in [(Technique::Bidirectional, 32), (Technique::LightTracing, 64)] {
            let other = replicates_env(&scene, env.clone(), &cam, BackendKind::Native, Estimator::Bdpt(tech), 3, spp, 12, 22);
            assert_agree(&path, &other, &format!("{what}, -m 3: {tech:?} vs path"), 0.03);
        }
    }
}

#[test]
fn a_convex_diffuse_ball_under_a_uniform_sky_reflects_albedo_times_the_sky() {
    // Seen from outside, a convex diffuse object under a uniform
    // environment L reflects rho L at every depth >= 1 (it never sees
    // itself): the centre blocks, all ball, have that mean; the corners
    // see the sky, L.
    let (rho, l) = (0.5f64, 2.0f32);
    let scene = scene_of(vec![(Shape::Sphere { center: Vec3::ZERO, radius: 1.2 }, diffuse("ball", rho as f32, 0.0))], vec![]);
    let mut cam = camera_at(&scene, Vec3::new(0.0, 0.0, 2.5), 16, 16);
    (cam.screen_w, cam.screen_h) = (16, 16);
    let env = Arc::new(EnvMap::from_texels("uniform".into(), 8, 4, vec![Vec3::splat(l); 32]));
    let centre = [1 + 5, 1 + 6, 1 + 9, 1 + 10];
    let alpha = sidak(0.01, 2 * 2 * centre.len());
    for m in [1u32, 3] {
        for (tech, spp) in [(Technique::Bidirectional, 16), (Technique::LightTracing, 512)] {
            let reps = replicates_env(&scene, Some(env.clone()), &cam, BackendKind::Native, Estimator::Bdpt(tech), m, spp, 12, 50);
            for &j in &centre {
                let (mean, v, n) = mean_var(reps.iter().map(|r| r[j]));
                let expect = rho * l as f64;
                let se = v.sqrt();
                assert!(se < 0.03 * expect, "{tech:?} -m {m}: underpowered (se {se})");
                let crit = StudentsT::new(0.0, 1.0, n - 1.0).unwrap().inverse_cdf(1.0 - alpha / 2.0);
                assert!((mean - expect).abs() <= crit * se.max(1e-9), "{tech:?} -m {m}: block {}: {mean:.5} ± {se:.5} vs {expect:.5}", j - 1);
            }
        }
    }
}

#[test]
fn lossless_glass_vanishes_in_a_uniform_environment() {
    // Every path from the camera through lossless glass ends in the
    // environment, with its (η_i/η_t)² factors cancelled, so each pixel is
    // the environment's radiance exactly — with the camera subpaths split at
    // the glass (`subpath::Branch`) as without: the branches' throughputs
    // (each lobe's times its probability) must add up to one. Deep enough
    // (-m 64) that the branches run out and the rest is picked by lobe.
    let l = 1.5f64;
    let env = Arc::new(EnvMap::from_texels("uniform".into(), 8, 4, vec![Vec3::splat(l as f32); 32]));
    for (what, shape) in [("glass sphere", Shape::Sphere { center: Vec3::ZERO, radius: 0.5 }), ("glass box", Shape::Mesh(flat_cube_mesh(0.4, Vec3::ZERO, false)))] {
        let scene = scene_of(vec![(shape, lossless_glass())], vec![]);
        let mut cam = camera_at(&scene, Vec3::new(0.1, 0.2, 1.6), 16, 16);
        (cam.screen_w, cam.screen_h) = (16, 16);
        for est in [Estimator::Bdpt(Technique::Bidirectional), Estimator::BdptSpecular(Technique::Bidirectional)] {
            let img = render_image_env(&scene, Some(env.clone()), &cam, BackendKind::Native, est, 64, true, 4, 3);
            let worst = img.iter().map(|p| ((p - l) / l).abs()).fold(0.0, f64::max);
            assert!(worst < 1e-4, "{what}, {est:?}: a pixel is off by {worst:e} of the environment");
        }
    }
}

#[test]
fn glass_the_camera_sees_follows_both_lobes_instead_of_picking_one() {
    // At -m 1 a glass sphere under a uniform sky shows only its reflection,
    // F(θ) L. The path tracer picks reflection with probability F, so a
    // sample is L or 0; BDPT's camera subpath follows both lobes (the
    // transmission's path is longer than -m 1 and adds nothing), so a
    // sample is F(θ) L and varies only with where it falls in the pixel.
    // Same mean, and per-pixel variance far below the path tracer's
    // F (1 − F) L² / spp.
    let l = 2.0f32;
    let env = Arc::new(EnvMap::from_texels("uniform".into(), 8, 4, vec![Vec3::splat(l); 32]));
    let scene = scene_of(vec![(Shape::Sphere { center: Vec3::ZERO, radius: 1.2 }, lossless_glass())], vec![]);
    let mut cam = camera_at(&scene, Vec3::new(0.0, 0.0, 2.5), 16, 16);
    (cam.screen_w, cam.screen_h) = (16, 16);
    let k = 16;
    let images = |est: Estimator, spp: u32, seed: u64| -> Vec<Vec<f64>> { (0..k).map(|i| render_image_env(&scene, Some(env.clone()), &cam, BackendKind::Native, est, 1, true, spp, seed + i)).collect() };
    let (spp_path, spp_bdpt) = (64, 4);
    let path = images(Estimator::Path, spp_path, 100);
    let bdpt = images(Estimator::Bdpt(Technique::Bidirectional), spp_bdpt, 200);
    // The pixels wholly on the ball: the centre 6×6, their mean per render.
    let centre: Vec<usize> = (5..11).flat_map(|y| (5..11).map(move |x| y * 16 + x)).collect();
    let region = |r: &Vec<f64>| centre.iter().map(|&j| r[j]).sum::<f64>() / centre.len() as f64;
    let (mp, vp, _) = mean_var(path.iter().map(region));
    let (mb, vb, _) = mean_var(bdpt.iter().map(region));
    // Near normal incidence F ≈ 0.034: a reflection is seen.
    assert!(mb > 0.02 * l as f64 && mb < 0.2 * l as f64, "{mb} is not a glass reflection of {l}");
    let se = (vp + vb).sqrt();
    assert!((mp - mb).abs() <= 4.0 * se, "path {mp:.5} vs bdpt {mb:.5} (se {se:.5})");
    // Per-sample variances of a pixel, summed over the centre.
    let per_sample = |imgs: &[Vec<f64>], spp: u32| centre.iter().map(|&j| mean_var(imgs.iter().map(|r| r[j])).1 * (k * spp as u64) as f64).sum::<f64>();
    let (var_path, var_bdpt) = (per_sample(&path, spp_path), per_sample(&bdpt, spp_bdpt));
    assert!(var_path > 0.0 && var_bdpt < 1e-3 * var_path, "BDPT's variance on the ball {var_bdpt:e} is not far below the path tracer's {var_path:e}: a lobe is still picked");
}

#[test]
fn every_shipped_scene_renders_with_bdpt_and_light_tracing_on_every_fast_backend() {
    // All 20 CS184 scenes (mirror, glass, refraction, microfacet, every
    // light kind they use): none refused, no NaN or Inf (`render_image`
    // asserts it), with BDPT in both light-path modes and light tracing.
    let backends: Vec<BackendKind> = common::backends().into_iter().filter(|b| *b != BackendKind::Brute).collect();
    let mut rendered = Vec::new();
    for path in common::shipped_scenes() {
        let (scene, cam) = shrunk(common::load(&path), 40, 30);
        scene.check_materials().unwrap_or_else(|e| panic!("{}: refused: {e}", path.display()));
        for &backend in &backends {
            for est in [Estimator::Bdpt(Technique::Bidirectional), Estimator::BdptSpecular(Technique::Bidirectional), Estimator::Bdpt(Technique::LightTracing)] {
                render_image(&scene, &cam, backend, est, 5, true, 2, 13);
            }
        }
        rendered.push(scene.name);
    }
    assert_eq!(rendered.len(), 20, "{rendered:?}");
    eprintln!("BDPT and light tracing finite on {} scenes with {backends:?}", rendered.len());
}
