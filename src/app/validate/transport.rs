//! Two independent estimators of one image must agree: the path tracer
//! against BDPT (every light subpath, every strategy), against light
//! tracing where the scene has no mirror or glass (light tracing cannot see
//! them from the camera), and, with `-a`, the adaptive image against a
//! fixed-rate one. Each estimator renders `REPLICATES` independent images
//! (their own seeds); the frame is cut into a grid of regions, and each
//! region's mean, per channel, is compared on the replicates' means by an
//! equivalence test (two one-sided tests, as a confidence interval of the
//! difference by Welch's t, the family held to `ALPHA` by Šidák's
//! correction) against a tolerance of `TOLERANCE` of the region's mean
//! (at least `FLOOR` of the whole frame's, so that a near-black corner is
//! not held to a relative tolerance of nothing):
//! * the interval inside the tolerance: agree;
//! * the interval wholly outside it: the estimators differ, a FAIL;
//! * otherwise: undecided, too little budget to tell.
//!
//! Why a tolerance rather than "no significant difference": two correct
//! estimators agree only to the f32 arithmetic of their rays (offsets off
//! surfaces, a point light's emitted ray started off the light), which a
//! long enough run always finds; a bug — a missing light, a wrong pdf, a
//! wrong MIS weight — moves a region by more than 2 %.

use super::stats::{lone_share, mean_var, sidak, t_quantile, welch};
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
use crate::render::{Adaptive, RenderOutput, RenderSettings};
use crate::sampler::SamplerKind;
use crate::scene::{Scene, Surface};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The checks' frame (the whole view).
pub const WIDTH: u32 = 64;
pub const HEIGHT: u32 = 48;
/// The regions compared: a grid of 4 x 3 over the frame, and the whole.
const GRID: (u32, u32) = (4, 3);
/// Independent renders per estimator.
/// (16 rather than 8: Student's quantile at the family's level falls from
/// about 4.6 to 4.1, which is a fifth fewer samples for the same interval.)
const REPLICATES: usize = 16;
/// The fewest a run stops at when its time is up.
const MIN_REPLICATES: usize = 8;
/// The family-wise false-alarm rate of a check's tests.
const ALPHA: f64 = 0.01;
/// Estimators agree when their regions' means are within this fraction
/// of the region's mean ...
pub const TOLERANCE: f64 = 0.02;
/// ... or of this fraction of the whole frame's mean, where larger.
const FLOOR: f64 = 0.1;
/// Why an optional comparison that cannot decide does not hold the verdict.
const COVERED: &str = "the other comparisons cover what it tests";

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

/// The tests of one comparison: per region and channel, the equivalence
/// test's verdict and its line.
struct Tests {
    differ: Vec<String>,
    undecided: Vec<String>,
    details: Vec<String>,
    /// The widest interval bound, as a fraction of its tolerance.
    widest: f64,
    /// Whether any region has light (a tolerance above 0).
    lit: bool,
    /// The factor on the samples that would bring every interval within
    /// half its tolerance: what decides a test whose difference is well
    /// inside the tolerance (the differences seen are mostly noise).
    needs_half: f64,
    /// The variances of the two sides' replicate means in the test whose
    /// interval is widest against its tolerance: how to share samples.
    bottleneck: (f64, f64),
    /// Where that test's variance is mostly one render's (`lone_share`
    /// above `LONE`): which side, render and region, and the share.
    lone: Option<String>,
}

/// A test whose variance is more than this share one replicate's is said
/// to be held up by a rare bright sample (`stats::lone_share`).
const LONE: f64 = 0.6;

