//! `pathtracer validate SCENE`: the validation harness as a user's own check
//! of any scene the renderer reads, with one verdict a CI system reads.
//!
//! Checks, each a line of the verdict:
//! * **geometry** (`geometry`): every backend of this build finds the same
//!   hits as native — ids, t within the backend contract's tolerance,
//!   normals — on camera rays, random rays and hard rays made from the
//!   scene (grazing along its edges, leaving its surfaces, through its
//!   vertices); brute force on a sample where the scene is large;
//! * **light transport** (`transport`): two independent estimators of the
//!   same image — the path tracer against BDPT, and against light tracing
//!   where the scene has no mirror or glass — compared region by region on
//!   independent replicate renders: an equivalence test per region and
//!   channel (Welch's interval of the difference, Šidák-corrected, against
//!   a tolerance of 2 % of the region’s mean), which passes only when the
//!   interval lies inside the tolerance and fails only when it lies wholly
//!   outside — too little budget to tell either way is undecided;
//! * **adaptive sampling**, with `-a`: the adaptive image against a
//!   fixed-rate one, the same way;
//! * **references** (`references`): each reference renderer of the
//!   repository's harness (Mitsuba 3, Cycles, POV-Ray) on the exported scene,
//!   through `validation/run_cases.py`; skipped with the exporter's reason
//!   where it cannot represent the scene exactly, or with what to install.
//!
//! `--budget` bounds the wall time, shared among the checks; a check that
//! cannot reach its power in its share says so. Exit status: 0 every check
//! passed (or was skipped for a stated reason), 1 a check failed, 2 a check
//! could not be decided (or the scene could not be loaded). `--report DIR`
//! writes `summary.json`, `junit.xml` and `report.html`.

mod geometry;
mod references;
mod report;
mod stats;
mod transport;

use super::cli::flags::check_flags;
use super::cli::render::{load_environment, load_scene, setup_camera};
use super::cli::ValidateArgs;
use crate::error::{Error, Result};
use std::time::{Duration, Instant};

pub use geometry::{compare_backends, ray_sets};
pub use report::junit;
pub use transport::{compare_estimators, estimator, Estimator};

/// What a check concluded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    Pass,
    Fail,
    /// Not run, for a stated reason that is not a fault (a reference that
    /// cannot represent the scene, a renderer not installed here).
    Skipped,
    /// Could not be decided: too little budget for the power it needs, a
    /// reference that crashed.
    Unresolved,
}

impl Status {
    pub fn word(self) -> &'static str {
        match self {
            Status::Pass => "PASS",
            Status::Fail => "FAIL",
            Status::Skipped => "SKIP",
            Status::Unresolved => "UNRESOLVED",
        }
    }
}

/// One check's verdict.
#[derive(Clone, Debug)]
pub struct Check {
    pub name: String,
    pub status: Status,
    /// One line: what was compared and what it found.
    pub summary: String,
    /// The evidence: each failure, each region's test.
    pub details: Vec<String>,
    pub seconds: f64,
}

impl Check {
    pub fn new(name: impl Into<String>, status: Status, summary: impl Into<String>) -> Check {
        Check { name: name.into(), status, summary: summary.into(), details: Vec::new(), seconds: 0.0 }
    }
}

/// `90s`, `5m`, `1h`, or plain seconds.
fn parse_budget(text: &str) -> Result<Duration> {
    let t = text.trim();
    let (num, unit) = match t.char_indices().find(|(_, c)| c.is_ascii_alphabetic()) {
        Some((i, _)) => (&t[..i], &t[i..]),
        None => (t, "s"),
    };
    let scale = match unit {
        "s" => 1.0,
        "m" | "min" => 60.0,
        "h" => 3600.0,
        _ => crate::bail!("--budget {text}: expected a time such as 90s, 5m or 1h"),
    };
    match num.trim().parse::<f64>() {
        Ok(v) if v > 0.0 && v.is_finite() && v * scale <= 86_400.0 => Ok(Duration::from_secs_f64(v * scale)),
        _ => crate::bail!("--budget {text}: expected a time such as 90s, 5m or 1h (at most a day)"),
    }
}

/// The budget's weight for each part: geometry, transport (shared by its
/// comparisons), adaptive sampling, references. A part that does not run
/// (no `-a`, no reference to render) leaves its weight to the others.
const SHARES: [(&str, f64); 4] = [("geometry", 0.15), ("transport", 0.45), ("adaptive", 0.1), ("references", 0.3)];

