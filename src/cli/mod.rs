//! The command line: CS184's flags plus ours (defined in `args`), one-line
//! errors, the summary line.

mod args;
pub mod docs;

pub use args::{BdptLightPaths, Cli, Command, EnvSamplingArg, IntegratorKind, LightPickArg, LightSamplingArg, RenderArgs, SamplerArg, SkySamplingArg, SplitArg};

use crate::accel;
use crate::camera::{Camera, DEFAULT_HEIGHT, DEFAULT_WIDTH};
use crate::error::{Error, Result};
use crate::image_io;
use crate::light::Lights;
use crate::render::bdpt::{Bdpt, LightPaths, Technique};
use crate::render::{self, aov, normals::NormalShading, path::{specular_guide::SpecularGuide, PathTracer}, Adaptive, Integrator, Region, RenderSettings};
use crate::scene::Bsdf;
use crate::scene::{builtin, Scene};
use clap::ValueEnum;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

const DEMO_SPP: u32 = 16;
const DEMO_DEPTH: u32 = 5;

/// Entry point for the binary: one line on error, non-zero exit, no panic.
pub fn main() -> ExitCode {
    // Die quietly on a closed pipe (`pathtracer ... | head`), as Unix tools do,
    // instead of panicking in println!.
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of one signal before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    match parse(std::env::args_os()) {
        Ok(Some(cli)) => match run(cli) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("pathtracer: error: {e}");
                ExitCode::from(if e.is_usage() { 2 } else { 1 })
            }
        },
        Ok(None) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("pathtracer: error: {e}");
            ExitCode::from(2)
        }
    }
}

/// "0.1.0 (commit 1a2b3c4d5e6f)": the version and the commit the binary was
/// built from ("+ changes" where its sources differed from the commit).
pub fn version_line() -> String {
    format!("{} ({})", env!("CARGO_PKG_VERSION"), env!("PATHTRACER_GIT_COMMIT"))
}

/// Parse a command line (the program name first). `Ok(None)` when clap
/// printed the help or the version; a bad command line is one line.
pub fn parse<I, T>(args: I) -> Result<Option<Cli>>
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    use clap::FromArgMatches;
    let args: Vec<T> = args.into_iter().collect();
    let bare = args.len() == 1;
    let os: Vec<std::ffi::OsString> = args.iter().cloned().map(Into::into).collect();
    let command = docs::command_for(&os);
    if let Some(first) = os.get(1) {
        not_a_command(&command, first)?;
    }
    match command.try_get_matches_from(os.iter()).and_then(|m| Cli::from_arg_matches(&m)) {
        Ok(c) => Ok(Some(Cli { bare, ..c })),
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
                let _ = e.print();
                return Ok(None);
            }
            Err(Error::new(format!("{} (see pathtracer --help)", usage_error(&e))))
        }
    }
}

/// A first argument that is neither a command nor a scene: a word with no
/// extension that names no file, such as a mistyped `merg`. Left to clap,
/// it would be read as the scene and the next argument as a command.
fn not_a_command(command: &clap::Command, first: &std::ffi::OsStr) -> Result<()> {
    let Some(word) = first.to_str() else { return Ok(()) };
    let path = Path::new(word);
    let looks_like_scene = word.starts_with('-') || path.exists() || path.extension().is_some() || word.contains(['/', ':']);
    let names: Vec<&str> = command.get_subcommands().filter(|s| !s.is_hide_set()).map(|s| s.get_name()).filter(|n| *n != "help").collect();
    if looks_like_scene || command.find_subcommand(word).is_some() || word == "help" {
        return Ok(());
    }
    let near = names.iter().copied().filter(|n| n.starts_with(word) || edit_distance(n, word) <= 2).min_by_key(|n| edit_distance(n, word));
    match near {
        Some(n) => crate::bail!("'{word}' is not a command; did you mean '{n}'? (commands: {})", names.join(", ")),
        None => crate::bail!("'{word}' is neither a command ({}) nor a scene file ({})", names.join(", "), crate::scene::FORMATS),
    }
}

/// Levenshtein distance, for suggesting a command.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