/// Judge the replicates' region means `ma` against `mb`.
fn judge(a: &str, b: &str, ma: &[Vec<[f64; 3]>], mb: &[Vec<[f64; 3]>]) -> Tests {
    let regions = ma[0].len();
    let level = sidak(ALPHA, regions * 3);
    let mut out = Tests { differ: Vec::new(), undecided: Vec::new(), details: Vec::new(), widest: 0.0, lit: false, needs_half: 1.0, bottleneck: (0.0, 0.0), lone: None };
    for r in 0..regions {
        for c in 0..3 {
            let xa: Vec<f64> = ma.iter().map(|m| m[r][c]).collect();
            let xb: Vec<f64> = mb.iter().map(|m| m[r][c]).collect();
            let whole = (ma.iter().chain(mb).map(|m| m[regions - 1][c]).sum::<f64>()) / (ma.len() + mb.len()) as f64;
            let w = welch(&xa, &xb);
            let tol = TOLERANCE * w.mean_a.abs().max(w.mean_b.abs()).max(FLOOR * whole.abs());
            // One-sided at the family's level each way (the two one-sided
            // tests): the interval is the 1 - 2 level one.
            let half = t_quantile(w.df, 1.0 - level) * w.se;
            let d = w.mean_a - w.mean_b;
            let label = if r + 1 == regions { "whole frame".to_string() } else { format!("region {} of {}x{}", r + 1, GRID.0, GRID.1) };
            let line = format!("{label}, channel {}: {a} {:.5} against {b} {:.5}: difference {d:+.2e} ± {half:.2e} (tolerance {tol:.2e}), t {:+.2}, p {:.2e}", ["R", "G", "B"][c], w.mean_a, w.mean_b, w.t, w.p);
            if tol > 0.0 {
                out.lit = true;
                out.widest = out.widest.max((d.abs() + half) / tol);
                let needs = (2.0 * half / tol).powi(2);
                if needs > out.needs_half {
                    out.needs_half = needs;
                    out.bottleneck = (mean_var(&xa).1, mean_var(&xb).1);
                    // The side whose variance dominates, if one render holds most of it.
                    let (side, xs) = if out.bottleneck.0 >= out.bottleneck.1 { (a, &xa) } else { (b, &xb) };
                    let (k, share) = lone_share(xs);
                    out.lone = (share > LONE).then(|| format!("render {} of {} of {side} holds {:.0} % of its variance in {label}, channel {}", k + 1, xs.len(), 100.0 * share, ["R", "G", "B"][c]));
                }
            }
            if tol > 0.0 && d.abs() - half > tol {
                out.differ.push(line.clone());
            } else if d.abs() + half > tol || (tol == 0.0 && half > 0.0) {
                out.undecided.push(line.clone());
            }
            out.details.push(line);
        }
    }
    out
}

