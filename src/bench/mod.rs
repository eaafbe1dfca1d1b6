//! `pathtracer bench`: BVH build time, memory and ray throughput per backend,
//! CS184's with/without-BVH render timing, and full path-traced renders per
//! backend, printed as Markdown tables.
//!
//! The ray sets are public so the cross-check tests trace exactly what the
//! benchmark times.

use crate::accel::{self, BackendKind, Traversal};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::ray::Ray;
use crate::light::Lights;
use crate::render::{self, normals::NormalShading, path::{specular_guide::{self, SpecularGuide}, PathTracer}, RenderSettings};
use crate::scene::{Scene, TriangleMesh};
use clap::Args;
use glam::Vec3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

mod rays;
pub mod scenes;
mod tables;
mod timing;

pub use rays::{camera_rays, diffuse_rays, random_rays, shadow_rays, tile_order};
pub use timing::PASSES;
use timing::{throughput, throughputs, RayKind, RaySet, TIMED};

pub use tables::Sample;
use tables::{ratio_table, scaling_table};

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
    /// path tracing of CBbunny, CBspheres_lambertian, CBspheres and CBgems at 64 spp, -m 5)
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

/// A closed lat-long unit sphere with `2 * segments * rings` triangles
/// (the pole triangles are degenerate, as in Embree's measurements).
pub fn lat_long_sphere(segments: u32, rings: u32) -> TriangleMesh {
    let mut m = TriangleMesh::default();
    for j in 0..=rings {
        let th = std::f32::consts::PI * j as f32 / rings as f32;
        for i in 0..=segments {
            let ph = 2.0 * std::f32::consts::PI * (i % segments) as f32 / segments as f32;
            m.positions.push(Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin()));
        }
    }
    let row = segments + 1;
    for j in 0..rings {
        for i in 0..segments {
            let (a, b, c, d) = (j * row + i, j * row + i + 1, (j + 1) * row + i, (j + 1) * row + i + 1);
            m.triangles.push([a, c, b]);
            m.triangles.push([b, c, d]);
        }
    }
    m.compute_normals();
    m
}

/// The `sphere:n` scene (a lat-long sphere of about `n` triangles seen
/// from +z), for tests.
pub fn procedural_scene(n: usize) -> Scene {
    scenes::generate(&format!("sphere:{n}")).expect("sphere is a generator").expect("a valid sphere count")
}

