//! The mutation fuzzer in the suite (`pathtracer::app::fuzz`): every seed input
//! renders unmutated; a few thousand mutated cases over every reader, fixed
//! seed, end rendered or refused by name with nothing left behind (no
//! panic, no hang, no stray file); and every input that ever failed
//! (`tests/fuzz/regressions/<kind>/<seed>--<what>.<ext>`) passes now.
//! The long run is `cargo run --release --example fuzz -- --cases 1000000`.

/// Every allocation counted per thread, so a case's memory is its own.
#[global_allocator]
static ALLOC: pathtracer::app::fuzz::alloc::CountingAlloc = pathtracer::app::fuzz::alloc::CountingAlloc::new();

use pathtracer::app::fuzz::{self, Kind, Outcome};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Duration;

/// The panic hook is the process's: one fuzz run at a time.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

fn corpus() -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz/corpus");
    assert!(dir.is_dir(), "test data missing: the fuzz corpus {} (cargo run --example fuzz -- --write-corpus)", dir.display());
    dir
}

fn scratch(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("pt-fuzz-test-{}-{name}", std::process::id()))
}

#[test]
fn every_seed_input_renders_unmutated() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let mut seen = 0;
    for kind in Kind::ALL {
        let seeds = fuzz::Seeds::load(&corpus(), kind).unwrap();
        for (name, bytes) in &seeds.files {
            let outcome = fuzz::run_one(&corpus(), kind, Some(name), bytes, scratch("seeds")).unwrap();
            assert_eq!(outcome, Outcome::Rendered, "{} seed {name}", kind.name());
            seen += 1;
        }
    }
    assert!(seen >= 20, "only {seen} seed inputs");
    let _ = std::fs::remove_dir_all(scratch("seeds"));
}

#[test]
fn mutated_inputs_render_or_are_refused_by_name() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let opts = fuzz::Options {
        corpus: corpus(),
        kinds: Kind::ALL.to_vec(),
        seed: 2026,
        first: 0,
        cases: 7000,
        workers: 2,
        hang_after: Duration::from_secs(20),
        scratch: scratch("run"),
    };
    let report = fuzz::run(&opts, &mut |_, _, _| {}).unwrap();
    eprintln!("{} cases in {:.1} s\n{}", report.total(), report.seconds, report.table());
    assert_eq!(report.total(), 7000);
    let failures: Vec<String> = report
        .findings
        .iter()
        .map(|f| format!("{} case {} (seed input {}): {}: {}", f.kind.name(), f.case, f.seed_name, f.outcome.class(), f.outcome.detail()))
        .collect();
    assert!(failures.is_empty(), "{} failing cases (rerun one with: cargo run --release --example fuzz -- --seed 2026 --first CASE --cases 1):\n{}", failures.len(), failures.join("\n"));
    // The cases reach past the first check of every reader: each kind has
    // inputs that render and inputs that are refused.
    for kind in Kind::ALL {
        for class in ["rendered", "refused"] {
            assert!(report.counts.get(&(kind, class)).copied().unwrap_or(0) >= 10, "{}: fewer than 10 cases {class}\n{}", kind.name(), report.table());
        }
    }
    let _ = std::fs::remove_dir_all(scratch("run"));
}

#[test]
fn every_input_that_ever_failed_passes() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz/regressions");
    let mut ran = 0;
    for kind in Kind::ALL {
        let dir = root.join(kind.name());
        let Ok(entries) = std::fs::read_dir(&dir) else { continue };
        let mut files: Vec<PathBuf> = entries.map(|e| e.unwrap().path()).collect();
        files.sort();
        for path in files {
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            let seed = name.split_once("--").map(|(s, _)| s.to_string());
            let input = std::fs::read(&path).unwrap();
            let outcome = fuzz::run_one(&corpus(), kind, seed.as_deref(), &input, scratch("regressions")).unwrap();
            assert!(!outcome.is_failure(), "{}: {}: {}", path.display(), outcome.class(), outcome.detail());
            ran += 1;
        }
    }
    assert!(ran > 0, "no regression inputs found under {}", root.display());
    eprintln!("{ran} regression inputs pass");
    let _ = std::fs::remove_dir_all(scratch("regressions"));
}
