//! Build one bench scene's acceleration structure again and again: the
//! workload to put under a profiler (`perf record`) or to time builds of
//! two binaries against each other, without the bench's ray tables.
//!
//! ```text
//! cargo run --release --example build_bvh -- SCENE BACKEND BUILDS [EXPECTED_RAYS]
//! perf record -g target/release/examples/build_bvh sphere:1M native 20
//! ```
//! Prints each build's wall time and the best. SCENE is a bench scene name
//! or file, BACKEND a `--backend` value; builds use every thread (rayon's
//! `RAYON_NUM_THREADS` limits them). The `PATHTRACER_NATIVE_*` switches
//! apply as they do to `pathtracer`. EXPECTED_RAYS, as the bench passes
//! it (its ray count over every pass), lets the native build weigh spatial
//! splits; without it the build does not try them.

use clap::ValueEnum;
use pathtracer::accel::{self, BackendKind};
use pathtracer::app::bench::load_bench_scene;
use std::time::Instant;

fn main() {
    if let Err(e) = run() {
        eprintln!("build_bvh: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (scene, backend, builds, expected) = match args.as_slice() {
        [s, b, n] => (s, b, n, None),
        [s, b, n, e] => (s, b, n, Some(e)),
        _ => return Err("usage: build_bvh SCENE BACKEND BUILDS [EXPECTED_RAYS]".into()),
    };
    let backend = BackendKind::from_str(backend, true)?;
    let builds: usize = builds.parse().map_err(|_| format!("BUILDS: not a count: {builds}"))?;
    let scene = load_bench_scene(scene).map_err(|e| e.to_string())?;
    let mut options = accel::BuildOptions::from_lookup(0, |k| std::env::var(k).ok()).map_err(|e| e.to_string())?;
    if let Some(e) = expected {
        options.native.expected_rays = e.parse().map_err(|_| format!("EXPECTED_RAYS: not a count: {e}"))?;
    }
    let mut times = Vec::with_capacity(builds);
    for _ in 0..builds {
        let start = Instant::now();
        let built = accel::build_with(backend, &scene.shapes, &options).map_err(|e| e.to_string())?;
        times.push(start.elapsed().as_secs_f64() * 1e3);
        drop(built);
    }
    let line: Vec<String> = times.iter().map(|t| format!("{t:.1}")).collect();
    let best = times.iter().copied().fold(f64::INFINITY, f64::min);
    println!("{} ms; best {best:.1} ms", line.join(" "));
    Ok(())
}
