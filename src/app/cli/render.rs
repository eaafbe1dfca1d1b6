//! `pathtracer [SCENE] [FLAGS]`: a render from the checked flags — the
//! scene loaded, the job prepared (`render::job::Job`), the backend built,
//! the image rendered, then the images written (or, for one part of a split
//! render, its partial) and the summary line printed.

use super::args::RenderArgs;
use super::flags::{check_flags, Flags, Part};
use crate::accel;
use crate::app::images;
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::image_io;
use crate::render::job::Job;
use crate::render::{RenderOutput, RenderSettings};
use crate::scene::{builtin, Scene};
use clap::ValueEnum;
use std::path::{Path, PathBuf};
use std::time::Instant;

pub(super) fn run_render(a: &RenderArgs) -> Result<()> {
    let f = check_flags(a).map_err(Error::into_usage)?;
    let threads = init_threads(a.threads)?;
    let scene = load_scene(a.scene.as_deref())?;
    let camera = setup_camera(a, &scene, f.width, f.height, f.lens)?;
    if let Some(p) = &a.write_camera {
        image_io::write_text(p, &camera.to_settings())?;
    }
    let job = Job::new(scene, camera, load_environment(a)?, f.sampling, f.spec)?;
    for note in job.notes.iter().chain(&f.batch_note) {
        eprintln!("{}: {note}", job.scene.name);
    }
    let mut options = crate::app::build_options(threads)?;
    options.native.expected_rays = f.expected_rays();
    let built = accel::build_with(a.backend, &job.scene.shapes, &options)?;
    let settings = settings(&f, a.seed);
    let start = Instant::now();
    let out = job.render(built.accel.as_ref(), &settings)?;
    let render_s = start.elapsed().as_secs_f64();
    if out.bad_samples > 0 {
        eprintln!("{}: warning: {} samples had a NaN or out-of-range value (counted as 0 or ±2^36)", job.scene.name, out.bad_samples);
    }
    let summary = timings(&built, render_s, out.rays);
    match &f.part {
        Some(p) => write_part(a, &job, &settings, p, &out, render_s, &summary, threads),
        None => write_images(a, &job, &f, &out, &summary, threads),
    }
}

/// The settings of the image loop from the checked flags.
fn settings(f: &Flags, seed: u64) -> RenderSettings {
    let mut s = RenderSettings::new(f.width, f.height, f.spp, seed);
    s.region = f.region;
    s.adaptive = f.adaptive;
    s.progress = progress_wanted();
    s.sampler = f.sampler;
    if let Some(p) = &f.part {
        s.share = p.share;
        s.keep_sums = true;
    }
    s
}

/// One part of a split render: its partial, and the summary line.
#[allow(clippy::too_many_arguments)]
fn write_part(a: &RenderArgs, job: &Job, settings: &RenderSettings, p: &Part, out: &RenderOutput, render_s: f64, summary: &str, threads: usize) -> Result<()> {
    let header = crate::partial::Header {
        settings: partial_settings(a, job, settings, p.kind)?,
        index: p.index,
        count: p.count,
        rays: out.rays,
        render_seconds: render_s,
        cpu_seconds: crate::partial::process_cpu_seconds(),
        bad_samples: out.bad_samples,
    };
    let path = a.partial.as_deref().expect("clap requires --partial with --part");
    crate::partial::write(path, &header, &out.sums, &out.splats)?;
    println!("{} | part {}/{} ({} split) | {summary} | {threads} threads | wrote {}", job.scene.name, p.index, p.count, p.kind.name(), path.display());
    Ok(())
}

/// The whole render's images, and the summary line.
fn write_images(a: &RenderArgs, job: &Job, f: &Flags, out: &RenderOutput, summary: &str, threads: usize) -> Result<()> {
    let output = a.output.clone().unwrap_or_else(|| PathBuf::from(format!("{}.png", job.scene.name)));
    // The rate image (CS184 writes it beside every -f output) only where
    // adaptive sampling ran: elsewhere every pixel took -s samples.
    let written = images::write_images(out, &output, a.output.is_some() && f.adaptive.is_some(), a.exr.as_deref(), a.variance_exr.as_deref(), f.spp)?;
    // With -a, how many samples the pixels kept (their mean per pixel):
    // what adaptive sampling saved against -s.
    let kept = match f.adaptive {
        Some(_) => {
            let total: u64 = out.samples.iter().map(|&n| n as u64).sum();
            format!(" | {total} samples kept ({:.1}/px of {})", total as f64 / out.samples.len().max(1) as f64, f.spp)
        }
        None => String::new(),
    };
    println!("{} | {} primitives | {summary}{kept} | {threads} threads | wrote {}", job.scene.name, job.scene.primitive_count(), written.join(", "));
    Ok(())
}