/// clap's parse error as one line saying what was wrong and what is
/// accepted, without clap's own hints (its "try --help" and its tip to
/// write `-- -1`, which this command line would read as a scene).
fn usage_error(e: &clap::Error) -> String {
    use clap::error::{ContextKind, ContextValue, ErrorKind};
    let get = |k: ContextKind| match e.get(k) {
        Some(ContextValue::String(s)) => Some(s.clone()),
        Some(ContextValue::Strings(v)) => Some(v.join(", ")),
        _ => None,
    };
    // "-s <N>" -> "-s": the flag as the user typed it.
    let arg = get(ContextKind::InvalidArg).map(|a| a.split([' ', '=']).next().unwrap_or_default().to_string()).unwrap_or_default();
    let value = get(ContextKind::InvalidValue).unwrap_or_default();
    let suggestion = get(ContextKind::SuggestedArg)
        .or_else(|| get(ContextKind::SuggestedSubcommand))
        .or_else(|| get(ContextKind::SuggestedValue))
        .map(|s| format!("; did you mean '{s}'?"))
        .unwrap_or_default();
    match e.kind() {
        ErrorKind::InvalidValue if value.is_empty() => format!("{arg}: a value is required"),
        ErrorKind::InvalidValue => match get(ContextKind::ValidValue) {
            Some(valid) => format!("{arg} {value}: not one of {valid}{suggestion}"),
            None => format!("{arg} {value}: not a valid value"),
        },
        ErrorKind::ValueValidation => {
            use std::error::Error as _;
            let source = e.source();
            let why = if let Some(p) = source.and_then(|s| s.downcast_ref::<std::num::ParseIntError>()) {
                use std::num::IntErrorKind::*;
                match p.kind() {
                    InvalidDigit if value.starts_with('-') => "expected a number of 0 or more".to_string(),
                    InvalidDigit => "expected a whole number".to_string(),
                    PosOverflow | NegOverflow => "the number is too large".to_string(),
                    Empty => "a value is required".to_string(),
                    _ => p.to_string(),
                }
            } else if source.is_some_and(|s| s.is::<std::num::ParseFloatError>()) {
                "expected a number".to_string()
            } else {
                source.map(|s| s.to_string()).unwrap_or_else(|| "not a valid value".into())
            };
            format!("{arg} {value}: {why}")
        }
        ErrorKind::UnknownArgument => format!("unknown option '{arg}'{suggestion}"),
        ErrorKind::InvalidSubcommand => format!("'{arg}' is not a command{suggestion}"),
        ErrorKind::WrongNumberOfValues | ErrorKind::TooFewValues | ErrorKind::TooManyValues => match e.get(ContextKind::ExpectedNumValues) {
            Some(ContextValue::Number(n)) => format!("{arg}: expected {n} values"),
            _ => format!("{arg}: wrong number of values"),
        },
        _ => {
            // clap's message up to its usage block (with the argument names
            // it lists on the lines after the first), without its hints.
            let text = e.render().to_string();
            let message = text.split("\n\nUsage").next().unwrap_or("invalid arguments");
            let message = message.split("\n\n  tip:").next().unwrap_or_default();
            let joined = message.split_whitespace().collect::<Vec<_>>().join(" ");
            joined.trim_start_matches("error: ").to_string()
        }
    }
}

/// Run a parsed command line, as the binary does.
pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Some(Command::Bench(b)) => crate::bench::run(&b),
        Some(Command::Compare { reference, images }) => compare(&reference, &images),
        Some(Command::Merge { partials, output, exr, variance_exr }) => {
            crate::merge::run(&partials, &output, exr.as_deref(), variance_exr.as_deref())
        }
        Some(Command::Verify { partials }) => crate::merge::verify(&partials),
        Some(Command::Export { render, out }) => run_export(&render, &out),
        Some(Command::Completions { shell }) => {
            docs::completions(shell, &mut std::io::stdout());
            Ok(())
        }
        Some(Command::Man { out }) => {
            let written = docs::man_pages(&out)?;
            println!("wrote {} man pages: {}", written.len(), written.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "));
            Ok(())
        }
        Some(Command::CliReference) => {
            print!("{}", docs::reference_markdown());
            Ok(())
        }
        None if cli.bare => {
            // The demo render: CS184's defaults (1 spp, direct light only)
            // would give a noisy, flat picture of the built-in scene.
            eprintln!("no arguments: rendering the built-in scene with -s {DEMO_SPP} -m {DEMO_DEPTH}");
            let mut r = cli.render;
            r.spp = Some(DEMO_SPP);
            r.max_depth = Some(DEMO_DEPTH);
            run_render(&r)
        }
        None => run_render(&cli.render),
    }
}

