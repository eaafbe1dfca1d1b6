//! `pathtracer validate`: its checks catch a broken backend and a broken
//! integrator, naming the check that failed; it passes on a shipped scene;
//! its JUnit XML is well formed and says what the lines say.

use glam::{Mat4, Vec3};
use pathtracer::accel::{self, BackendKind, Hit, Traversal};
use pathtracer::app::validate::{compare_backends, compare_estimators, estimator, ray_sets, Status};
use pathtracer::camera::Camera;
use pathtracer::ray::Ray;
use pathtracer::render::bdpt::{LightPaths, Technique};
use pathtracer::render::integrator::{BdptOptions, Bounces, IntegratorSpec, PathOptions};
use pathtracer::render::job::{Job, LightSampling};
use pathtracer::sampler::SamplerKind;
use pathtracer::scene::{LightDesc, LightKind, Scene};
use std::path::Path;
use std::process::Command;
use std::sync::Mutex;
use std::time::Duration;

/// The checks are timed against a budget: the tests that render take the
/// machine one at a time, so that a budget means what it says.
static MACHINE: Mutex<()> = Mutex::new(());

fn scene(name: &str) -> Scene {
    pathtracer::scene::load_file(&Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cs184/sky").join(name)).unwrap()
}

fn camera(scene: &Scene) -> Camera {
    let mut c = Camera::from_scene(scene);
    c.resize_keep_fov(64, 48);
    c
}

/// Native's answers, but wrong on about one ray in 40 (chosen by the
/// ray's own bits, so the same rays whatever the thread order): a hit
/// moved 1 % along the ray, or a hit reported as a miss.
struct Broken(Box<dyn Traversal>);

impl Broken {
    fn spoils(r: &Ray) -> u32 {
        r.dir.x.to_bits().wrapping_mul(2654435761) >> 26
    }
}

impl Traversal for Broken {
    fn name(&self) -> &'static str {
        "broken"
    }
    fn memory_bytes(&self) -> usize {
        self.0.memory_bytes()
    }
    fn intersect(&self, r: &Ray) -> Option<Hit> {
        let h = self.0.intersect(r);
        match Self::spoils(r) {
            0 => None,
            1 => h.map(|h| Hit { t: h.t * 1.01, ..h }),
            _ => h,
        }
    }
    fn occluded(&self, r: &Ray) -> bool {
        self.0.occluded(r)
    }
}

#[test]
fn a_backend_returning_wrong_hits_fails_the_geometry_check() {
    let _machine = MACHINE.lock().unwrap_or_else(|e| e.into_inner());
    let s = scene("CBbunny.dae");
    let native = accel::build(BackendKind::Native, &s.shapes, 0).unwrap().accel;
    let rays = ray_sets(&s, &camera(&s), native.as_ref(), 2048);
    assert!(rays.iter().all(|(_, set)| !set.is_empty()), "every kind of ray is made: {:?}", rays.iter().map(|(k, v)| (k, v.len())).collect::<Vec<_>>());
    // The same backend twice agrees: the check can pass.
    let again = accel::build(BackendKind::Native, &s.shapes, 0).unwrap().accel;
    let ok = compare_backends("geometry: native against native", &s, native.as_ref(), again.as_ref(), &rays, None);
    assert_eq!(ok.status, Status::Pass, "{}", ok.summary);
    let broken = Broken(accel::build(BackendKind::Native, &s.shapes, 0).unwrap().accel);
    let c = compare_backends("geometry: broken against native", &s, native.as_ref(), &broken, &rays, None);
    assert_eq!(c.status, Status::Fail, "{}", c.summary);
    assert!(c.name.contains("broken") && c.summary.contains("differ"), "{}: {}", c.name, c.summary);
    // Both faults are reported, ray by ray.
    assert!(c.details.iter().any(|d| d.contains("t/u/v differ")), "{:#?}", c.details);
    assert!(c.details.iter().any(|d| d.contains("None")), "{:#?}", c.details);
}

/// The Cornell box with a second light: a point light under the ceiling.
fn two_lights() -> (Scene, Scene) {
    let one = scene("CBempty.dae");
    let mut two = one.clone();
    let b = two.bounds();
    let at = Vec3::new(b.min.x + 0.3 * b.extent().x, b.max.y - 0.2 * b.extent().y, b.min.z + 0.5 * b.extent().z);
    two.lights.push(LightDesc { name: "second".into(), kind: LightKind::Point, radiance: Vec3::splat(0.5), transform: Mat4::from_translation(at) });
    (two, one)
}