/// Everything that changes a split render's image, for its partials'
/// headers: parts that differ in any of it are refused by `merge`.
fn partial_settings(a: &RenderArgs, job: &Job, s: &RenderSettings, kind: crate::partial::SplitKind) -> Result<Vec<(String, String)>> {
    let (scene, camera) = (&job.scene, &job.camera);
    use crate::partial::sha256_hex;
    let file_hash = |p: &Path| -> Result<String> {
        std::fs::read(p).map(|b| sha256_hex(&b)).map_err(|e| Error::new(format!("{}: cannot read: {e}", p.display())))
    };
    let scene_hash = match &a.scene {
        Some(p) => file_hash(p)?,
        None => sha256_hex(builtin::TEXT.as_bytes()),
    };
    let env_hash = a.environment.as_deref().map(file_hash).transpose()?.unwrap_or_else(|| "none".into());
    let r = s.region();
    let adaptive = match s.adaptive {
        None => "none".to_string(),
        Some(ad) => format!("{} {:e} {}", ad.batch, ad.tolerance, if ad.pilot { "pilot" } else { "cs184" }),
    };
    let kv = |k: &str, v: String| (k.to_string(), v);
    let mut fields = vec![
        kv("pathtracer", env!("CARGO_PKG_VERSION").to_string()),
        kv("scene", scene.name.clone()),
        kv("scene_sha256", scene_hash),
        kv("environment_sha256", env_hash),
        kv("camera", camera.to_settings().trim_end().replace('\n', " / ")),
        kv("width", s.width.to_string()),
        kv("height", s.height.to_string()),
        kv("region", format!("{} {} {} {}", r.x, r.y, r.w, r.h)),
        kv("spp", s.spp.to_string()),
        kv("seed", s.seed.to_string()),
        kv("sampler", a.sampler.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default()),
        kv("light_sampling", a.light_sampling.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default()),
        kv("sky_sampling", a.sky_sampling.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default()),
        kv("env_sampling", a.env_sampling.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default()),
        kv("specular_guide", a.specular_guide.to_string()),
        kv("light_pick", a.light_pick.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default()),
        kv("adaptive", adaptive),
    ];
    // The integrator's options, as its spec records them.
    fields.extend(job.spec.header_fields().into_iter().map(|(k, v)| kv(k, v)));
    fields.push(kv("backend", a.backend.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default()));
    fields.push(kv("split", kind.name().to_string()));
    Ok(fields)
}

/// The summary line's backend, build, render and ray-throughput fields.
fn timings(built: &accel::Built, render_s: f64, rays: u64) -> String {
    format!(
        "backend {} | BVH build {:.3} s | render {:.3} s | {rays} rays | {:.2} Mrays/s",
        built.accel.describe(),
        built.build_seconds,
        render_s,
        rays as f64 / render_s.max(1e-9) / 1e6
    )
}

/// Whether to draw a progress bar: only on a terminal, never under CI.
fn progress_wanted() -> bool {
    use std::io::IsTerminal;
    std::io::stderr().is_terminal() && std::env::var_os("CI").is_none()
}

/// Configure the global rayon pool (`-t`; absent means all cores).
pub fn init_threads(threads: Option<usize>) -> Result<usize> {
    let n = match threads {
        None => std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        Some(0) => crate::bail!("-t 0: the thread count must be at least 1"),
        Some(n) if n > 4096 => crate::bail!("-t {n}: too many threads"),
        Some(n) => n,
    };
    // A second call (tests) finds the pool already built; that is fine.
    let _ = rayon::ThreadPoolBuilder::new().num_threads(n).build_global();
    Ok(n)
}

pub fn load_scene(path: Option<&Path>) -> Result<Scene> {
    match path {
        None => builtin::load(),
        Some(p) => {
            // A generator spec (arch:1M) unless a file of that name exists.
            let generated = if p.exists() { None } else { crate::scene::generated::generate(&p.to_string_lossy(), &crate::app::bench::find_scene) };
            generated.unwrap_or_else(|| crate::scene::load_file(p))
        }
    }
}

/// The environment map of `-e`, loaded and tabulated for sampling.
pub(crate) fn load_environment(a: &RenderArgs) -> Result<Option<std::sync::Arc<crate::light::EnvMap>>> {
    a.environment.as_deref().map(|p| crate::light::EnvMap::load(p).map(std::sync::Arc::new)).transpose()
}

/// CS184's camera placement, then `-r` (crop, or scale with --keep-fov), then
/// `-c`, then `lens` (`-b`, `-d` from `lens_flags`).
pub(crate) fn setup_camera(a: &RenderArgs, scene: &Scene, width: u32, height: u32, lens: (Option<f32>, Option<f32>)) -> Result<Camera> {
    let mut camera = Camera::from_scene(scene);
    if a.resolution.is_some() {
        if a.keep_fov {
            camera.resize_keep_fov(width, height);
        } else {
            camera.set_screen_size(width, height);
        }
    }
    if let Some(c) = &a.camera {
        camera.load_settings(c)?;
        // The frame size comes from -r (or 800x600), not from the file.
        camera.screen_w = width;
        camera.screen_h = height;
    }
    // -b and -d on the command line win over a camera file's values.
    let (b, d) = lens;
    if let Some(b) = b {
        camera.lens_radius = b;
    }
    if let Some(d) = d {
        camera.focal_distance = d;
    }
    Ok(camera)
}
