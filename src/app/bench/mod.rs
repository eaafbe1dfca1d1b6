//! `pathtracer bench`: BVH build time, memory and ray throughput per backend,
//! CS184's with/without-BVH render timing, and full path-traced renders per
//! backend, printed as Markdown tables. The ray sets it times are the
//! library's (`accel::workloads`), so the cross-check tests trace exactly
//! what the benchmark times; its generated scenes are `scene::generated`.

use crate::accel::{self, BackendKind};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::light::Lights;
use crate::render::{self, path::{specular_guide::{self, SpecularGuide}, PathTracer}, RenderSettings};
use crate::scene::Scene;
use clap::Args;
use glam::Vec3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

#[cfg(has_embree)]
mod embree_calls;
mod resume;
mod ray_sets;
mod run;
mod tables;
mod timing;

use crate::scene::generated;
pub use timing::PASSES;
pub use run::run;

pub use tables::Sample;

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Scene files (.dae, .obj, .ply) or names (cow, maxplanck, CBbunny, ...
    /// found in scenes/cs184 under the current folder), or generated scenes of N
    /// triangles: sphere:N, arch:N, grass:N, stadium:N, subdiv:NAME:N (see
    /// docs/benchmarks/README.md). Default: cow maxplanck CBbunny beetle sphere:1M
    /// sphere:5M arch:2M grass:2M stadium:2M subdiv:bunny:1.5M arch:10M.
    pub scenes: Vec<String>,
    /// Backends to time [default: native, embree3, embree3-high, embree4,
    /// embree4-high (those that load here), brute]; the peers built in are
    /// timed too unless --no-peers
    #[arg(long, value_enum, value_delimiter = ',')]
    pub backends: Vec<BackendKind>,
    /// Rays per throughput measurement (brute uses a 1/32 subset)
    #[arg(long, default_value_t = 1 << 20)]
    pub rays: usize,
    /// Skip the render timings (normal shading with and without the BVH;
    /// path tracing of CBbunny, CBspheres_lambertian, CBspheres, CBgems and
    /// subdiv:CBbunny:1M at 64 spp, -m 5)
    #[arg(long)]
    pub no_render: bool,
    /// Leave out the peer libraries built in with `--features peers` (obvhs)
    #[arg(long)]
    pub no_peers: bool,
    /// Timed passes per contender, ray kind and thread count (the best is
    /// kept; one untimed pass comes first)
    #[arg(long, default_value_t = PASSES, value_parser = clap::builder::TypedValueParser::map(clap::value_parser!(u32).range(1..=100), |n| n as usize))]
    pub passes: usize,
    /// Only the build and throughput tables: no SAH statistics (a child run
    /// that builds the scene again), no Embree batch-call table, no renders.
    /// For thread-scaling runs on a machine where minutes count.
    #[arg(long)]
    pub throughput_only: bool,
    /// Thread counts to time throughput at, e.g. 1,2,4,8,16 [default: 1 and
    /// every thread of the machine]. With three or more, a thread-scaling
    /// table follows the throughput table. Builds always use every thread.
    #[arg(long, value_delimiter = ',', value_name = "N,...")]
    pub threads: Vec<usize>,
    /// Also write the throughput rows as CSV
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Also write the printed tables as Markdown
    #[arg(long, value_name = "FILE")]
    pub markdown: Option<PathBuf>,
    /// Keep each finished part of the run (a scene's tables, a scene's
    /// path-traced renders) in DIR, and take the parts an earlier run of
    /// this same binary, machine and options kept there, from the same
    /// scene files, instead of measuring them again: a run cut short starts
    /// again where it stopped
    #[arg(long, value_name = "DIR")]
    pub resume: Option<PathBuf>,
}

/// The default bench scenes: the CS184 scans, the easy procedural sphere and
/// the hard generators of `scenes` (1M-10M triangles).
pub const DEFAULT_SCENES: [&str; 11] =
    ["cow", "maxplanck", "CBbunny", "beetle", "sphere:1M", "sphere:5M", "arch:2M", "grass:2M", "stadium:2M", "subdiv:bunny:1.5M", "arch:10M"];

/// Path-traced render timing (the benchmark's last table): these scenes at
/// 480x360, 64 spp, -m 5, every backend but brute, same seed. CBspheres (mirror
/// and glass spheres) and CBgems (glass meshes) time the delta-BSDF paths.
pub const RENDER_SCENES: [&str; 5] = ["CBbunny", "CBspheres_lambertian", "CBspheres", "CBgems", "subdiv:CBbunny:1M"];

