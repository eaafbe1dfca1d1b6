//! Helpers shared by the integration tests.
#![allow(dead_code)]

use pathtracer::accel::{self, BackendKind, Traversal};
use pathtracer::scene::{collada, Scene, Shape};
use std::path::{Path, PathBuf};

/// Every backend built into this binary. Embree is included when the build
/// found it; `PATHTRACER_REQUIRE_EMBREE=1` (set by CI) makes its absence fatal.
pub fn backends() -> Vec<BackendKind> {
    let mut v = vec![BackendKind::Native, BackendKind::Brute];
    if accel::embree::available() {
        v.push(BackendKind::Embree);
    } else {
        assert!(
            std::env::var_os("PATHTRACER_REQUIRE_EMBREE").is_none(),
            "PATHTRACER_REQUIRE_EMBREE is set but this build has no Embree backend: {}",
            accel::embree::unavailable_reason()
        );
        eprintln!("NOTE: Embree backend not built in ({}); Embree cases skipped", accel::embree::unavailable_reason());
    }
    v
}

pub fn build(kind: BackendKind, shapes: &[Shape]) -> Box<dyn Traversal> {
    accel::build(kind, shapes, 0).unwrap_or_else(|e| panic!("building {kind}: {e}")).accel
}

/// The 20 CS184 scenes beside the project. Missing data is a failure, not a pass.
pub fn shared_scene_dir() -> PathBuf {
    let dir = std::env::var_os("PATHTRACER_SHARED_SCENES")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/scenes/cs184"));
    assert!(
        dir.is_dir(),
        "test data missing: CS184 scenes not found at {} (set PATHTRACER_SHARED_SCENES)",
        dir.display()
    );
    dir
}

/// Every shipped `.dae`, sorted, with the scenes the project carries itself.
pub fn shipped_scenes() -> Vec<PathBuf> {
    let mut v = Vec::new();
    for sub in ["meshedit", "simple", "sky"] {
        let d = shared_scene_dir().join(sub);
        for e in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "dae") {
                v.push(p);
            }
        }
    }
    v.sort();
    assert_eq!(v.len(), 20, "expected the 20 CS184 scenes in {}", shared_scene_dir().display());
    v
}

pub fn load(p: &Path) -> Scene {
    collada::load_file(p).unwrap_or_else(|e| panic!("{e}"))
}

pub fn scene_path(sub: &str, name: &str) -> PathBuf {
    let p = shared_scene_dir().join(sub).join(format!("{name}.dae"));
    assert!(p.exists(), "test data missing: {}", p.display());
    p
}
