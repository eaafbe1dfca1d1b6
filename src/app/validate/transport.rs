//! Two independent estimators of one image must agree: the path tracer
//! against BDPT (every light subpath, every strategy), against light
//! tracing where the scene has no mirror or glass (light tracing cannot see
//! them from the camera), and, with `-a`, the adaptive image against a
//! fixed-rate one. Each estimator renders `REPLICATES` independent images
//! (their own seeds); the frame is cut into a grid of regions, and each
//! region's mean, per channel, is compared by Welch's test on the
//! replicates' means, the family held to `ALPHA` (Šidák). A region where
//! the estimators differ fails the check, and so does a check whose test
//! of the whole image could not have found a difference of
//! `DETECTABLE` of its mean (too little budget: undecided).

use super::stats::{detectable, sidak, welch, Welch};
use super::{Check, Status};
use crate::accel::{self, BackendKind, Traversal};
use crate::app::cli::flags::Flags;
use crate::app::cli::RenderArgs;
use crate::camera::Camera;
use crate::error::Result;
use crate::light::EnvMap;
use crate::render::bdpt::{LightPaths, Technique};
use crate::render::integrator::{BdptOptions, IntegratorSpec, PathOptions};
use crate::render::job::Job;
use crate::render::{RenderOutput, RenderSettings};
use crate::scene::{Scene, Surface};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The checks' frame (the whole view).
pub const WIDTH: u32 = 64;
pub const HEIGHT: u32 = 48;
/// The regions compared: a grid of 4 x 3 over the frame, and the whole.
const GRID: (u32, u32) = (4, 3);
/// Independent renders per estimator.
const REPLICATES: usize = 8;
/// The family-wise false-alarm rate of a check's tests.
const ALPHA: f64 = 0.01;
/// A check must be able to find this relative difference of the whole
/// image's mean with probability `POWER`.
const DETECTABLE: f64 = 0.03;
const POWER: f64 = 0.8;

/// One way of estimating the image: renders it with a seed and a sample
/// count.
pub struct Estimator<'a> {
    pub name: String,
    pub render: Box<dyn Fn(u64, u32) -> RenderOutput + Sync + 'a>,
}

/// The means of each region and channel of an image (`GRID` regions, then
/// the whole frame), `[region][channel]`.
fn region_means(img: &crate::image_io::Rgb) -> Vec<[f64; 3]> {
    let (w, h) = (img.width, img.height);
    let mut out = Vec::new();
    let cell = |x0: u32, x1: u32, y0: u32, y1: u32| {
        let mut s = [0.0f64; 3];
        for y in y0..y1 {
            for x in x0..x1 {
                let p = img.get(x, y);
                s[0] += p.x as f64;
                s[1] += p.y as f64;
                s[2] += p.z as f64;
            }
        }
        let n = ((x1 - x0) * (y1 - y0)).max(1) as f64;
        s.map(|v| v / n)
    };
    for gy in 0..GRID.1 {
        for gx in 0..GRID.0 {
            out.push(cell(gx * w / GRID.0, (gx + 1) * w / GRID.0, gy * h / GRID.1, (gy + 1) * h / GRID.1));
        }
    }
    out.push(cell(0, w, 0, h));
    out
}