/// `a` against `b`, each rendered `REPLICATES` times within `budget`. A
/// pilot of a tenth of the budget first predicts whether the rest can
/// decide; an `optional` check (another comparison covers what it tests)
/// that cannot by far is skipped there, saying what it would need, and so
/// is one the full run leaves undecided (never one that differs).
pub fn compare_estimators(name: &str, a: &Estimator, b: &Estimator, budget: Duration, optional: bool) -> Check {
    let start = Instant::now();
    let total = budget.as_secs_f64();
    // The cost of a sample per pixel of each (all replicates), first from
    // one render of each, then from the pilot's.
    let timed = |e: &Estimator, base: u64, spp: u32| {
        let s = Instant::now();
        let m: Vec<Vec<[f64; 3]>> = (0..REPLICATES as u64).map(|k| region_means(&(e.render)(base + k, spp).image)).collect();
        (m, s.elapsed().as_secs_f64())
    };
    let one = |e: &Estimator| {
        let s = Instant::now();
        std::hint::black_box((e.render)(0, 1));
        REPLICATES as f64 * s.elapsed().as_secs_f64()
    };
    let (mut cost_a, mut cost_b) = (one(a), one(b));
    let cannot = |spp_needed: f64, per_spp: f64, seconds: f64| {
        let need = spp_needed * per_spp + seconds;
        let status = if optional { Status::Skipped } else { Status::Unresolved };
        Check { seconds, ..Check::new(name, status, format!("the budget's share ({total:.1} s) cannot decide it: about {} would (a --budget {:.0} times larger){}", super::seconds(need), (need / total).max(1.0).ceil(), if optional { format!("; {COVERED}") } else { String::new() })) }
    };
    let left = |start: Instant| total - start.elapsed().as_secs_f64();
    let spp = ((left(start) / (cost_a + cost_b)).floor() as u32).min(4096);
    if spp == 0 {
        return cannot(1.0, cost_a + cost_b, start.elapsed().as_secs_f64());
    }
    // The pilot, a tenth of the budget.
    let pilot_spp = (spp / 10).max(1);
    let ((pa, ta), (pb, tb)) = (timed(a, 1_000_001, pilot_spp), timed(b, 2_000_001, pilot_spp));
    let pilot = judge(&a.name, &b.name, &pa, &pb);
    if pilot_spp >= 4 {
        (cost_a, cost_b) = (ta / pilot_spp as f64, tb / pilot_spp as f64);
    }
    let even = (left(start) / (cost_a + cost_b)).max(1.0);
    if optional && pilot.differ.is_empty() && pilot.needs_half > 4.0 * even / pilot_spp as f64 {
        return cannot(pilot.needs_half * pilot_spp as f64, cost_a + cost_b, start.elapsed().as_secs_f64());
    }
    // Samples shared by each side's variance and cost where the pilot's
    // widest interval is (n_a / n_b = sqrt(v_a c_b / (v_b c_a))), within 8x.
    let (va, vb) = pilot.bottleneck;
    let ratio = if va > 0.0 && vb > 0.0 { ((va * cost_b) / (vb * cost_a)).sqrt().clamp(0.125, 8.0) } else { 1.0 };
    let k = left(start) / (cost_a * ratio + cost_b);
    let (spp_a, spp_b) = (((k * ratio).floor() as u32).clamp(1, 4096), (k.floor() as u32).clamp(1, 4096));
    // The replicates in pairs; should the pilot's costs prove low, the
    // pairs stop at the deadline (never below `MIN_REPLICATES`).
    let (mut ma, mut mb) = (Vec::new(), Vec::new());
    let main = Instant::now();
    for k in 0..REPLICATES as u64 {
        let per_pair = main.elapsed().as_secs_f64() / k.max(1) as f64;
        if k as usize >= MIN_REPLICATES && left(start) < per_pair {
            break;
        }
        ma.push(region_means(&(a.render)(1 + k, spp_a).image));
        mb.push(region_means(&(b.render)(1001 + k, spp_b).image));
    }
    let tests = judge(&a.name, &b.name, &ma, &mb);
    let seconds = start.elapsed().as_secs_f64();
    let regions = GRID.0 * GRID.1 + 1;
    let setting = format!("{} renders each, {spp_a} spp of {} and {spp_b} of {}, {regions} regions x 3 channels, tolerance {:.0} %, family-wise alpha {ALPHA}", ma.len(), a.name, b.name, 100.0 * TOLERANCE);
    let (status, summary) = if !tests.differ.is_empty() {
        (Status::Fail, format!("{} of {} tests differ by more than the tolerance ({setting}); first: {}", tests.differ.len(), regions * 3, tests.differ[0]))
    } else if !tests.lit {
        (Status::Unresolved, format!("the image is black: nothing to compare ({setting})"))
    } else if !tests.undecided.is_empty() {
        let mut more = format!("about {:.0} times the samples would (a --budget about {:.0} times larger)", tests.needs_half.ceil(), (tests.needs_half * seconds / total).max(1.0).ceil());
        if let Some(lone) = &tests.lone {
            // A heavy tail: the figure above comes from one render's rare
            // sample, and more samples settle it only slowly.
            more = format!("{lone}: a rare, very bright sample (light that reaches a surface from a point light or a small bright light very close to it is typical), so the interval is as wide as that one sample makes it and more samples narrow it only slowly; {more}");
        }
        if optional {
            // The pilot underestimated it; what it tests is covered by the
            // other comparisons, so it does not hold the verdict.
            let line = format!("{} of {} tests could not tell within the budget's share ({total:.1} s): {more}; {COVERED} ({setting}); first: {}", tests.undecided.len(), regions * 3, tests.undecided[0]);
            let mut details: Vec<String> = tests.undecided;
            details.extend(tests.details);
            return Check { name: name.into(), status: Status::Skipped, summary: line, details, seconds };
        }
        (Status::Unresolved, format!("{} of {} tests could not tell, their interval reaching past the tolerance: {more} ({setting}); first: {}", tests.undecided.len(), regions * 3, tests.undecided[0]))
    } else {
        (Status::Pass, format!("agree in every region ({setting}; the widest interval reaches {:.0} % of its tolerance)", 100.0 * tests.widest))
    };
    let mut details: Vec<String> = tests.differ.into_iter().chain(tests.undecided).collect();
    details.extend(tests.details);
    Check { name: name.into(), status, summary, details, seconds }
}

