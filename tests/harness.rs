//! The validation harness's own scripts, run as the harness runs them: its
//! reference exporters on a scene exported by `pathtracer export` (what a
//! reference cannot render exactly is refused with its reason: exit 3, one
//! `cannot represent exactly` line; what it can is rendered), and its
//! statistics. They need what `validation/setup` installs (Blender, the
//! virtual environment); where that is missing a test says so and does not
//! pass silently.

mod common;

use std::path::Path;
use std::process::{Command, Output};

fn export(dir: &Path, flags: &[&str]) -> std::path::PathBuf {
    let scene = dir.join("scene");
    let out = Command::new(env!("CARGO_BIN_EXE_pathtracer"))
        .arg("export")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cs184/sky/CBspheres_lambertian.dae"))
        .args(flags)
        .args(["-r", "16", "12", "--keep-fov", "--out"])
        .arg(&scene)
        .env("CI", "true")
        .output()
        .unwrap();
    assert!(out.status.success(), "export failed: {}", String::from_utf8_lossy(&out.stderr));
    scene
}

fn cycles(scene: &Path, mode: &str, out: &Path, extra: &[&str]) -> Output {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("validation/cycles_ref.py");
    Command::new("blender")
        .args(["-b", "--factory-startup", "--python-exit-code", "1", "-P"])
        .arg(&script)
        .arg("--")
        .arg(scene)
        .args(["--mode", mode, "--spp", "1", "--renders", "1", "--threads", "1"])
        .args(extra)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap()
}

fn blender_installed() -> bool {
    Command::new("blender").arg("--version").output().is_ok_and(|o| o.status.success())
}

/// Cycles 3.4's light from a world map depends on its importance map
/// (validation/env_study.py), so an environment map is refused for
/// radiance, with that reason; its intersection passes do not light
/// anything and still render; `--environment-map` renders it anyway.
#[test]
fn cycles_refuses_an_environment_map_for_radiance_only() {
    if !blender_installed() {
        eprintln!("SKIPPED: Blender is not installed (validation/setup installs it); the Cycles exporter's refusals were not checked");
        return;
    }
    let dir = common::Scratch::new("harness", "cycles_env");
    let map = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/envmaps/studio.exr");
    let scene = export(&dir, &["-e", map.to_str().unwrap()]);

    let out = cycles(&scene, "radiance", &dir.join("radiance"), &[]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "{err}");
    let line: Vec<&str> = err.lines().filter(|l| l.contains("cannot represent exactly")).collect();
    assert_eq!(line.len(), 1, "{err}");
    assert!(line[0].contains("environment map") && line[0].contains("importance map") && line[0].contains("env_study.py"), "{}", line[0]);
    assert!(!dir.join("radiance_cycles.json").exists(), "a refusal leaves no result");

    let out = cycles(&scene, "depth", &dir.join("depth"), &[]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(dir.join("depth_cycles.json").exists() && dir.join("depth_r0.exr").exists());

    let out = cycles(&scene, "radiance", &dir.join("forced"), &["--environment-map"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(dir.join("forced_r0.exr").exists());

    // The same scene without the map is not refused.
    let plain = common::Scratch::new("harness", "cycles_plain");
    let scene = export(&plain, &[]);
    let out = cycles(&scene, "radiance", &plain.join("radiance"), &[]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// The harness's Welch test (`validation/stats.py`) judges a difference
/// against Student's t with the variances' degrees of freedom: its tail
/// probabilities are the t table's; on simulated correct renders whose
/// reference variance comes from 8 renders it keeps the 99.75 % rule
/// (where the normal's critical value fails a third of the runs), and it
/// still fails a render with a few pixels off by 8 standard errors.
#[test]
fn the_harness_welch_test_has_students_tails() {
    let python = Path::new(env!("CARGO_MANIFEST_DIR")).join("validation/.venv/bin/python");
    if !python.exists() {
        eprintln!("SKIPPED: validation/.venv is missing (validation/setup makes it); the harness's statistics were not checked");
        return;
    }
    let script = r#"
import numpy as np, stats
for nu, t in stats.T_CRIT_001.items():
    assert abs(stats.t_two_sided_p(t, nu) - 0.01) < 2e-5, (nu, stats.t_two_sided_p(t, nu))
assert abs(stats.t_two_sided_p(1.959964, 1e7) - 0.05) < 1e-5
rng = np.random.default_rng(1)
n, runs = 471, 100
fail_z = fail_t = 0
for k in range(runs):
    renders = rng.normal(0, np.sqrt(8.0), size=(8, n))
    r, vr = renders.mean(0), renders.var(0, ddof=1) / 8
    x = rng.normal(0, np.sqrt(0.05), n)
    vx = 0.05 * rng.chisquare(504, n) / 504
    z = np.abs(x - r) / np.sqrt(vx + vr)
    fail_z += np.mean(z <= stats.z_critical(n)) < stats.PASS_FRACTION
    fail_t += np.mean(stats.welch_ok(x - r, vx, 504, vr, 7, n)) < stats.PASS_FRACTION
assert fail_t <= 2 and fail_z >= 20, (fail_t, fail_z)
x = rng.normal(0, np.sqrt(0.05), n)
x[:5] += 8 * np.sqrt(0.05 + 1.0)
renders = rng.normal(0, np.sqrt(8.0), size=(8, n))
ok = stats.welch_ok(x - renders.mean(0), np.full(n, 0.05), 504, renders.var(0, ddof=1) / 8, 7, n)
assert np.mean(ok) < stats.PASS_FRACTION, np.mean(ok)
print("ok", fail_t, fail_z)
"#;
    let out = Command::new(&python).arg("-c").arg(script).current_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("validation")).output().unwrap();
    assert!(out.status.success(), "{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
}