/// Brute force is skipped above this many primitives (hours per measurement).
const BRUTE_LIMIT: usize = 100_000;
/// The most threads `--threads` takes (rayon pools beyond this are a typo).
const MAX_THREADS: usize = 1024;
/// Builds timed per backend and scene; the table shows the fastest.
const BUILD_REPS: usize = 3;

/// Folders searched for scene names, in order.
pub fn scene_dirs() -> Vec<PathBuf> {
    let mut dirs = Vec::new();
    if let Some(d) = std::env::var_os("PATHTRACER_SCENES") {
        dirs.push(PathBuf::from(d));
    }
    for sub in ["sky", "meshedit", "simple"] {
        dirs.push(Path::new("scenes/cs184").join(sub));
    }
    dirs
}

/// A path as given, or `NAME.dae` found in `scene_dirs()`.
pub fn find_scene(name: &str) -> Result<PathBuf> {
    let p = Path::new(name);
    if p.exists() {
        return Ok(p.to_path_buf());
    }
    let has_ext = [".dae", ".obj", ".ply"].iter().any(|e| name.to_ascii_lowercase().ends_with(e));
    let file = if has_ext { name.to_string() } else { format!("{name}.dae") };
    scene_dirs()
        .into_iter()
        .map(|d| d.join(&file))
        .find(|p| p.exists())
        .ok_or_else(|| Error::new(format!("{name}: scene not found (looked in $PATHTRACER_SCENES and scenes/cs184/{{sky,meshedit,simple}} under the current folder)")))
}

/// A scene file or name (see `find_scene`), or a generator spec
/// (`scene::generated`).
pub fn load_bench_scene(name: &str) -> Result<Scene> {
    if !Path::new(name).exists() {
        if let Some(s) = generated::generate(name, &find_scene) {
            return s;
        }
    }
    crate::scene::load_file(&find_scene(name)?)
}

/// The files the scene `name` is read from (the file it names or finds, the
/// scene a generator refines; none for a generator that reads nothing), for
/// `--resume` to tell an edited scene from the one a kept part measured.
pub fn scene_files(name: &str) -> Vec<PathBuf> {
    let names = match generated::inputs(name) {
        Some(names) if !Path::new(name).exists() => names,
        _ => vec![name],
    };
    names.into_iter().filter_map(|n| find_scene(n).ok()).collect()
}

/// The CPU's model name and the SIMD extensions the backends can use, so a
/// table says what it was measured on.
fn cpu_model() -> String {
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| t.lines().find(|l| l.starts_with("model name")).and_then(|l| l.split(':').nth(1)).map(|m| m.trim().to_string()))
        .unwrap_or_else(|| std::env::consts::ARCH.to_string());
    #[cfg(target_arch = "x86_64")]
    let isa = if is_x86_feature_detected!("avx512f") {
        "AVX-512"
    } else if is_x86_feature_detected!("avx2") {
        "AVX2"
    } else {
        "SSE2"
    };
    #[cfg(not(target_arch = "x86_64"))]
    let isa = "no x86 SIMD";
    format!("{model} ({isa})")
}

/// Embree's own SAH cost for the scene `name`, from the BVH statistics it
/// prints with `verbose=2`: a child `pathtracer bench` run builds the scene
/// with Embree alone and this parses its `total : sah = X` line. `None`
/// where that is not possible (not running as the `pathtracer` binary, the
/// line missing).
fn embree_sah(name: &str, major: crate::accel::embree::Major) -> Option<f64> {
    let exe = std::env::current_exe().ok()?;
    if !exe.file_name()?.to_string_lossy().starts_with("pathtracer") {
        return None;
    }
    let out = std::process::Command::new(exe)
        .args(["bench", name, "--backends", &format!("embree{}", major.number()), "--no-render", "--rays", "16"])
        .env("PATHTRACER_EMBREE_CONFIG", "verbose=2")
        .stdin(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .output()
        .ok()?;
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().find(|l| l.trim_start().starts_with("total") && l.contains("sah ="))?;
    line.split("sah =").nth(1)?.split_whitespace().next()?.parse().ok()
}

/// What the benchmark times: one of our backends, or a peer library on the
/// same rays (built in with `--features peers`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Contender {
    Backend(BackendKind),
    #[cfg(feature = "peers")]
    Obvhs,
    #[cfg(feature = "peers")]
    TinyBvh(crate::accel::tinybvh_peer::Build),
}

impl std::fmt::Display for Contender {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Contender::Backend(k) => write!(f, "{k}"),
            #[cfg(feature = "peers")]
            Contender::Obvhs => f.write_str("obvhs"),
            #[cfg(feature = "peers")]
            Contender::TinyBvh(crate::accel::tinybvh_peer::Build::Sah) => f.write_str("tinybvh"),
            #[cfg(feature = "peers")]
            Contender::TinyBvh(crate::accel::tinybvh_peer::Build::Hq) => f.write_str("tinybvh-hq"),
        }
    }
}