/// `a` against `b`, each rendered `REPLICATES` times within `budget`.
pub fn compare_estimators(name: &str, a: &Estimator, b: &Estimator, budget: Duration) -> Check {
    let start = Instant::now();
    // The cost of a sample per pixel of each, from one render of each.
    let t = |e: &Estimator| {
        let s = Instant::now();
        std::hint::black_box((e.render)(0, 1));
        s.elapsed().as_secs_f64()
    };
    let per_spp = t(a) + t(b);
    let left = budget.as_secs_f64() - start.elapsed().as_secs_f64();
    let spp = ((left / (REPLICATES as f64 * per_spp)).floor() as u32).min(4096);
    if spp == 0 {
        let need = REPLICATES as f64 * per_spp + start.elapsed().as_secs_f64();
        return Check { seconds: start.elapsed().as_secs_f64(), ..Check::new(name, Status::Unresolved, format!("the budget's share ({:.1} s) cannot afford one sample per pixel of {REPLICATES} replicates of each (about {need:.1} s): give a larger --budget", budget.as_secs_f64())) };
    }
    let means = |e: &Estimator, base: u64| -> Vec<Vec<[f64; 3]>> { (0..REPLICATES as u64).map(|k| region_means(&(e.render)(base + k, spp).image)).collect() };
    let (ma, mb) = (means(a, 1), means(b, 1001));
    let regions = ma[0].len();
    let level = sidak(ALPHA, regions * 3);
    let mut details = Vec::new();
    let mut failed = Vec::new();
    let mut whole: Option<(Welch, f64)> = None;
    for r in 0..regions {
        for c in 0..3 {
            let xa: Vec<f64> = ma.iter().map(|m| m[r][c]).collect();
            let xb: Vec<f64> = mb.iter().map(|m| m[r][c]).collect();
            let w = welch(&xa, &xb);
            let d = detectable(&w, level, POWER);
            let label = if r + 1 == regions { "whole frame".to_string() } else { format!("region {} of {}x{}", r + 1, GRID.0, GRID.1) };
            let line = format!("{label}, channel {}: {} {:.5} against {} {:.5}, t {:+.2}, p {:.2e}, finds a difference of {:.4}", ["R", "G", "B"][c], a.name, w.mean_a, b.name, w.mean_b, w.t, w.p, d);
            if w.p < level {
                failed.push(line.clone());
            }
            details.push(line);
            if r + 1 == regions && w.mean_a.abs().max(w.mean_b.abs()) > 0.0 {
                let rel = d / w.mean_a.abs().max(w.mean_b.abs());
                if whole.is_none_or(|(_, best)| rel > best) {
                    whole = Some((w, rel));
                }
            }
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    let setting = format!("{REPLICATES} renders of {spp} spp each, {} regions x 3 channels, family-wise alpha {ALPHA}", regions);
    let (status, summary) = if !failed.is_empty() {
        (Status::Fail, format!("{} of {} tests differ ({setting}); first: {}", failed.len(), regions * 3, failed[0]))
    } else {
        match whole {
            None => (Status::Unresolved, format!("the image is black: nothing to compare ({setting})")),
            Some((_, rel)) if rel > DETECTABLE => (Status::Unresolved, format!("no difference found, but the test could only find one of {:.1} % of the image's mean (needs {:.0} %): give a larger --budget ({setting})", 100.0 * rel, 100.0 * DETECTABLE)),
            Some((_, rel)) => (Status::Pass, format!("agree in every region ({setting}; would find a {:.2} % difference of the whole image's mean)", 100.0 * rel)),
        }
    };
    let mut details = details;
    details.splice(0..0, failed);
    Check { name: name.into(), status, summary, details, seconds }
}

/// Whether the scene has a mirror, glass or refracting surface (light
/// tracing cannot see those from the camera).
fn has_specular(scene: &Scene) -> bool {
    scene.materials.iter().any(|m| matches!(m.surface, Surface::Mirror { .. } | Surface::Glass { .. } | Surface::Refraction { .. }))
}

/// An estimator rendering `spec` of the scene with `accel`.
fn estimator<'a>(name: &str, scene: &Scene, camera: &Camera, env: Option<Arc<EnvMap>>, f: &Flags, spec: IntegratorSpec, accel: &'a dyn Traversal, adaptive: bool) -> Result<Estimator<'a>> {
    let job = Job::new(scene.clone(), camera.clone(), env, f.sampling, spec)?;
    let (sampler, adaptive) = (f.sampler, if adaptive { f.adaptive } else { None });
    Ok(Estimator {
        name: name.into(),
        render: Box::new(move |seed, spp| {
            let mut s = RenderSettings::new(WIDTH, HEIGHT, spp, seed);
            s.sampler = sampler;
            s.adaptive = adaptive;
            job.render(accel, &s).expect("a prepared job renders")
        }),
    })
}

/// The transport checks of the scene with the render flags `f`.
pub fn run(scene: &Scene, camera: &Camera, env: Option<Arc<EnvMap>>, f: &Flags, a: &RenderArgs, budget: Duration, adaptive_budget: Duration) -> Result<Vec<Check>> {
    let accel = accel::build(BackendKind::Native, &scene.shapes, 0)?;
    let bounces = f.spec.bounces().unwrap_or(crate::render::integrator::Bounces { max_depth: 5, accumulate: true });
    let path_spec = match f.spec {
        IntegratorSpec::Path(o) => IntegratorSpec::Path(o),
        _ => IntegratorSpec::Path(PathOptions { bounces, light_samples: 1, hemisphere: false, russian_roulette: true, specular_guide: a.specular_guide }),
    };
    let path = estimator("path tracer", scene, camera, env.clone(), f, path_spec, accel.accel.as_ref(), false)?;
    let mut checks = Vec::new();
    let specular = has_specular(scene);
    let pairs = if specular { 1.0 } else { 2.0 };
    let bdpt = estimator("BDPT", scene, camera, env.clone(), f, IntegratorSpec::Bdpt(BdptOptions { bounces, technique: Technique::Bidirectional, light_paths: LightPaths::All }), accel.accel.as_ref(), false)?;
    checks.push(compare_estimators("light transport: path tracer against BDPT", &path, &bdpt, budget.div_f64(pairs)));
    let light_name = "light transport: path tracer against light tracing";
    if specular {
        checks.push(Check::new(light_name, Status::Skipped, "the scene has mirror, glass or refracting surfaces, which light tracing cannot see from the camera"));
    } else {
        let light = estimator("light tracing", scene, camera, env.clone(), f, IntegratorSpec::LightTracing(bounces), accel.accel.as_ref(), false)?;
        checks.push(compare_estimators(light_name, &path, &light, budget.div_f64(pairs)));
    }
    if f.adaptive.is_some() {
        let adaptive = estimator("adaptive", scene, camera, env, f, path_spec, accel.accel.as_ref(), true)?;
        let name = format!("adaptive sampling (-a, {} rule) against fixed-rate sampling", if f.adaptive.is_some_and(|a| a.pilot) { "pilot" } else { "CS184's" });
        let mut c = compare_estimators(&name, &adaptive, &path, adaptive_budget);
        if c.status == Status::Fail && !f.adaptive.is_some_and(|a| a.pilot) {
            c.summary += " (CS184's stopping rule decides on the samples it keeps, which biases it; --adaptive-pilot does not)";
        }
        checks.push(c);
    }
    Ok(checks)
}