fn parse_pair<T: std::str::FromStr>(v: &[String], flag: &str) -> Result<Vec<T>> {
    v.iter()
        .map(|s| s.parse::<T>().map_err(|_| Error::new(format!("{flag}: '{s}' is not a valid value"))))
        .collect()
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
            let generated = if p.exists() { None } else { crate::bench::scenes::generate(&p.to_string_lossy()) };
            generated.unwrap_or_else(|| crate::scene::load_file(p))
        }
    }
}

/// The render's flags, checked: every value in range, every combination
/// one the integrator supports. A failure here is a usage error (exit 2).
struct Flags {
    width: u32,
    height: u32,
    spp: u32,
    adaptive: Option<Adaptive>,
    batch_note: Option<String>,
    region: Option<Region>,
    light_samples: u32,
    max_depth: u32,
    accumulate: bool,
    lens: (Option<f32>, Option<f32>),
    part: Option<Part>,
    /// `--bdpt-strategy`, parsed.
    strategy: Option<Technique>,
}

fn check_flags(a: &RenderArgs) -> Result<Flags> {
    let (width, height) = frame_size(a)?;
    let spp = a.spp.unwrap_or(1);
    if spp == 0 || spp > 1 << 20 {
        crate::bail!("-s {spp}: samples per pixel must be between 1 and 1048576");
    }
    let mut batch_note = None;
    let adaptive = match &a.adaptive {
        None => None,
        Some(v) => {
            let batch: u32 = v[0].parse().map_err(|_| Error::new(format!("-a: batch '{}' is not a positive integer", v[0])))?;
            let tol: f32 = v[1].parse().map_err(|_| Error::new(format!("-a: tolerance '{}' is not a number", v[1])))?;
            if batch < 2 {
                crate::bail!("-a {batch} {tol}: the batch must be at least 2 samples");
            }
            if !(tol > 0.0 && tol.is_finite()) {
                crate::bail!("-a {batch} {tol}: the tolerance must be a positive number");
            }
            // Owen-scrambled Sobol points are stratified in aligned blocks of
            // 2^m samples: a pixel that stops (or, with the pilot rule, is
            // given) a multiple of a power-of-two batch keeps whole blocks.
            let batch = if a.sampler != SamplerArg::Independent && !batch.is_power_of_two() {
                let b = batch.checked_next_power_of_two().unwrap_or(1 << 31);
                batch_note = Some(format!("-a {batch}: Sobol samples are stratified in blocks of powers of two; checking every {b} samples"));
                b
            } else {
                batch
            };
            Some(Adaptive { batch, tolerance: tol, pilot: a.adaptive_pilot })
        }
    };
    let region = match &a.cell {
        None => None,
        Some(v) => {
            let c: Vec<u32> = parse_pair(v, "-p")?;
            let r = Region { x: c[0], y: c[1], w: c[2], h: c[3] };
            if r.w == 0 || r.h == 0 || r.x as u64 + r.w as u64 > width as u64 || r.y as u64 + r.h as u64 > height as u64 {
                crate::bail!("-p {} {} {} {}: the cell must lie inside the {width}x{height} frame", r.x, r.y, r.w, r.h);
            }
            Some(r)
        }
    };
    let transport = matches!(a.integrator, IntegratorKind::Path | IntegratorKind::Bdpt | IntegratorKind::Light);
    let bidirectional = matches!(a.integrator, IntegratorKind::Bdpt | IntegratorKind::Light);
    if bidirectional {
        let name = a.integrator.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default();
        let path_only = [
            (a.light_samples.is_some(), "-l"),
            (a.hemisphere, "-H"),
            (adaptive.is_some(), "-a (a pixel's stopping rule cannot see the light other pixels' samples splat into it)"),
            (a.split == Some(SplitArg::Tiles), "--split tiles (a tile's light subpaths light other tiles)"),
        ];
        if let Some((_, flag)) = path_only.iter().find(|(used, _)| *used) {
            crate::bail!("--integrator {name}: {flag} is not supported with this integrator; use --integrator path");
        }
    }
    if a.bdpt_strategy.is_some() && a.integrator != IntegratorKind::Bdpt {
        crate::bail!("--bdpt-strategy applies to --integrator bdpt");
    }
    if a.bdpt_light_paths.is_some() && a.integrator != IntegratorKind::Bdpt {
        crate::bail!("--bdpt-light-paths applies to --integrator bdpt");
    }
    if !transport {
        let lighting_flags = [
            (a.light_samples.is_some(), "-l"),
            (a.max_depth.is_some(), "-m"),
            (a.accumulate.is_some(), "-o"),
            (a.hemisphere, "-H"),
            (a.no_rr, "--no-rr"),
            (a.environment.is_some(), "-e"),
        ];
        if let Some((_, flag)) = lighting_flags.iter().find(|(used, _)| *used) {
            crate::bail!("{flag} applies to light transport; it has no effect with --integrator {}", a.integrator.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default());
        }
    }
    if !(0.0..0.95).contains(&a.specular_guide) {
        crate::bail!("--specular-guide {}: the share of guided bounce rays must be a number in [0, 0.95)", a.specular_guide);
    }
    let light_samples = a.light_samples.unwrap_or(1);
    if light_samples == 0 || light_samples > 1 << 16 {
        crate::bail!("-l {light_samples}: samples per light must be between 1 and 65536");
    }
    let max_depth = a.max_depth.unwrap_or(1);
    if max_depth > 100_000 {
        crate::bail!("-m {max_depth}: the maximum ray depth is 100000");
    }
    let accumulate = match a.accumulate {
        None => true,
        Some(v) if v == 0 || v == 1 => v == 1,
        Some(v) => crate::bail!("-o {v}: expected 0 (only bounce m) or 1 (accumulate)"),
    };
    let lens = lens_flags(a)?;
    check_output_names(a.output.as_deref(), a.exr.as_deref(), a.variance_exr.as_deref())?;
    let part = part_flags(a, spp, adaptive.is_some(), region.unwrap_or(Region { x: 0, y: 0, w: width, h: height }))?;
    if a.threads == Some(0) {
        crate::bail!("-t 0: the thread count must be at least 1 (without -t every core renders)");
    }
    let strategy = a.bdpt_strategy.as_deref().map(parse_strategy).transpose()?;
    Ok(Flags { width, height, spp, adaptive, batch_note, region, light_samples, max_depth, accumulate, lens, part, strategy })
}