impl Contender {
    fn build(self, scene: &Scene, threads: usize, expected_rays: u64) -> Result<accel::Built> {
        match self {
            Contender::Backend(k) => {
                let mut options = crate::app::build_options(threads)?;
                options.native.expected_rays = expected_rays;
                accel::build_with(k, &scene.shapes, &options)
            }
            #[cfg(feature = "peers")]
            Contender::Obvhs => {
                // obvhs builds on rayon's global pool (all threads).
                let start = std::time::Instant::now();
                let accel = Box::new(accel::obvhs_peer::ObvhsPeer::build(&scene.shapes)?);
                Ok(accel::Built { accel, build_seconds: start.elapsed().as_secs_f64() })
            }
            #[cfg(feature = "peers")]
            Contender::TinyBvh(b) => {
                let start = std::time::Instant::now();
                let accel = Box::new(accel::tinybvh_peer::TinyBvhPeer::build(&scene.shapes, b)?);
                Ok(accel::Built { accel, build_seconds: start.elapsed().as_secs_f64() })
            }
        }
    }
}

/// The peers compiled into this binary.
fn peers() -> Vec<Contender> {
    #[allow(unused_mut)]
    let mut v = Vec::new();
    #[cfg(feature = "peers")]
    v.extend([Contender::Obvhs, Contender::TinyBvh(crate::accel::tinybvh_peer::Build::Sah), Contender::TinyBvh(crate::accel::tinybvh_peer::Build::Hq)]);
    v
}



/// Time full renders of one scene per backend, with and without camera-ray
/// batches, and check that every render made the same image.
fn path_render_rows(name: &str, backends: &[BackendKind], threads: usize) -> Result<String> {
    let scene = load_bench_scene(name)?;
    let lights = Lights::from_scene(&scene)?;
    let (guide, _) = SpecularGuide::of_scene(&scene, specular_guide::DEFAULT_FRACTION);
    let mut cam = Camera::from_scene(&scene);
    cam.set_screen_size(480, 360);
    let mut rows = String::new();
    let mut first: Option<Vec<Vec3>> = None;
    for &kind in backends {
        let mut options = crate::app::build_options(threads)?;
        // 480x360 pixels, 64 samples, 6 bounces of a closest and a shadow ray.
        options.native.expected_rays = 480 * 360 * 64 * 6 * 2;
        let built = accel::build_with(kind, &scene.shapes, &options)?;
        let integ = PathTracer {
            scene: &scene,
            lights: &lights,
            guide: guide.as_ref(),
            max_depth: 5,
            accumulate: true,
            hemisphere: false,
            light_samples: 1,
            russian_roulette: true,
        };
        for batch in [true, false] {
            let mut settings = RenderSettings::new(480, 360, 64, 1);
            settings.batch_rays = batch;
            let out = render::render(&cam, built.accel.as_ref(), &integ, &settings);
            let same = match &first {
                None => {
                    first = Some(out.image.pixels.clone());
                    "reference".to_string()
                }
                Some(f) => {
                    let differ = f.iter().zip(&out.image.pixels).filter(|(a, b)| a != b).count();
                    if differ == 0 { "identical".to_string() } else { format!("{differ} pixels differ") }
                }
            };
            let _ = writeln!(
                rows,
                "| {} | {} | {} | {:.2} | {} | {:.2} | {} |",
                scene.name,
                kind,
                if batch { "batched" } else { "single" },
                out.seconds,
                out.rays,
                out.rays as f64 / out.seconds / 1e6,
                same
            );
        }
    }
    Ok(rows)
}

/// The seed write-up's render timings (normal shading), where it gives them.
fn seed_timing(scene: &str) -> (&'static str, &'static str) {
    match scene {
        "cow" => ("0.03", "5"),
        "maxplanck" => ("0.3", "47"),
        _ => ("–", "–"),
    }
}

/// The thread counts to time, ascending and distinct: those asked for, or 1
/// and `all` (just 1 on a one-thread machine).
fn thread_counts(asked: &[usize], all: usize) -> Result<Vec<usize>> {
    let mut v: Vec<usize> = if asked.is_empty() { vec![1, all] } else { asked.to_vec() };
    if let Some(bad) = v.iter().find(|&&t| t == 0 || t > MAX_THREADS) {
        return Err(Error::new(format!("bench: --threads {bad}: a thread count must be 1 to {MAX_THREADS}")));
    }
    v.sort_unstable();
    v.dedup();
    Ok(v)
}