/// A scene file or name (see `find_scene`), or a generator spec (`scenes`).
pub fn load_bench_scene(name: &str) -> Result<Scene> {
    if !Path::new(name).exists() {
        if let Some(s) = scenes::generate(name) {
            return s;
        }
    }
    crate::scene::load_file(&find_scene(name)?)
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
    fn build(self, scene: &Scene, threads: usize) -> Result<accel::Built> {
        match self {
            Contender::Backend(k) => accel::build_with(k, &scene.shapes, &accel::BuildOptions { threads, native: accel::NativeOptions::from_env()? }),
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


/// Each Embree's batch calls compared on one thread (which ones the backend
/// uses for coherent and incoherent batches were chosen from these numbers,
/// `embree::Major::default_batch_modes`), and the best of them per ray kind
/// pushed to `best`, so that native is compared with each Embree at its best
/// and not only with the calls the backend uses. Every call of the major
/// (a loop of single rays; Embree 3's streams; packets of 4, 8 and 16) is
/// timed with the coherent flag for camera and shadow rays and with the
/// incoherent flag for every ray kind: on the large meshes Embree 3's
/// incoherent stream is its fastest shadow call (1 thread, Mrays/s, coherent
/// / incoherent stream: sphere:1M 6.39 / 8.95, grass:500k 0.60 / 1.21,
/// subdiv:bunny:500k 4.72 / 7.58; cow 26.0 / 16.1).
#[cfg(has_embree)]
fn embree_modes(
    major: crate::accel::embree::Major,
    scene: &Scene,
    cam: &[Ray],
    rnd: &[Ray],
    shadow: &[Ray],
    diffuse: &[Ray],
    rows: &mut String,
    best: &mut Vec<(String, &'static str, Contender, f64)>,
) -> Result<()> {
    use crate::accel::embree::{BatchMode, EmbreeBackend, Quality};
    let mut e = EmbreeBackend::build(major, &scene.shapes, 1, Quality::Medium)?;
    let contender = Contender::Backend(if major == crate::accel::embree::Major::V3 { BackendKind::Embree3 } else { BackendKind::Embree4 });
    for (label, rays, coherent, incoherent) in [
        ("camera", cam, Some(RayKind::Camera), RayKind::Random),
        ("shadow", shadow, Some(RayKind::Shadow), RayKind::ShadowIncoherent),
        ("random", rnd, None, RayKind::Random),
        ("diffuse", diffuse, None, RayKind::Random),
    ] {
        let mut cells = Vec::new();
        let mut top = 0.0f64;
        for &mode in BatchMode::all(major) {
            e.set_batch_modes(mode, mode);
            for kind in [coherent, Some(incoherent)] {
                let m = kind.map(|k| throughput(&e, rays, k, 1, 3));
                if let Some(m) = m {
                    top = top.max(m);
                }
                cells.push(m.map_or("–".to_string(), |m| format!("{m:.2}")));
            }
        }
        best.push((scene.name.clone(), label, contender, top));
        let _ = writeln!(rows, "| {} | embree{} | {label} | {} |", scene.name, major.number(), cells.join(" | "));
    }
    Ok(())
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
        let built = accel::build_with(kind, &scene.shapes, &accel::BuildOptions { threads, native: accel::NativeOptions::from_env()? })?;
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

pub fn run(args: &BenchArgs) -> Result<()> {
    let all = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    let backends: Vec<BackendKind> = if args.backends.is_empty() {
        let mut v = vec![BackendKind::Native];
        if accel::embree::available(accel::embree::Major::V3) {
            v.extend([BackendKind::Embree3, BackendKind::Embree3High]);
        }
        if accel::embree::available(accel::embree::Major::V4) {
            v.extend([BackendKind::Embree4, BackendKind::Embree4High]);
        }
        v.push(BackendKind::Brute);
        v
    } else {
        args.backends.clone()
    };
    // Ours first, then the peers, brute force last.
    let mut contenders: Vec<Contender> = backends.iter().filter(|&&k| k != BackendKind::Brute).map(|&k| Contender::Backend(k)).collect();
    if !args.no_peers {
        contenders.extend(peers());
    }
    if backends.contains(&BackendKind::Brute) {
        contenders.push(Contender::Backend(BackendKind::Brute));
    }
    let brute = Contender::Backend(BackendKind::Brute);
    let names: Vec<String> = if args.scenes.is_empty() { DEFAULT_SCENES.iter().map(|s| s.to_string()).collect() } else { args.scenes.clone() };
    let thread_counts = thread_counts(&args.threads, all)?;
    let no_render = args.no_render || args.throughput_only;
    let threads_said = thread_counts.iter().map(|t| t.to_string()).collect::<Vec<_>>().join(", ");
    let mut md = String::new();
    let mut samples: Vec<Sample> = Vec::new();
    let _ = writeln!(md, "Machine: {}, {all} threads.\n", cpu_model());
    let _ = writeln!(md, "Throughput in Mrays/s (best of {} passes after an untimed one, the contenders' passes alternating; brute: one pass on a 1/32 subset). Threads: {threads_said}. Build: best of {BUILD_REPS} builds on {all} threads.\n", args.passes);
    let _ = write!(md, "| scene | prims | backend | build ms | MiB | B/prim |");
    for rays in timing::labels() {
        for t in &thread_counts {
            let _ = write!(md, " {rays} {t}T |");
        }
    }
    let _ = writeln!(md, "\n|---|---:|---|---:|---:|---:|{}", "---:|".repeat(TIMED.len() * thread_counts.len()));
    let mut render_rows = String::new();
    let mut sah_rows = String::new();
    #[allow(unused_mut)]
    let mut mode_rows = String::new();
    #[allow(unused_mut)]
    let mut embree_best: Vec<(String, &'static str, Contender, f64)> = Vec::new();
    // The Embree majors timed: their SAH costs and batch calls are tabled.
    let majors: Vec<accel::embree::Major> = accel::embree::Major::ALL
        .into_iter()
        .filter(|&m| backends.iter().any(|b| b.embree().and_then(|r| r.ok()).is_some_and(|(mm, _)| mm == m)))
        .collect();
    for name in &names {
        let scene = load_bench_scene(name)?;
        let prims = scene.primitive_count();
        let camera = Camera::from_scene(&scene);
        // 1024x768 camera rays (repeated up to `--rays`); fewer rays make a
        // smaller image of the whole frame, so shadow rays still start on
        // what the camera sees.
        let (w, h) = if args.rays >= 1024 * 768 {
            (1024, 768)
        } else {
            let w = ((args.rays as f64 * 4.0 / 3.0).sqrt() as u32).max(4);
            (w, (args.rays as u32 / w).max(3))
        };
        let cam_all = camera_rays(&camera, w, h);
        let cam: Vec<Ray> = cam_all.iter().cycle().take(args.rays).copied().collect();
        let rnd = random_rays(&scene, args.rays, 1);
        // Build times: the best of BUILD_REPS rounds, each building every
        // backend once in turn, so that neither is charged alone for
        // first-touch costs (fresh pages from the OS, Embree starting its
        // TBB threads) or for a noisy stretch of a shared machine. Timed
        // one backend after the other, whichever came first was 5-10 ms
        // slower on the 1M-triangle mesh.
        let mut build_times: std::collections::HashMap<Contender, f64> = Default::default();
        for _ in 0..BUILD_REPS {
            for &kind in contenders.iter().filter(|&&k| k != brute) {
                if let Ok(b) = kind.build(&scene, all) {
                    let t = build_times.entry(kind).or_insert(f64::INFINITY);
                    *t = t.min(b.build_seconds);
                }
            }
        }
        // Every contender built and held at once, so that their passes can
        // alternate (`throughputs`).
        let mut built: Vec<(Contender, accel::Built)> = Vec::new();
        for &kind in &contenders {
            if kind == brute && prims > BRUTE_LIMIT {
                continue;
            }
            match kind.build(&scene, all) {
                Ok(b) => built.push((kind, b)),
                Err(e) => eprintln!("bench: {}: {kind}: {e}", scene.name),
            }
        }
        let Some((_, first)) = built.first() else { continue };
        // Repeated up to `--rays` as the camera rays are: only the camera
        // rays that hit make shadow rays (7 % of them on arch), and a pass of
        // 60k rays (under a millisecond) timed mostly the thread pool's
        // start at 2 threads (arch:500k shadow rays 91 Mrays/s at 1 and 2
        // threads alike, Embree 70 and 69).
        let shadow = shadow_rays(&scene, first.accel.as_ref(), &cam);
        let shadow: Vec<Ray> = if shadow.is_empty() { shadow } else { shadow.iter().cycle().take(args.rays).copied().collect() };
        // Diffuse rays from the same hits, repeated up to `--rays` alike.
        let tiles = tile_order(&cam_all, w, h, crate::render::TILE);
        let diffuse = diffuse_rays(&scene, first.accel.as_ref(), &tiles, 7);
        let diffuse: Vec<Ray> = if diffuse.is_empty() { diffuse } else { diffuse.iter().cycle().take(args.rays).copied().collect() };
        let timed: Vec<&dyn Traversal> = built.iter().filter(|(k, _)| *k != brute).map(|(_, b)| b.accel.as_ref()).collect();
        let mut cells: Vec<Vec<f64>> = vec![Vec::new(); built.len()];
        for (label, set, rk) in TIMED {
            let rays = match set {
                RaySet::Camera => &cam,
                RaySet::Shadow => &shadow,
                RaySet::Random => &rnd,
                RaySet::Diffuse => &diffuse,
            };
            for &t in &thread_counts {
                let mut speeds = throughputs(&timed, rays, rk, t, args.passes).into_iter();
                for (i, (kind, b)) in built.iter().enumerate() {
                    // Brute force: one pass over every 32nd ray.
                    let m = if *kind == brute {
                        throughput(b.accel.as_ref(), &rays.iter().step_by(32).copied().collect::<Vec<_>>(), rk, t, 1)
                    } else {
                        speeds.next().expect("one speed per timed contender")
                    };
                    samples.push(Sample { scene: scene.name.clone(), rays: label, threads: t, backend: *kind, mrays_per_s: m });
                    cells[i].push(m);
                }
            }
        }
        for &kind in &contenders {
            if kind == brute && prims > BRUTE_LIMIT {
                let _ = writeln!(md, "| {} | {} | brute | – | – | – | skipped above {} primitives |{}", scene.name, prims, BRUTE_LIMIT, " |".repeat(TIMED.len() * thread_counts.len() - 1));
                continue;
            }
            let Some(i) = built.iter().position(|(k, _)| *k == kind) else { continue };
            let a = built[i].1.accel.as_ref();
            let best_build = build_times.get(&kind).copied().unwrap_or(built[i].1.build_seconds);
            if let Some((nodes, leaves)) = a.sah_cost() {
                let total = nodes + leaves;
                let mut cells = String::new();
                for major in accel::embree::Major::ALL {
                    let e = if majors.contains(&major) && !args.throughput_only { embree_sah(name, major) } else { None };
                    let (e, r) = e.map_or(("–".to_string(), "–".to_string()), |e| (format!("{e:.3}"), format!("{:.3}", total / e)));
                    let _ = write!(cells, " {e} | {r} |");
                }
                let _ = writeln!(sah_rows, "| {} | {} | {:.3} | {:.3} | {:.3} |{cells}", scene.name, kind, nodes, leaves, total);
            }
            let mem = a.memory_bytes() as f64;
            let _ = writeln!(
                md,
                "| {} | {} | {} | {:.1} | {:.1} | {:.1} | {} |",
                scene.name,
                prims,
                kind,
                best_build * 1e3,
                mem / (1024.0 * 1024.0),
                mem / prims.max(1) as f64,
                cells[i].iter().map(|c| if *c < 0.1 { format!("{c:.4}") } else { format!("{c:.2}") }).collect::<Vec<_>>().join(" | ")
            );
        }
        drop(built);
        #[cfg(has_embree)]
        if !args.throughput_only {
            for &major in &majors {
                embree_modes(major, &scene, &cam, &rnd, &shadow, &diffuse, &mut mode_rows, &mut embree_best)?;
            }
        }
        if !no_render && !scene.source.starts_with("<generated") {
            let mut times = Vec::new();
            for kind in [BackendKind::Native, BackendKind::Brute] {
                let built = accel::build(kind, &scene.shapes, all)?;
                let mut cam = camera.clone();
                cam.set_screen_size(480, 360);
                let integ = NormalShading { scene: &scene };
                let settings = RenderSettings::new(480, 360, 1, 0);
                let out = render::render(&cam, built.accel.as_ref(), &integ, &settings);
                times.push(out.seconds);
            }
            let (seed_bvh, seed_brute) = seed_timing(&scene.name);
            let _ = writeln!(
                render_rows,
                "| {} | {} | {:.3} | {:.2} | {:.0}x | {} | {} |",
                scene.name,
                prims,
                times[0],
                times[1],
                times[1] / times[0],
                seed_bvh,
                seed_brute
            );
        }
    }
    for other in contenders.iter().copied().filter(|&c| c != brute && c != Contender::Backend(BackendKind::Native)) {
        let ratios = ratio_table(&samples, &thread_counts, other);
        if !ratios.is_empty() {
            let _ = writeln!(md, "\nnative ÷ {other} throughput, from this run:\n");
            md.push_str(&ratios);
        }
    }
    if thread_counts.len() > 2 {
        let _ = writeln!(md, "\nThroughput against threads, Mrays/s, from this run (efficiency: speed-up ÷ thread ratio):\n");
        md.push_str(&scaling_table(&samples, &thread_counts));
    }
    if !sah_rows.is_empty() {
        let _ = writeln!(
            md,
            "\nSAH cost of the native tree, counted as Embree's BVH statistics count it: \
             expected node visits + expected 4-triangle block tests per ray through the root box. Embree's total is read from its own \
             statistics (a child `pathtracer bench` run with PATHTRACER_EMBREE_CONFIG=verbose=2, line `total : sah = ...`):\n"
        );
        let _ = writeln!(md, "| scene | backend | nodes | leaves | total | Embree 3 total | native ÷ Embree 3 | Embree 4 total | native ÷ Embree 4 |");
        let _ = writeln!(md, "|---|---|---:|---:|---:|---:|---:|---:|---:|");
        md.push_str(&sah_rows);
    }
    if !mode_rows.is_empty() {
        let _ = writeln!(
            md,
            "\nEmbree batch calls, 1 thread, Mrays/s: each call with the coherent flag (camera and shadow rays) and with the incoherent \
             flag (c / i); the loop of rtcIntersect1, Embree 3's rtcIntersect1M stream (Embree 4 has none: –), rtcIntersect4/8/16 packets:\n"
        );
        let _ = writeln!(md, "| scene | embree | rays | loop c | loop i | stream c | stream i | packet4 c | packet4 i | packet8 c | packet8 i | packet16 c | packet16 i |");
        let _ = writeln!(md, "|---|---|---|{}", "---:|".repeat(10));
        // Embree 4's rows have no stream columns: put dashes in their place.
        for line in mode_rows.lines() {
            if line.contains("| embree4 |") {
                let cells: Vec<&str> = line.split(" | ").collect();
                // scene, embree4, rays, loop c, loop i, then packets.
                let mut fixed = cells[..5].to_vec();
                fixed.extend(["–", "–"]);
                fixed.extend(&cells[5..]);
                let _ = writeln!(md, "{}", fixed.join(" | "));
            } else {
                let _ = writeln!(md, "{line}");
            }
        }
        let _ = writeln!(md, "\nnative ÷ each Embree's fastest batch call above (the best of its columns), 1 thread, from this run:\n");
        md.push_str(&tables::best_call_table(&samples, &embree_best));
    }
    if !render_rows.is_empty() {
        let _ = writeln!(md, "\nNormal-shading render, 480x360, 1 spp, {all} threads (seconds; seed: CS184 write-up, settings unknown):\n");
        let _ = writeln!(md, "| scene | prims | with BVH | without BVH | speed-up | seed with BVH | seed without |");
        let _ = writeln!(md, "|---|---:|---:|---:|---:|---:|---:|");
        md.push_str(&render_rows);
    }
    if !no_render {
        let backends: Vec<BackendKind> = backends.iter().copied().filter(|b| *b != BackendKind::Brute).collect();
        let _ = writeln!(
            md,
            "\nPath-traced render, 480x360 (CS184 crop), 64 spp, -m 5, seed 1, {all} threads: rays traced in batches (the renderer's \
             default: each sample round of a tile traces its camera rays as one coherent batch, then bounce by bounce its shadow rays \
             as one batch and its other rays as another) or one at a time. Image: compared with the scene's first row, pixel by pixel:\n"
        );
        let _ = writeln!(md, "| scene | backend | rays traced | render s | rays | Mrays/s | image |");
        let _ = writeln!(md, "|---|---|---|---:|---:|---:|---|");
        for name in RENDER_SCENES {
            md.push_str(&path_render_rows(name, &backends, all)?);
        }
    }
    print!("{md}");
    if let Some(p) = &args.markdown {
        crate::image_io::write_text(p, &md)?;
    }
    if let Some(p) = &args.csv {
        let mut csv = String::from("scene,rays,threads,backend,mrays_per_s\n");
        for s in &samples {
            let _ = writeln!(csv, "{},{},{},{},{:.4}", s.scene, s.rays, s.threads, s.backend, s.mrays_per_s);
        }
        crate::image_io::write_text(p, &csv)?;
    }
    Ok(())
}
