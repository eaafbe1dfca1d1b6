//! Trace one bench ray set through one backend for a while, single
//! threaded: the workload to put under a profiler (`perf record`), which
//! `pathtracer bench` mixes with builds and other contenders.
//!
//! ```text
//! cargo run --release --example trace_rays -- SCENE BACKEND KIND SECONDS
//! perf record -g target/release/examples/trace_rays subdiv:bunny:1.5M native random 10
//! ```
//! SCENE is a bench scene name or file; BACKEND a `--backend` value, or
//! `obvhs` where the example is built with `--features peers`; KIND
//! `camera`, `shadow`, `random` or `diffuse` (the bench's rays and batch
//! calls; diffuse rays leave the camera rays' hits in 32x32 tiles), or
//! `random1` / `diffuse1`: the same rays one call each (`intersect`). The
//! `PATHTRACER_NATIVE_*` switches apply as they do to `pathtracer`.
//!
//! KIND `work` (native or obvhs, SECONDS unused) times nothing: it counts
//! what one closest-hit query of each random ray visits, native's nodes
//! and four-triangle leaf groups, obvhs's node tests and triangle tests,
//! and prints their means.

use clap::ValueEnum;
use pathtracer::accel::wide::{WideBvh, NATIVE_WIDTH};
use pathtracer::accel::{self, BackendKind, Traversal};
use pathtracer::accel::workloads::{camera_rays, diffuse_rays, random_rays, shadow_rays, tile_order};
use pathtracer::app::bench::load_bench_scene;
use pathtracer::camera::Camera;
use pathtracer::scene::Scene;
use std::time::Instant;

fn main() {
    if let Err(e) = run() {
        eprintln!("trace_rays: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [scene, backend, kind, seconds] = args.as_slice() else {
        return Err("usage: trace_rays SCENE BACKEND|obvhs camera|shadow|random|diffuse|random1|diffuse1|work SECONDS".into());
    };
    let seconds: f64 = seconds.parse().map_err(|_| format!("SECONDS: not a number: {seconds}"))?;
    let scene = load_bench_scene(scene).map_err(|e| e.to_string())?;
    let options = accel::BuildOptions::from_lookup(0, |k| std::env::var(k).ok()).map_err(|e| e.to_string())?;
    let n = 1 << 20;
    if kind == "work" {
        return count_work(&scene, backend, &options, n);
    }
    let accel: Box<dyn Traversal> = if backend == "obvhs" {
        obvhs(&scene)?
    } else {
        let backend = BackendKind::from_str(backend, true)?;
        accel::build_with(backend, &scene.shapes, &options).map_err(|e| e.to_string())?.accel
    };
    let accel = accel.as_ref();
    let mut cam = Camera::from_scene(&scene);
    cam.set_screen_size(1024, 1024);
    let (set, one_call) = match kind.strip_suffix('1') {
        Some(set @ ("random" | "diffuse")) => (set, true),
        _ => (kind.as_str(), false),
    };
    let rays = match set {
        "camera" => camera_rays(&cam, 1024, 1024),
        "shadow" => shadow_rays(&scene, accel, &camera_rays(&cam, 1024, 1024)),
        "random" => random_rays(&scene, n, 1),
        "diffuse" => diffuse_rays(&scene, accel, &tile_order(&camera_rays(&cam, 1024, 1024), 1024, 1024, 32), 7),
        _ => return Err(format!("KIND: camera, shadow, random, diffuse, random1 or diffuse1, not {kind}")),
    };
    let start = Instant::now();
    let (mut traced, mut hits) = (0usize, 0usize);
    while start.elapsed().as_secs_f64() < seconds {
        for chunk in rays.chunks(4096) {
            if kind == "shadow" {
                let mut out = vec![false; chunk.len()];
                accel.occluded_coherent(chunk, &mut out);
                hits += out.iter().filter(|&&o| o).count();
            } else {
                let mut out = vec![None; chunk.len()];
                if one_call {
                    for (ray, hit) in chunk.iter().zip(&mut out) {
                        *hit = accel.intersect(ray);
                    }
                } else if kind == "camera" {
                    accel.intersect_coherent(chunk, &mut out);
                } else {
                    accel.intersect_batch(chunk, &mut out);
                }
                hits += out.iter().filter(|h| h.is_some()).count();
            }
        }
        traced += rays.len();
    }
    let t = start.elapsed().as_secs_f64();
    println!("{} {backend} {kind}: {traced} rays, {hits} hits, {:.2} Mrays/s (1 thread)", scene.name, traced as f64 / t / 1e6);
    Ok(())
}

#[cfg(feature = "peers")]
fn obvhs(scene: &Scene) -> Result<Box<dyn Traversal>, String> {
    Ok(Box::new(accel::obvhs_peer::ObvhsPeer::build(&scene.shapes).map_err(|e| e.to_string())?))
}

#[cfg(not(feature = "peers"))]
fn obvhs(_: &Scene) -> Result<Box<dyn Traversal>, String> {
    Err("obvhs: build the example with --features peers".into())
}

/// KIND `work`: the mean nodes and leaf tests per random ray.
fn count_work(scene: &Scene, backend: &str, options: &accel::BuildOptions, n: usize) -> Result<(), String> {
    let rays = random_rays(scene, n, 1);
    match backend {
        "native" => {
            let bvh = WideBvh::<NATIVE_WIDTH>::build_with(&scene.shapes, &options.native);
            println!("{} native work: {:.2} nodes + four-triangle groups per random ray", scene.name, bvh.closest_work(&rays));
        }
        "obvhs" => count_obvhs(scene, &rays)?,
        _ => return Err(format!("KIND work: BACKEND native or obvhs, not {backend}")),
    }
    Ok(())
}

#[cfg(feature = "peers")]
fn count_obvhs(scene: &Scene, rays: &[pathtracer::ray::Ray]) -> Result<(), String> {
    let peer = accel::obvhs_peer::ObvhsPeer::build(&scene.shapes).map_err(|e| e.to_string())?;
    let (mut nodes, mut tests) = (0u64, 0u64);
    for r in rays {
        let (a, b) = peer.closest_work(r);
        nodes += a as u64;
        tests += b as u64;
    }
    let per_ray = |sum: u64| sum as f64 / rays.len() as f64;
    println!("{} obvhs work: {:.2} node tests, {:.2} triangle tests per random ray", scene.name, per_ray(nodes), per_ray(tests));
    Ok(())
}

#[cfg(not(feature = "peers"))]
fn count_obvhs(_: &Scene, _: &[pathtracer::ray::Ray]) -> Result<(), String> {
    Err("obvhs: build the example with --features peers".into())
}
