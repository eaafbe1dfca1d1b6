//! The command line: CS184's flags plus ours (defined in `args`), checked
//! into the library's values (`flags`), the render (`render`), the other
//! commands, and one-line answers to mistakes (`usage`).

mod args;
pub mod docs;
pub(crate) mod flags;
pub(crate) mod render;
mod usage;

pub use args::{BdptLightPaths, Cli, Command, EnvSamplingArg, IntegratorKind, LightPickArg, LightSamplingArg, RenderArgs, SamplerArg, SkySamplingArg, SplitArg, ValidateArgs};

pub use render::{init_threads, load_scene};

use crate::error::{Error, Result};
use crate::image_io;
use crate::light::Lights;
use render::run_render;
use std::path::{Path, PathBuf};
use usage::{not_a_command, usage_error};

const DEMO_SPP: u32 = 16;
const DEMO_DEPTH: u32 = 5;



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

/// Run a parsed command line, every command but `validate` (which
/// `app::run`, the binary's, runs too).
pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Some(Command::Bench(b)) => crate::app::bench::run(&b),
        // `validate` is built on this module (its render flags): `app::run`
        // runs it, one level up.
        Some(Command::Validate(_)) => Err(Error::new("pathtracer validate runs through pathtracer::app::run")),
        Some(Command::Compare { reference, images }) => compare(&reference, &images),
        Some(Command::Merge { partials, output, exr, variance_exr }) => {
            crate::app::merge::run(&partials, &output, exr.as_deref(), variance_exr.as_deref())
        }
        Some(Command::Verify { partials }) => crate::app::merge::verify(&partials),
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

fn run_export(a: &RenderArgs, out: &Path) -> Result<()> {
    if a.part.is_some() {
        crate::bail!("--part applies to rendering; export writes the whole scene");
    }
    let (width, height) = flags::frame_size(a).map_err(Error::into_usage)?;
    let lens = flags::lens_flags(a).map_err(Error::into_usage)?;
    let scene = load_scene(a.scene.as_deref())?;
    scene.check_materials()?;
    let camera = render::setup_camera(a, &scene, width, height, lens)?;
    let lights = Lights::with_environment(&scene, render::load_environment(a)?)?;
    crate::app::export::export(&scene, &camera, &lights, out)?;
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