fn share(budget: Duration, part: &str, running: &[&str]) -> Duration {
    let weight = |p: &str| SHARES.iter().find(|(q, _)| *q == p).map_or(0.0, |s| s.1);
    let total: f64 = running.iter().map(|p| weight(p)).sum();
    if running.contains(&part) && total > 0.0 {
        budget.mul_f64(weight(part) / total)
    } else {
        Duration::ZERO
    }
}

pub fn run(args: &ValidateArgs) -> Result<()> {
    let budget = match &args.budget {
        Some(b) => parse_budget(b).map_err(Error::into_usage)?,
        None => Duration::from_secs(120),
    };
    let a = &args.render;
    let Some(path) = a.scene.as_deref() else {
        return Err(Error::usage("validate: name the scene to check (pathtracer validate SCENE)"));
    };
    // Anything that stops the checks from running is exit status 2.
    let f = check_flags(a).map_err(Error::into_usage)?;
    let scene = load_scene(Some(path)).map_err(Error::into_usage)?;
    let mut camera = setup_camera(a, &scene, f.width, f.height, f.lens).map_err(Error::into_usage)?;
    let env = load_environment(a).map_err(Error::into_usage)?;
    // The checks' frame: the whole view, small.
    camera.resize_keep_fov(transport::WIDTH, transport::HEIGHT);
    let start = Instant::now();
    let mut running = vec!["geometry", "transport"];
    if f.adaptive.is_some() {
        running.push("adaptive");
    }
    if references::will_render(&args.references) {
        running.push("references");
    }
    // Each part may spend its share and whatever the parts before it left:
    // it runs until the sum of the shares so far.
    let part = |p: &str| share(budget, p, &running);
    let left = |until: Duration| until.saturating_sub(start.elapsed());
    let mut checks = Vec::new();
    checks.extend(geometry::run(&scene, &camera, left(part("geometry")))?);
    let transport = left(part("geometry") + part("transport"));
    checks.extend(transport::run(&scene, &camera, env.clone(), &f, a, transport, part("adaptive"))?);
    let references = left(part("geometry") + part("transport") + part("adaptive") + part("references"));
    checks.extend(references::run(path, a, &args.references, references, args.report.as_deref()));
    for c in &checks {
        println!("{:<10} {}: {}", c.status.word(), c.name, c.summary);
    }
    let count = |s: Status| checks.iter().filter(|c| c.status == s).count();
    let (passed, failed, skipped, unresolved) = (count(Status::Pass), count(Status::Fail), count(Status::Skipped), count(Status::Unresolved));
    let took = start.elapsed().as_secs_f64();
    println!(
        "{} | {} checks: {passed} passed, {failed} failed, {unresolved} undecided, {skipped} skipped | {took:.1} s of a {} budget",
        scene.name,
        checks.len(),
        seconds(budget.as_secs_f64())
    );
    if let Some(dir) = &args.report {
        report::write(dir, &scene.name, &checks, took)?;
    }
    if failed > 0 {
        crate::bail!("validate: {failed} of {} checks failed on {}", checks.len(), path.display());
    }
    if unresolved > 0 {
        return Err(Error::usage(format!("validate: {unresolved} of {} checks could not be decided on {} (see their lines)", checks.len(), path.display())));
    }
    Ok(())
}

/// A time as the checks' lines write it: whole seconds, or tenths below 10 s
/// (a 0.5 s budget is not "0 s").
fn seconds(s: f64) -> String {
    if s < 10.0 {
        format!("{s:.1} s")
    } else {
        format!("{s:.0} s")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn budgets_parse_and_bad_ones_are_refused() {
        assert_eq!(parse_budget("90s").unwrap(), Duration::from_secs(90));
        assert_eq!(parse_budget("5m").unwrap(), Duration::from_secs(300));
        assert_eq!(parse_budget("1h").unwrap(), Duration::from_secs(3600));
        assert_eq!(parse_budget("2.5").unwrap(), Duration::from_secs_f64(2.5));
        for bad in ["", "-1s", "fast", "5y", "0m", "2d"] {
            assert!(parse_budget(bad).is_err(), "{bad}");
        }
        assert!((SHARES.iter().map(|s| s.1).sum::<f64>() - 1.0).abs() < 1e-12);
        // Parts that do not run leave their share to the others.
        let b = Duration::from_secs(100);
        let all = ["geometry", "transport", "adaptive", "references"];
        assert!((share(b, "transport", &all).as_secs_f64() - 45.0).abs() < 1e-9);
        assert!((share(b, "transport", &["geometry", "transport"]).as_secs_f64() - 75.0).abs() < 1e-9);
        assert_eq!(share(b, "adaptive", &["geometry", "transport"]), Duration::ZERO);
    }
}