fn run_render(a: &RenderArgs) -> Result<()> {
    // Validate every flag before doing any work.
    let Flags { width, height, spp, adaptive, batch_note, region, light_samples, max_depth, accumulate, lens, part, strategy } = check_flags(a).map_err(Error::into_usage)?;
    let threads = init_threads(a.threads)?;
    let native = accel::NativeOptions::from_env()?;

    let scene = load_scene(a.scene.as_deref())?;
    let camera = setup_camera(a, &scene, width, height, lens)?;
    let env = load_environment(a)?;
    let output = a.output.clone().unwrap_or_else(|| PathBuf::from(format!("{}.png", scene.name)));
    if let Some(p) = &a.write_camera {
        image_io::write_text(p, &camera.to_settings())?;
    }

    let lights = match a.integrator {
        IntegratorKind::Path | IntegratorKind::Bdpt | IntegratorKind::Light => {
            check_materials(&scene)?;
            let l = Lights::with_environment(&scene, env)?.with_sampling(a.light_sampling == LightSamplingArg::Area, a.sky_sampling == SkySamplingArg::Uniform).with_env_sampling(a.env_sampling != EnvSamplingArg::Map, a.env_sampling == EnvSamplingArg::Product).with_light_pick(&scene, a.light_pick == LightPickArg::One);
            if l.lights.is_empty() {
                // One line: the notes (a zero-radiance light dropped) go into it.
                let why = if l.notes.is_empty() { String::new() } else { format!(" ({})", l.notes.join("; ")) };
                eprintln!("{}: warning: the scene has no light{why}; the image will be black (an environment map, -e FILE.exr, would light it)", scene.name);
            } else {
                for note in &l.notes {
                    eprintln!("{}: {note}", scene.name);
                }
            }
            l
        }
        IntegratorKind::Normals | IntegratorKind::Depth | IntegratorKind::ObjectId => Lights::default(),
    };
    if let Some(note) = &batch_note {
        eprintln!("{}: {note}", scene.name);
    }
    // The path tracer's guide toward mirror, glass and metal objects.
    let guide = match a.integrator {
        IntegratorKind::Path => {
            let (guide, note) = SpecularGuide::of_scene(&scene, a.specular_guide);
            if let Some(note) = note {
                eprintln!("{}: {note}", scene.name);
            }
            guide
        }
        _ => None,
    };
    let options = accel::BuildOptions { threads, native };
    let built = accel::build_with(a.backend, &scene.shapes, &options)?;
    let integrator: Box<dyn Integrator> = match a.integrator {
        IntegratorKind::Normals => Box::new(NormalShading { scene: &scene }),
        IntegratorKind::Depth => Box::new(aov::Depth),
        IntegratorKind::ObjectId => Box::new(aov::ObjectId),
        IntegratorKind::Path => Box::new(PathTracer {
            scene: &scene,
            lights: &lights,
            guide: guide.as_ref(),
            max_depth,
            accumulate,
            hemisphere: a.hemisphere,
            light_samples,
            russian_roulette: !a.no_rr,
        }),
        IntegratorKind::Bdpt | IntegratorKind::Light => {
            let technique = match (strategy, a.integrator) {
                (_, IntegratorKind::Light) => Technique::LightTracing,
                (Some(t), _) => t,
                (None, _) => Technique::Bidirectional,
            };
            let region = region.unwrap_or(Region { x: 0, y: 0, w: width, h: height });
            let light_paths = match a.bdpt_light_paths {
                None | Some(BdptLightPaths::All) => LightPaths::All,
                Some(BdptLightPaths::Specular) => LightPaths::Specular,
            };
            Box::new(Bdpt::new(&scene, &lights, &camera, width, height, region, max_depth, accumulate, technique)?.with_light_paths(light_paths))
        }
    };
    let mut settings = RenderSettings::new(width, height, spp, a.seed);
    settings.region = region;
    settings.adaptive = adaptive;
    settings.progress = render::progress_wanted();
    settings.sampler = match a.sampler {
        SamplerArg::Sobol => crate::sampler::SamplerKind::Sobol,
        SamplerArg::SobolPadded => crate::sampler::SamplerKind::SobolPadded,
        SamplerArg::Independent => crate::sampler::SamplerKind::Independent,
    };
    if let Some(p) = &part {
        settings.share = p.share;
        settings.keep_sums = true;
    }
    let start = Instant::now();
    let out = render::render(&camera, built.accel.as_ref(), integrator.as_ref(), &settings);
    let render_s = start.elapsed().as_secs_f64();
    if out.bad_samples > 0 {
        eprintln!("{}: warning: {} samples had a NaN or out-of-range value (counted as 0 or ±2^36)", scene.name, out.bad_samples);
    }
    if let Some(p) = &part {
        let header = crate::partial::Header {
            settings: partial_settings(a, &scene, &camera, &settings, p.kind)?,
            index: p.index,
            count: p.count,
            rays: out.rays,
            render_seconds: render_s,
            cpu_seconds: crate::partial::process_cpu_seconds(),
            bad_samples: out.bad_samples,
        };
        let path = a.partial.as_deref().expect("clap requires --partial with --part");
        crate::partial::write(path, &header, &out.sums, &out.splats)?;
        println!(
            "{} | part {}/{} ({} split) | {} | {} threads | wrote {}",
            scene.name,
            p.index,
            p.count,
            p.kind.name(),
            timings(&built, render_s, out.rays),
            threads,
            path.display()
        );
        return Ok(());
    }

    // The rate image (CS184 writes it beside every -f output) only where
    // adaptive sampling ran: elsewhere every pixel took -s samples.
    let written = write_images(&out, &output, a.output.is_some() && adaptive.is_some(), a.exr.as_deref(), a.variance_exr.as_deref(), spp)?;
    // With -a, how many samples the pixels kept (their mean per pixel): what adaptive
    // sampling saved against -s.
    let kept = match adaptive {
        Some(_) => {
            let total: u64 = out.samples.iter().map(|&n| n as u64).sum();
            format!(" | {total} samples kept ({:.1}/px of {spp})", total as f64 / out.samples.len().max(1) as f64)
        }
        None => String::new(),
    };
    println!(
        "{} | {} primitives | {}{kept} | {} threads | wrote {}",
        scene.name,
        scene.primitive_count(),
        timings(&built, render_s, out.rays),
        threads,
        written.join(", ")
    );
    Ok(())
}

