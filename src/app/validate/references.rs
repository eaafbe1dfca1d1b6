//! The reference renderers on the user's scene, through the repository's
//! harness (`validation/run_cases.py --scene`, its quick tier's sizes):
//! the scene exported from our loader, rendered by each reference that can
//! represent it exactly (Mitsuba 3, Blender Cycles, POV-Ray), and judged by
//! the harness's tests. A reference that cannot represent the scene is
//! skipped with its exporter's reason; without the harness, or with it not
//! installed, every reference is skipped with what to do.

use super::{Check, Status};
use crate::app::cli::RenderArgs;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

const ALL: [&str; 3] = ["mitsuba", "cycles", "povray"];

/// The harness's folder, when the command runs from the repository root.
fn harness() -> Option<PathBuf> {
    let d = PathBuf::from("validation");
    d.join("run_cases.py").is_file().then_some(d)
}

/// The scene-changing flags the export must see too.
fn scene_flags(a: &RenderArgs) -> Vec<String> {
    let mut v = Vec::new();
    if let Some(e) = &a.environment {
        v.extend(["-e".to_string(), e.display().to_string()]);
    }
    if let Some(b) = &a.lens_radius {
        v.extend(["-b".to_string(), b.clone()]);
    }
    if let Some(d) = &a.focal_distance {
        v.extend(["-d".to_string(), d.clone()]);
    }
    v
}

/// The references asked for: every one by default, none for `none`.
fn asked_for(asked: &[String]) -> Vec<String> {
    if asked.is_empty() {
        ALL.iter().map(|s| s.to_string()).collect()
    } else {
        asked.iter().filter(|r| r.as_str() != "none").cloned().collect()
    }
}

/// Whether `run` will render anything (a reference asked for, the harness
/// here and installed): the budget's share for references is spent on the
/// other checks otherwise.
pub fn will_render(asked: &[String]) -> bool {
    !asked_for(asked).is_empty() && harness().is_some_and(|d| d.join(".venv/bin/python").is_file())
}

pub fn run(scene: &Path, a: &RenderArgs, asked: &[String], budget: Duration, report: Option<&Path>) -> Vec<Check> {
    let refs = asked_for(asked);
    if refs.is_empty() {
        return Vec::new();
    }
    if let Some(bad) = refs.iter().find(|r| !ALL.contains(&r.as_str())) {
        return vec![Check::new(format!("references: {bad}"), Status::Unresolved, format!("no reference renderer '{bad}': expected {}", ALL.join(", ")))];
    }
    let skip_all = |why: &str| refs.iter().map(|r| Check::new(format!("reference: {r}"), Status::Skipped, why.to_string())).collect::<Vec<_>>();
    let Some(dir) = harness() else {
        return skip_all("the reference renderers run through the repository's harness: run pathtracer validate from the repository's root, after validation/setup");
    };
    let python = dir.join(".venv/bin/python");
    if !python.is_file() {
        return skip_all("the harness is not installed here: run validation/setup (Blender, POV-Ray, Mitsuba 3)");
    }
    let missing: Vec<&str> = [("cycles", "blender"), ("povray", "povray")].into_iter().filter(|(r, tool)| refs.iter().any(|x| x == r) && Command::new("which").arg(tool).output().map_or(true, |o| !o.status.success())).map(|(r, _)| r).collect();
    let start = Instant::now();
    let out = match report {
        Some(r) => r.join("harness"),
        None => std::env::temp_dir().join(format!("pathtracer-validate-{}", std::process::id())),
    };
    let exe = std::env::current_exe().map(|p| p.display().to_string()).unwrap_or_else(|_| "pathtracer".into());
    let m = a.max_depth.unwrap_or(5);
    let run_refs: Vec<&String> = refs.iter().filter(|r| !missing.contains(&r.as_str())).collect();
    let mut checks: Vec<Check> = missing.iter().map(|r| Check::new(format!("reference: {r}"), Status::Skipped, "its renderer is not installed here: run validation/setup")).collect();
    if run_refs.is_empty() {
        return checks;
    }
    let status = Command::new(&python)
        .arg(dir.join("run_cases.py"))
        .args(["quick", "--scene", &scene.display().to_string(), "-m", &m.to_string(), "--backends", "native", "--pathtracer", &exe])
        .args(["--refs", &run_refs.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(",")])
        .args(["--scene-flags", &scene_flags(a).join(" ")])
        .arg("--out")
        .arg(&out)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .output();
    let seconds = start.elapsed().as_secs_f64();
    let summary = std::fs::read_to_string(out.join("summary.json")).ok().and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok());
    let Some(summary) = summary else {
        let why = match status {
            Ok(o) => {
                let err = String::from_utf8_lossy(&o.stderr);
                let last = err.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("no message").trim().to_string();
                format!("{last} ({}, no summary written)", o.status)
            }
            Err(e) => format!("cannot run the harness: {e}"),
        };
        checks.extend(run_refs.iter().map(|r| Check { seconds, ..Check::new(format!("reference: {r}"), Status::Unresolved, format!("the harness stopped: {why}")) }));
        return checks;
    };
    for r in run_refs {
        let rows: Vec<&serde_json::Value> = summary["results"].as_array().into_iter().flatten().filter(|x| x["reference"].as_str() == Some(r.as_str())).collect();
        let name = format!("reference: {r}");
        let refused = rows.iter().find_map(|x| x["refused"].as_str());
        let failed: Vec<String> = rows.iter().filter(|x| x["passed"] == false).map(|x| format!("{} {}: {}", x["kind"].as_str().unwrap_or(""), x["case"].as_str().unwrap_or(""), x["summary"].as_str().map(String::from).unwrap_or_else(|| format!("global t {}", x["global_z"])))).collect();
        let judged = rows.iter().filter(|x| x["refused"].is_null()).count();
        let c = if !failed.is_empty() {
            Check::new(name, Status::Fail, format!("{} of {} comparisons differ; first: {}", failed.len(), judged, failed[0]))
        } else if judged == 0 {
            Check::new(name, Status::Skipped, refused.map_or("the harness made no comparison with it".to_string(), |w| format!("cannot represent the scene exactly: {w}")))
        } else {
            let mut c = Check::new(name, Status::Pass, format!("{judged} comparisons agree (the harness's quick tier: per-pixel Welch z, Šidák-corrected, and the image mean){}", refused.map_or(String::new(), |w| format!("; refused for some: {w}"))));
            c.details = rows.iter().filter_map(|x| x["summary"].as_str().map(String::from)).collect();
            c
        };
        checks.push(Check { seconds, details: if c.details.is_empty() { failed } else { c.details.clone() }, ..c });
    }
    if seconds > 2.0 * budget.as_secs_f64() {
        if let Some(c) = checks.last_mut() {
            c.details.push(format!("the references took {seconds:.0} s of a {:.0} s share: the harness renders at its quick tier's sizes whatever the budget", budget.as_secs_f64()));
        }
    }
    if report.is_none() {
        let _ = std::fs::remove_dir_all(&out);
    }
    checks
}