#[test]
fn an_integrator_missing_a_light_fails_the_transport_check() {
    let _machine = MACHINE.lock().unwrap_or_else(|e| e.into_inner());
    let (two, one) = two_lights();
    let cam = camera(&two);
    let native = accel::build(BackendKind::Native, &two.shapes, 0).unwrap().accel;
    let bounces = Bounces { max_depth: 3, accumulate: true };
    let path = IntegratorSpec::Path(PathOptions { bounces, light_samples: 1, hemisphere: false, russian_roulette: true, specular_guide: 0.0 });
    let bdpt = IntegratorSpec::Bdpt(BdptOptions { bounces, technique: Technique::Bidirectional, light_paths: LightPaths::All, unseen_light_caustics: false });
    let job = |s: &Scene, spec| Job::new(s.clone(), cam.clone(), None, LightSampling::default(), spec).unwrap();
    let path_tracer = estimator("path tracer", job(&two, path), SamplerKind::Sobol, None, native.as_ref());
    // BDPT that leaves the second light out: an integrator missing a light's contribution.
    let missing = estimator("BDPT", job(&one, bdpt), SamplerKind::Sobol, None, native.as_ref());
    let c = compare_estimators("light transport: path tracer against BDPT", &path_tracer, &missing, Duration::from_secs(8), false);
    assert_eq!(c.status, Status::Fail, "{}", c.summary);
    assert!(c.name.contains("light transport") && c.summary.contains("differ by more than the tolerance"), "{}", c.summary);
    // With the light, the same comparison is not a failure.
    let whole = estimator("BDPT", job(&two, bdpt), SamplerKind::Sobol, None, native.as_ref());
    let c = compare_estimators("light transport: path tracer against BDPT", &path_tracer, &whole, Duration::from_secs(8), false);
    assert_ne!(c.status, Status::Fail, "{}", c.summary);
}

/// The whole command on a shipped scene: every check passes within its
/// budget, and the JUnit file parses and says the same. The scene's light
/// is an area light: CBempty's point light, 1 cm under its ceiling, gives
/// the path tracer rare samples thousands of times the usual (one of 15
/// renders of 1144 samples a pixel held one in the run it left
/// undecided), which left this comparison undecided now and then within
/// the budget.
#[test]
fn validate_passes_on_a_shipped_scene_and_writes_well_formed_junit() {
    let _machine = MACHINE.lock().unwrap_or_else(|e| e.into_inner());
    let dir = std::env::temp_dir().join(format!("pt-validate-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let out = Command::new(env!("CARGO_BIN_EXE_pathtracer"))
        .args(["validate", "scenes/cs184/sky/CBspheres_lambertian.dae", "-m", "2", "--budget", "90s", "--references", "none", "--report"])
        .arg(&dir)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("CI", "true")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "exit {:?}\n{stdout}\n{}", out.status.code(), String::from_utf8_lossy(&out.stderr));
    let lines: Vec<&str> = stdout.lines().collect();
    assert!(lines.iter().any(|l| l.starts_with("PASS") && l.contains("light transport: path tracer against BDPT")), "{stdout}");
    assert!(lines.last().unwrap().contains("0 failed, 0 undecided"), "{stdout}");
    let xml = std::fs::read_to_string(dir.join("junit.xml")).unwrap();
    let doc = roxmltree::Document::parse(&xml).unwrap_or_else(|e| panic!("junit.xml is not well formed: {e}\n{xml}"));
    let root = doc.root_element();
    assert_eq!(root.tag_name().name(), "testsuites");
    let suite = root.children().find(|n| n.has_tag_name("testsuite")).expect("a testsuite");
    let cases: Vec<_> = suite.children().filter(|n| n.has_tag_name("testcase")).collect();
    let checks = lines.iter().filter(|l| ["PASS", "FAIL", "SKIP", "UNRESOLVED"].iter().any(|w| l.starts_with(w))).count();
    assert_eq!(cases.len(), checks, "one test case per check line");
    assert_eq!(suite.attribute("tests"), Some(checks.to_string().as_str()));
    assert_eq!(suite.attribute("failures"), Some("0"));
    assert!(cases.iter().all(|c| c.attribute("name").is_some() && c.attribute("time").is_some_and(|t| t.parse::<f64>().is_ok())));
    let skipped = cases.iter().filter(|c| c.children().any(|n| n.has_tag_name("skipped"))).count();
    assert_eq!(suite.attribute("skipped"), Some(skipped.to_string().as_str()));
    let summary: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["passed"], true);
    assert!(std::fs::read_to_string(dir.join("report.html")).unwrap().contains("light transport"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// JUnit escapes what a check's line can hold (a scene named with
/// markup, a ray's debug text), and marks failures and undecided checks.
#[test]
fn junit_escapes_and_marks_every_status() {
    use pathtracer::app::validate::{junit, Check};
    let checks = vec![
        Check::new("geometry: a <b> & \"c\"", Status::Fail, "1 of 2 rays differ; first: Some(Hit { t: 1.0 }) against None"),
        Check::new("light transport: x", Status::Unresolved, "could not tell"),
        Check::new("reference: cycles", Status::Skipped, "cannot represent 'it' exactly"),
        Check::new("ok", Status::Pass, "fine"),
    ];
    let xml = junit("scene <&>", &checks, 1.5);
    let doc = roxmltree::Document::parse(&xml).unwrap_or_else(|e| panic!("{e}\n{xml}"));
    let suite = doc.root_element().children().find(|n| n.has_tag_name("testsuite")).unwrap();
    assert_eq!(suite.attribute("name"), Some("scene <&>"));
    assert_eq!((suite.attribute("failures"), suite.attribute("errors"), suite.attribute("skipped")), (Some("1"), Some("1"), Some("1")));
    let cases: Vec<_> = suite.children().filter(|n| n.has_tag_name("testcase")).collect();
    assert_eq!(cases[0].attribute("name"), Some("geometry: a <b> & \"c\""));
    assert!(cases[0].children().any(|n| n.has_tag_name("failure")));
    assert!(cases[1].children().any(|n| n.has_tag_name("error")));
    assert!(cases[2].children().any(|n| n.has_tag_name("skipped")));
}