/// `--bdpt-strategy S,T[,weighted]`.
fn parse_strategy(text: &str) -> Result<Technique> {
    let w: Vec<&str> = text.split(',').map(str::trim).collect();
    let num = |x: &str| x.parse::<usize>().ok();
    match (w.len(), w.first().and_then(|x| num(x)), w.get(1).and_then(|x| num(x)), w.get(2).copied()) {
        (2 | 3, Some(s), Some(t), weighted) if t >= 1 && !(s == 1 && t == 1) && matches!(weighted, None | Some("weighted")) => {
            Ok(Technique::Strategy { s, t, weighted: weighted.is_some() })
        }
        _ => crate::bail!("--bdpt-strategy {text}: expected S,T or S,T,weighted with T >= 1 and (S,T) not (1,1) (S light vertices, T camera vertices)"),
    }
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

/// The output files' names, checked before any work: the image's extension
/// names its format (.png, .jpg, .jpeg), the EXRs end in .exr.
pub(crate) fn check_output_names(image: Option<&Path>, exr: Option<&Path>, variance_exr: Option<&Path>) -> Result<()> {
    if let Some(p) = image {
        image_io::DisplayFormat::of(p)?;
    }
    for (p, flag) in [(exr, "--exr"), (variance_exr, "--variance-exr")] {
        if let Some(p) = p.filter(|p| !p.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr"))) {
            crate::bail!("{flag} {}: an OpenEXR file's name ends in .exr", p.display());
        }
    }
    Ok(())
}

/// A render's image files: the tone-mapped image in the format its name
/// says, with `rate` (adaptive sampling ran) its `_rate.png` beside it, and
/// the EXRs asked for; returns the paths written. `merge` writes through
/// this too, so a merged split render writes what the render would have.
pub(crate) fn write_images(
    out: &render::RenderOutput,
    image: &Path,
    rate: bool,
    exr: Option<&Path>,
    variance_exr: Option<&Path>,
    spp: u32,
) -> Result<Vec<String>> {
    image_io::write_display(image, &out.image)?;
    let mut written = vec![image.display().to_string()];
    if rate {
        let rate = rate_path(image);
        image_io::write_rate_png(&rate, out.image.width, out.image.height, &out.samples, spp)?;
        written.push(rate.display().to_string());
    }
    for (path, img) in [(exr, &out.image), (variance_exr, &out.variance)] {
        if let Some(p) = path {
            image_io::write_exr(p, img)?;
            written.push(p.display().to_string());
        }
    }
    Ok(written)
}

/// A checked `--part I/N`.
struct Part {
    index: u32,
    count: u32,
    kind: crate::partial::SplitKind,
    share: render::Share,
}

/// `--part`, `--partial` and `--split`, checked against the other flags.
fn part_flags(a: &RenderArgs, spp: u32, adaptive: bool, region: Region) -> Result<Option<Part>> {
    use crate::partial::SplitKind;
    let Some(text) = &a.part else { return Ok(None) };
    let parsed = text.split_once('/').and_then(|(i, n)| Some((i.trim().parse::<u32>().ok()?, n.trim().parse::<u32>().ok()?)));
    let (index, count) = match parsed {
        Some((i, n)) if n >= 1 && i < n => (i, n),
        _ => crate::bail!("--part {text}: expected I/N with 0 <= I < N (part I of N, counted from 0)"),
    };
    for (used, flag) in [(a.output.is_some(), "-f"), (a.exr.is_some(), "--exr"), (a.variance_exr.is_some(), "--variance-exr")] {
        if used {
            crate::bail!("{flag} with --part: a part writes a partial (--partial FILE); `pathtracer merge` writes the images");
        }
    }
    let kind = match (a.split, adaptive) {
        (Some(SplitArg::Samples), true) => crate::bail!(
            "--split samples with -a: adaptive sampling decides on all of a pixel's samples, so it splits by tiles (--split tiles)"
        ),
        (Some(SplitArg::Samples), false) | (None, false) => SplitKind::Samples,
        (Some(SplitArg::Tiles), _) | (None, true) => SplitKind::Tiles,
    };
    let share = match kind {
        SplitKind::Samples => {
            if count > spp {
                crate::bail!("--part {text}: a sample split needs N <= the samples per pixel ({spp}); use fewer parts or --split tiles");
            }
            render::Share::samples_of(index, count, spp)
        }
        SplitKind::Tiles => {
            let (cols, rows) = render::tile_grid(region);
            if count > cols * rows {
                crate::bail!("--part {text}: a tile split needs N <= the number of {}x{} tiles ({})", render::TILE, render::TILE, cols * rows);
            }
            render::Share::Tiles { index, count }
        }
    };
    Ok(Some(Part { index, count, kind, share }))
}

/// Everything that changes a split render's image, for its partials'
/// headers: parts that differ in any of it are refused by `merge`.
fn partial_settings(
    a: &RenderArgs,
    scene: &Scene,
    camera: &Camera,
    s: &RenderSettings,
    kind: crate::partial::SplitKind,
) -> Result<Vec<(String, String)>> {
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
    let flag = |b: bool| if b { "1" } else { "0" }.to_string();
    let kv = |k: &str, v: String| (k.to_string(), v);
    Ok(vec![
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
        kv("integrator", a.integrator.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default()),
        kv("max_depth", a.max_depth.unwrap_or(1).to_string()),
        kv("light_samples", a.light_samples.unwrap_or(1).to_string()),
        kv("accumulate", a.accumulate.unwrap_or(1).to_string()),
        kv("hemisphere", flag(a.hemisphere)),
        kv("russian_roulette", flag(!a.no_rr)),
        kv("backend", a.backend.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default()),
        kv("split", kind.name().to_string()),
    ])
}

/// `-b` and `-d`, checked.
fn lens_flags(a: &RenderArgs) -> Result<(Option<f32>, Option<f32>)> {
    let parse = |v: &Option<String>, flag: &str| -> Result<Option<f32>> {
        v.as_ref().map(|s| s.parse::<f32>().map_err(|_| Error::new(format!("{flag}: '{s}' is not a number")))).transpose()
    };
    let b = parse(&a.lens_radius, "-b")?;
    let d = parse(&a.focal_distance, "-d")?;
    if let Some(b) = b {
        if !(b >= 0.0 && b.is_finite()) {
            crate::bail!("-b {b}: the lens radius must be a finite number >= 0");
        }
    }
    if let Some(d) = d {
        if !(d > 0.0 && d.is_finite()) {
            crate::bail!("-d {d}: the focal distance must be a finite number > 0");
        }
    }
    Ok((b, d))
}

/// The environment map of `-e`, loaded and tabulated for sampling.
fn load_environment(a: &RenderArgs) -> Result<Option<std::sync::Arc<crate::light::EnvMap>>> {
    a.environment.as_deref().map(|p| crate::light::EnvMap::load(p).map(std::sync::Arc::new)).transpose()
}

/// The frame size from `-r` (800x600 without it).
fn frame_size(a: &RenderArgs) -> Result<(u32, u32)> {
    match &a.resolution {
        None => Ok((DEFAULT_WIDTH, DEFAULT_HEIGHT)),
        Some(v) => {
            let r: Vec<u32> = parse_pair(v, "-r")?;
            if r[0] == 0 || r[1] == 0 || r[0] > 16384 || r[1] > 16384 {
                crate::bail!("-r {} {}: width and height must be between 1 and 16384", r[0], r[1]);
            }
            Ok((r[0], r[1]))
        }
    }
}

/// CS184's camera placement, then `-r` (crop, or scale with --keep-fov), then
/// `-c`, then `lens` (`-b`, `-d` from `lens_flags`).
fn setup_camera(a: &RenderArgs, scene: &Scene, width: u32, height: u32, lens: (Option<f32>, Option<f32>)) -> Result<Camera> {
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

fn run_export(a: &RenderArgs, out: &Path) -> Result<()> {
    if a.part.is_some() {
        crate::bail!("--part applies to rendering; export writes the whole scene");
    }
    let (width, height) = frame_size(a)?;
    let lens = lens_flags(a)?;
    let scene = load_scene(a.scene.as_deref())?;
    check_materials(&scene)?;
    let camera = setup_camera(a, &scene, width, height, lens)?;
    let lights = Lights::with_environment(&scene, load_environment(a)?)?;
    crate::export::export(&scene, &camera, &lights, out)?;
    println!("{}: exported {} shapes and {} lights to {}", scene.name, scene.shapes.len(), lights.lights.len(), out.display());
    Ok(())
}

fn compare(reference: &Path, images: &[PathBuf]) -> Result<()> {
    let r = image_io::read_exr(reference)?;
    for p in images {
        let img = image_io::read_exr(p)?;
        if (img.width, img.height) != (r.width, r.height) {
            crate::bail!("{}: {}x{} but the reference is {}x{}", p.display(), img.width, img.height, r.width, r.height);
        }
        println!(
            "{} | relMSE {:.6e} | relative bias {:+.4}%",
            p.display(),
            crate::metrics::rel_mse(&img, &r),
            100.0 * crate::metrics::rel_bias(&img, &r)
        );
    }
    Ok(())
}

/// The path integrator renders every CGL material with the parameters the
/// shipped scenes use; anything else (rough glass or refraction, values
/// outside a model's domain) is refused by name rather than approximated.
pub fn check_materials(scene: &Scene) -> Result<()> {
    for obj in &scene.objects {
        let m = &scene.materials[obj.material];
        let refuse = |why: String| -> Result<()> {
            crate::bail!("{}: object '{}' uses material '{}' ({}): {why}", scene.source, obj.name, m.name, m.bsdf.kind())
        };
        let colour_ok = |c: glam::Vec3| c.is_finite() && c.min_element() >= 0.0;
        match m.bsdf {
            Bsdf::Diffuse { albedo } if !colour_ok(albedo) => refuse(format!("diffuse colour {albedo} must be finite and non-negative"))?,
            Bsdf::Mirror { reflectance } if !colour_ok(reflectance) => refuse(format!("reflectance {reflectance} must be finite and non-negative"))?,
            Bsdf::Glass { roughness, .. } | Bsdf::Refraction { roughness, .. } if roughness != 0.0 => {
                refuse(format!("roughness {roughness} is not supported: only smooth (roughness 0) dielectrics are modelled, as in every CS184 scene"))?
            }
            Bsdf::Glass { ior, reflectance, transmittance, .. } if !(ior > 0.0 && ior.is_finite() && colour_ok(reflectance) && colour_ok(transmittance)) => {
                refuse(format!("ior {ior}, reflectance {reflectance}, transmittance {transmittance}: the ior must be positive and the colours non-negative"))?
            }
            Bsdf::Refraction { ior, transmittance, .. } if !(ior > 0.0 && ior.is_finite() && colour_ok(transmittance)) => {
                refuse(format!("ior {ior}, transmittance {transmittance}: the ior must be positive and the colour non-negative"))?
            }
            Bsdf::Microfacet { alpha, eta, k } if !(alpha > 0.0 && alpha.is_finite() && colour_ok(eta) && colour_ok(k)) => {
                refuse(format!("alpha {alpha}, eta {eta}, k {k}: alpha must be positive and eta, k non-negative"))?
            }
            _ => {}
        }
    }
    Ok(())
}

/// CS184's `<FILE minus its last 4 chars>_rate.png`, done on the extension.
pub fn rate_path(output: &Path) -> PathBuf {
    let stem = output.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    output.with_file_name(format!("{stem}_rate.png"))
}