/// Whether the scene has a mirror, glass or refracting surface (light
/// tracing cannot see those from the camera).
fn has_specular(scene: &Scene) -> bool {
    scene.materials.iter().any(|m| matches!(m.surface, Surface::Mirror { .. } | Surface::Glass { .. } | Surface::Refraction { .. }))
}

/// An estimator: `job` rendered with `accel` at the checks' frame size,
/// with `sampler` and, for the adaptive image, `adaptive`.
pub fn estimator<'a>(name: &str, job: Job, sampler: SamplerKind, adaptive: Option<Adaptive>, accel: &'a dyn Traversal) -> Estimator<'a> {
    Estimator {
        name: name.into(),
        render: Box::new(move |seed, spp| {
            let mut s = RenderSettings::new(WIDTH, HEIGHT, spp, seed);
            // Every estimator estimates the pixels' averages, at any count.
            s.centre_single_sample = false;
            s.sampler = sampler;
            s.adaptive = adaptive;
            job.render(accel, &s).expect("a prepared job renders")
        }),
    }
}

/// The transport checks of the scene with the render flags `f`.
pub fn run(scene: &Scene, camera: &Camera, env: Option<Arc<EnvMap>>, f: &Flags, a: &RenderArgs, budget: Duration, adaptive_budget: Duration) -> Result<Vec<Check>> {
    let accel = accel::build(BackendKind::Native, &scene.shapes, 0)?;
    let bounces = f.spec.bounces().unwrap_or(crate::render::integrator::Bounces { max_depth: 5, accumulate: true });
    let path_spec = match f.spec {
        IntegratorSpec::Path(o) => IntegratorSpec::Path(o),
        _ => IntegratorSpec::Path(PathOptions { bounces, light_samples: 1, hemisphere: false, russian_roulette: true, specular_guide: a.specular_guide }),
    };
    let native = accel.accel.as_ref();
    let job = |spec: IntegratorSpec| Job::new(scene.clone(), camera.clone(), env.clone(), f.sampling, spec);
    let path_job = job(path_spec)?;
    if path_job.lights.lights.is_empty() {
        // Every estimator renders black: nothing to compare, said at once.
        let why = "the scene has no light (no lamp, no emissive surface, no -e map): every estimator renders it black; give it a light (an unlit scene is meant for -e MAP.exr)";
        return Ok(vec![Check::new("light transport", Status::Unresolved, why)]);
    }
    let path = estimator("path tracer", path_job, f.sampler, None, native);
    let start = Instant::now();
    let specular = has_specular(scene);
    // Light tracing first, on 35 % of the share where it runs (it is often
    // too noisy to decide, and then stops after its pilot); BDPT gets what
    // is left.
    let light_name = "light transport: path tracer against light tracing";
    let light_check = if specular {
        Check::new(light_name, Status::Skipped, "the scene has mirror, glass or refracting surfaces, which light tracing cannot see from the camera")
    } else {
        let light = estimator("light tracing", job(IntegratorSpec::LightTracing(bounces))?, f.sampler, None, native);
        compare_estimators(light_name, &path, &light, budget.mul_f64(0.35), true)
    };
    let bdpt = estimator("BDPT", job(IntegratorSpec::Bdpt(BdptOptions { bounces, technique: Technique::Bidirectional, light_paths: LightPaths::All, unseen_light_caustics: false }))?, f.sampler, None, native);
    let left = budget.saturating_sub(start.elapsed());
    let mut checks = vec![compare_estimators("light transport: path tracer against BDPT", &path, &bdpt, left, false), light_check];
    if f.adaptive.is_some() {
        let adaptive = estimator("adaptive", job(path_spec)?, f.sampler, f.adaptive, native);
        let name = format!("adaptive sampling (-a, {} rule) against fixed-rate sampling", if f.adaptive.is_some_and(|a| a.pilot) { "pilot" } else { "CS184's" });
        let mut c = compare_estimators(&name, &adaptive, &path, adaptive_budget, false);
        if c.status == Status::Fail && !f.adaptive.is_some_and(|a| a.pilot) {
            c.summary += " (CS184's stopping rule decides on the samples it keeps, which biases it; --adaptive-pilot does not)";
        }
        checks.push(c);
    }
    Ok(checks)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn replicates(n: usize, phase: f64) -> Vec<Vec<[f64; 3]>> {
        let regions = (GRID.0 * GRID.1 + 1) as usize;
        (0..n).map(|k| (0..regions).map(|r| [0, 1, 2].map(|c| 1.0 + 1e-3 * ((k * 7 + r * 3 + c) as f64 + phase).sin())).collect()).collect()
    }

    /// One render's rare bright sample leaves the test undecided, and the
    /// verdict says which render holds the variance; without it, none is named.
    #[test]
    fn a_lone_bright_render_is_named() {
        let (a, mut b) = (replicates(15, 0.0), replicates(15, 0.5));
        let calm = judge("path tracer", "BDPT", &a, &b);
        assert!(calm.differ.is_empty() && calm.undecided.is_empty() && calm.lone.is_none(), "{:?} {:?}", calm.undecided, calm.lone);
        b[9][3][0] += 0.5;
        let t = judge("path tracer", "BDPT", &a, &b);
        assert!(t.differ.is_empty() && !t.undecided.is_empty(), "{:?}", t.details);
        let lone = t.lone.expect("the bright render is named");
        assert!(lone.contains("render 10 of 15 of BDPT") && lone.contains("region 4 of 4x3, channel R"), "{lone}");
    }

    /// A budget that affords one sample a pixel still compares like with
    /// like: the estimators' one-sample renders estimate the pixels'
    /// averages, as their many-sample renders do. CBempty's point light,
    /// 1 cm under its ceiling, makes a bright spot that the pixels' centres
    /// (the CLI's `-s 1`) sample far from its average: those renders read
    /// the frame about 9 % brighter, which the checks took for a bug.
    #[test]
    fn one_sample_a_pixel_estimates_the_pixels_averages() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cs184/sky/CBempty.dae");
        let scene = crate::scene::load_file(&path).expect("CBempty loads");
        let mut camera = Camera::from_scene(&scene);
        camera.resize_keep_fov(WIDTH, HEIGHT);
        let accel = accel::build(BackendKind::Native, &scene.shapes, 0).unwrap();
        let bounces = crate::render::integrator::Bounces { max_depth: 5, accumulate: true };
        let spec = IntegratorSpec::Path(PathOptions { bounces, light_samples: 1, hemisphere: false, russian_roulette: true, specular_guide: 0.0 });
        let job = || Job::new(scene.clone(), camera.clone(), None, Default::default(), spec).unwrap();
        let native = accel.accel.as_ref();
        let means = |e: &Estimator, base: u64, spp: u32| (0..REPLICATES as u64).map(|k| region_means(&(e.render)(base + k, spp).image)).collect::<Vec<_>>();
        let estimator = estimator("path tracer", job(), SamplerKind::Sobol, None, native);
        let many = means(&estimator, 101, 8);
        let one = judge("one sample", "eight samples", &means(&estimator, 1, 1), &many);
        assert!(one.differ.is_empty(), "{:?}", one.differ);
        // The pixels' centres, as the CLI traces one sample: the test tells them apart.
        let centre_job = job();
        let centres = Estimator {
            name: "pixel centres".into(),
            render: Box::new(move |seed, spp| centre_job.render(native, &RenderSettings::new(WIDTH, HEIGHT, spp, seed)).unwrap()),
        };
        let centred = judge("pixel centres", "eight samples", &means(&centres, 1, 1), &many);
        assert!(centred.differ.iter().any(|l| l.starts_with("whole frame")), "{:?}", centred.details);
    }
}
