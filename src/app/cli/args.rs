//! The command-line arguments (clap): CS184's flags, ours, the subcommands.

use crate::accel::BackendKind;
use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

/// The examples at the end of `--help` (and of the man page).
pub const EXAMPLES: &str = "\
Examples:
  pathtracer
      Render the built-in Cornell box (16 samples per pixel, -m 5).
  pathtracer scene.dae -t 8 -s 64 -l 4 -m 5 -r 480 360 -f out.png
      A CS184 render: 8 threads, 64 samples per pixel, 5 bounces.
  pathtracer scene.dae -s 256 -b 0.05 -d 4.5
      Depth of field through a thin lens.
  pathtracer bunny_unlit.dae -e studio.exr -s 64 -m 5
      Lit by an environment map.
  pathtracer scene.dae -s 1024 -a 64 0.05 -m 5 -f out.png
      Adaptive sampling; also writes out_rate.png.
  pathtracer scene.dae --integrator normals
      CS184's normal shading.
  pathtracer scene.dae --backend embree
      The same image through Embree's traversal.
  pathtracer scene.dae -s 256 --part 0/2 --partial p0.ptp
  pathtracer scene.dae -s 256 --part 1/2 --partial p1.ptp
  pathtracer merge p0.ptp p1.ptp -f out.png
      A render split in two, merged into the one-machine image, byte for byte.
  pathtracer bench cow CBbunny
      BVH build time and ray throughput per backend.
  pathtracer validate scene.dae -m 5 --budget 5m --report checks
      Check a scene every way we can (backends, estimators, references); exit 0, 1 or 2.";

/// A whole number of 0 or more, answered in one line when it is not one
/// (clap's own parsers would say "-1 is not in 0..=4294967295").
fn whole<T: TryFrom<u64>>(s: &str) -> Result<T, String> {
    use std::num::IntErrorKind;
    if s.trim_start().starts_with('-') {
        return Err("expected a whole number of 0 or more".into());
    }
    match s.trim().parse::<u64>() {
        Ok(v) => T::try_from(v).map_err(|_| "the number is too large".into()),
        Err(e) if *e.kind() == IntErrorKind::PosOverflow => Err("the number is too large".into()),
        Err(_) => Err("expected a whole number".into()),
    }
}

#[derive(Parser, Debug)]
#[command(
    name = "pathtracer",
    version,
    about = "Physically based path tracer for CS184 .dae scenes (native BVH, Embree or brute-force traversal)",
    long_about = "Physically based path tracer for CS184 COLLADA scenes (and OBJ/PLY meshes), with interchangeable \
ray-traversal backends: our own BVH (native), Intel Embree, and brute force (the oracle). Without a subcommand it \
renders SCENE (the built-in Cornell box without one) to a PNG, taking CS184's flags.",
    after_help = EXAMPLES,
    args_conflicts_with_subcommands = true
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
    #[command(flatten)]
    pub render: RenderArgs,
    /// No argument at all was given: the demo render (`cli::run`).
    #[arg(skip)]
    pub bare: bool,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Time BVH builds and ray throughput per backend, and print a table.
    Bench(crate::app::bench::BenchArgs),
    /// Write the loaded scene (camera placed, lights merged) as scene.json + OBJ
    /// meshes for the validation harness's reference-renderer exporters.
    Export {
        #[command(flatten)]
        render: RenderArgs,
        /// Output folder
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
    },
    /// Combine the partials of a split render (--part I/N --partial FILE) into
    /// exactly the images the one-machine render writes.
    Merge {
        /// The partials, one per part, in any order
        #[arg(required = true, value_name = "PARTIAL")]
        partials: Vec<PathBuf>,
        /// Output image, PNG or JPEG by its extension (.png, .jpg, .jpeg);
        /// where the parts ran adaptive sampling (-a) also its sample-rate
        /// image FILE_rate.png (FILE without its extension)
        #[arg(short = 'f', value_name = "FILE", required = true)]
        output: PathBuf,
        /// Also write the linear radiance as OpenEXR
        #[arg(long, value_name = "FILE")]
        exr: Option<PathBuf>,
        /// Also write the per-pixel variance of the mean as OpenEXR
        #[arg(long, value_name = "FILE")]
        variance_exr: Option<PathBuf>,
    },
    /// Check a scene in every way we can: every backend's hits against
    /// native's, the path tracer against BDPT and light tracing, adaptive
    /// sampling against fixed-rate sampling, and the reference renderers;
    /// one verdict line per check, exit status 0 (all pass), 1 (a check
    /// failed) or 2 (could not decide or run).
    Validate(ValidateArgs),
    /// Check partials on their own (header and records checksums): one line
    /// per partial, a non-zero exit when any is damaged.
    Verify {
        /// The partials to check
        #[arg(required = true, value_name = "PARTIAL")]
        partials: Vec<PathBuf>,
    },
    /// Error of OpenEXR images against a reference: relMSE and relative bias.
    Compare {
        /// The reference image (linear OpenEXR)
        reference: PathBuf,
        /// Images to compare with it
        #[arg(required = true)]
        images: Vec<PathBuf>,
    },
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell)
    /// to standard output, e.g. `pathtracer completions bash > /etc/bash_completion.d/pathtracer`.
    Completions {
        /// The shell
        shell: clap_complete::Shell,
    },
    /// Write the man pages (pathtracer.1 and one per subcommand) into DIR.
    Man {
        /// Output folder
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
    },
    /// Print the command-line reference as Markdown (docs/reference/cli.md is
    /// this output; a test checks that it is current).
    #[command(hide = true)]
    CliReference,
}

/// `--bdpt-light-paths`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum BdptLightPaths {
    All,
    Specular,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum IntegratorKind {
    /// Light transport: direct lighting (-m 1) or global illumination (-m > 1).
    Path,
    /// Bidirectional path tracing: camera and light subpaths joined by every
    /// strategy, weighted by multiple importance sampling (caustics)
    Bdpt,
    /// Light tracing: paths from the lights, each vertex joined to the lens
    /// (Mitsuba's particle tracer)
    Light,
    /// Shading normal as colour, n*0.5+0.5 (CS184's normal_shading).
    Normals,
    /// Distance to the first hit along the camera ray (0 where it escapes).
    Depth,
    /// A flat colour per object (`pathtracer export` lists each object's colour).
    ObjectId,
}

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// Scene file: CS184 COLLADA (.dae), or a mesh as Wavefront OBJ (.obj) or
    /// PLY (.ply, ASCII or binary). OBJ/PLY carry geometry only, so they get
    /// fixed defaults: CS184's diffuse 0.5 on every mesh (OBJ materials are
    /// not read), a hemisphere sky of radiance 1 over +y (bunny.dae's light),
    /// CS184's camera placement looking along -z with no clipping planes.
    /// Without a file, the built-in CBspheres_lambertian is rendered.
    pub scene: Option<PathBuf>,
    /// Render threads, at least 1 [default: all cores]
    #[arg(help_heading = "CS184 flags", short = 't', allow_negative_numbers = true, value_parser = whole::<usize>, value_name = "N")]
    pub threads: Option<usize>,
    /// Camera rays per pixel (the maximum with -a) [default: 1]
    #[arg(help_heading = "CS184 flags", short = 's', allow_negative_numbers = true, value_parser = whole::<u32>, value_name = "N")]
    pub spp: Option<u32>,
    /// Samples per area light; with several lights and --light-pick one,
    /// light samples per vertex, each picking one light [default: 1]
    #[arg(help_heading = "CS184 flags", short = 'l', allow_negative_numbers = true, value_parser = whole::<u32>, value_name = "N")]
    pub light_samples: Option<u32>,
    /// Maximum ray depth [default: 1]
    #[arg(help_heading = "CS184 flags", short = 'm', allow_negative_numbers = true, value_parser = whole::<u32>, value_name = "N")]
    pub max_depth: Option<u32>,
    /// 1: accumulate bounces 0..m; 0: output only bounce m [default: 1]
    #[arg(help_heading = "CS184 flags", short = 'o', allow_negative_numbers = true, value_parser = whole::<u32>, value_name = "0|1")]
    pub accumulate: Option<u32>,
    /// Uniform hemisphere sampling for direct light instead of light sampling
    #[arg(help_heading = "CS184 flags", short = 'H')]
    pub hemisphere: bool,
    /// Adaptive sampling: check every BATCH samples, stop at relative tolerance TOL
    #[arg(help_heading = "CS184 flags", short = 'a', num_args = 2, value_names = ["BATCH", "TOL"], allow_negative_numbers = true)]
    pub adaptive: Option<Vec<String>>,
    /// Frame size in pixels [default: 800 600]; keeps CS184's pixel focal length
    #[arg(help_heading = "CS184 flags", short = 'r', num_args = 2, value_names = ["W", "H"], allow_negative_numbers = true)]
    pub resolution: Option<Vec<String>>,
    /// With -r: scale the 800x600 view to the new size instead of cropping it
    #[arg(help_heading = "Output", long, requires = "resolution")]
    pub keep_fov: bool,
    /// Output image, PNG or JPEG by its extension (.png, .jpg, .jpeg); with
    /// -a also its sample-rate image FILE_rate.png (FILE without its
    /// extension) [default: ./SCENE.png]
    #[arg(help_heading = "CS184 flags", short = 'f', value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Load a CS184 camera settings file
    #[arg(help_heading = "CS184 flags", short = 'c', value_name = "FILE")]
    pub camera: Option<PathBuf>,
    /// Render only the cell at X,Y (from the bottom-left) of size DX x DY
    #[arg(help_heading = "CS184 flags", short = 'p', num_args = 4, value_names = ["X", "Y", "DX", "DY"], allow_negative_numbers = true)]
    pub cell: Option<Vec<String>>,
    /// Environment light: a latitude-longitude OpenEXR map (CS184's -e)
    #[arg(help_heading = "CS184 flags", short = 'e', value_name = "FILE.exr")]
    pub environment: Option<PathBuf>,
    /// Thin-lens radius in scene units; 0 is a pinhole [default: 0]
    #[arg(help_heading = "CS184 flags", short = 'b', value_name = "RADIUS", allow_negative_numbers = true)]
    pub lens_radius: Option<String>,
    /// Focal distance: the plane in focus, in scene units along the view axis [default: 4.7]
    #[arg(help_heading = "CS184 flags", short = 'd', value_name = "DIST", allow_negative_numbers = true)]
    pub focal_distance: Option<String>,
    /// Ray traversal backend
    #[arg(help_heading = "Backends", long, value_enum, default_value_t = BackendKind::Native)]
    pub backend: BackendKind,
    /// What to compute per camera ray
    #[arg(help_heading = "Light transport", long, value_enum, default_value_t = IntegratorKind::Path)]
    pub integrator: IntegratorKind,
    /// With --integrator bdpt: render only strategy S,T (S light vertices, T
    /// camera vertices) unweighted, or S,T,weighted with its MIS weight, as
    /// pbrt-v4's strategy images: the weighted ones sum to the full image
    #[arg(help_heading = "Light transport", long, value_name = "S,T[,weighted]")]
    pub bdpt_strategy: Option<String>,
    /// With --integrator bdpt: which light subpaths go on past their first
    /// bounce. specular: only those whose first bounce is a mirror or
    /// glass, so light subpaths make only the caustics and the camera side
    /// the rest, as a path tracer does, at a fraction of the cost per
    /// sample (less error at equal time on every scene measured); all:
    /// every one (every strategy) [default: specular]
    #[arg(help_heading = "Light transport", long, value_enum, value_name = "PATHS")]
    pub bdpt_light_paths: Option<BdptLightPaths>,
    /// Disable Russian roulette (paths then always run to -m bounces)
    #[arg(help_heading = "Light transport", long)]
    pub no_rr: bool,
    /// With -a: decide each pixel's sample count on pilot samples that are
    /// then discarded (unbiased; CS184's rule decides on the samples it keeps)
    #[arg(help_heading = "Light transport", long, requires = "adaptive")]
    pub adaptive_pilot: bool,
    /// Seed of the per-pixel sample draws
    #[arg(help_heading = "Light transport", long, allow_negative_numbers = true, value_parser = whole::<u64>, default_value_t = 0)]
    pub seed: u64,
    /// Where each sample's random numbers come from: Owen-scrambled Sobol
    /// points (stratified) or independent uniform numbers
    #[arg(help_heading = "Light transport", long, value_enum, default_value_t = SamplerArg::Sobol)]
    pub sampler: SamplerArg,
    /// How rectangular and spherical lights are sampled: uniformly in the
    /// solid angle they subtend, or (CS184's way, for A/B comparisons) by area
    #[arg(help_heading = "Light transport", long, value_enum, default_value_t = LightSamplingArg::SolidAngle)]
    pub light_sampling: LightSamplingArg,
    /// How the hemisphere light is sampled at diffuse vertices: by the lune
    /// (the clipped cosine), or (CS184's way, for A/B comparisons) uniformly
    /// with MIS
    #[arg(help_heading = "Light transport", long, value_enum, default_value_t = SkySamplingArg::Lune)]
    pub sky_sampling: SkySamplingArg,
    /// How the environment map (-e) is sampled at reflecting vertices: by
    /// the map times a bound of the receiver's cosine and, at glossy
    /// vertices of α ≤ 0.1, inside the lobe's cone; or for A/B comparisons
    /// by the cosine bound everywhere, or by the map alone (Cycles' and
    /// Mitsuba's way)
    #[arg(help_heading = "Light transport", long, value_enum, default_value_t = EnvSamplingArg::Product)]
    pub env_sampling: EnvSamplingArg,
    /// Share of a diffuse surface's bounce rays aimed at the scene's mirror,
    /// glass and metal objects reflecting at least half the light (a
    /// mixture with the cosine lobe, weighted by its pdf: unbiased), so that
    /// caustics through them are found more often; 0 for the cosine lobe
    /// alone (CS184's, Cycles' and Mitsuba's way). Up to 16 objects
    #[arg(help_heading = "Light transport", long, value_name = "FRACTION", allow_negative_numbers = true, default_value_t = crate::render::path::specular_guide::DEFAULT_FRACTION)]
    pub specular_guide: f32,
    /// With several lights: each light sample picks one, in proportion to
    /// an estimate of what each sends to the vertex, or
    /// every light is sampled at every vertex. Scenes with an environment
    /// map, the hemisphere light, a non-rectangular emissive mesh or more
    /// than 8 lights always sample every light
    #[arg(help_heading = "Light transport", long, value_enum, default_value_t = LightPickArg::One)]
    pub light_pick: LightPickArg,
    /// Also write the linear radiance as OpenEXR
    #[arg(help_heading = "Output", long, value_name = "FILE")]
    pub exr: Option<PathBuf>,
    /// Also write the per-pixel variance of the mean as OpenEXR
    #[arg(help_heading = "Output", long, value_name = "FILE")]
    pub variance_exr: Option<PathBuf>,
    /// Write the camera settings (CS184's six-line format) used for this render
    #[arg(help_heading = "Output", long, value_name = "FILE")]
    pub write_camera: Option<PathBuf>,
    /// Render only part I (from 0) of N of the work and write it to --partial
    /// FILE instead of images; `pathtracer merge` makes the images from all N
    #[arg(help_heading = "Split renders", long, value_name = "I/N", requires = "partial", allow_hyphen_values = true)]
    pub part: Option<String>,
    /// The partial file --part writes
    #[arg(help_heading = "Split renders", long, value_name = "FILE", requires = "part")]
    pub partial: Option<PathBuf>,
    /// How --part divides the work: sample ranges of every pixel, or
    /// interleaved tiles [default: samples; tiles with -a]
    #[arg(help_heading = "Split renders", long, value_enum, requires = "part")]
    pub split: Option<SplitArg>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SamplerArg {
    /// Owen-scrambled, shuffled Sobol points (Burley 2020), the first light sample and the position in the pixel one 4D point
    Sobol,
    /// Owen-scrambled Sobol, one 2D sequence per draw (Cycles 3.4's way; for A/B comparisons)
    SobolPadded,
    /// Independent uniform random numbers (CS184's kind; for A/B comparisons)
    Independent,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum LightSamplingArg {
    /// Rectangles by solid angle (Ureña et al.), spheres by their cone
    SolidAngle,
    /// Uniform points on the light's area (CS184's kind; for A/B comparisons)
    Area,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SkySamplingArg {
    /// The clipped cosine over the sky's part of the hemisphere, alone
    Lune,
    /// Uniform directions over the sky, with MIS (CS184's kind; for A/B comparisons)
    Uniform,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum EnvSamplingArg {
    /// The map times a conservative bound of the receiver's cosine, per bin of normals; at glossy vertices (microfacet, α ≤ 0.1) the map inside the lobe's cone
    Product,
    /// The cosine bound at every reflecting vertex, glossy ones included
    Cosine,
    /// The map's luminance alone
    Map,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum LightPickArg {
    /// Each light sample picks one light by its estimated share here
    One,
    /// Every light is sampled at every vertex (CS184's way; for A/B comparisons)
    All,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SplitArg {
    /// Sample indices [I*S/N, (I+1)*S/N) of every pixel
    Samples,
    /// Tiles k of the frame with k mod N = I (pixels are independent, so
    /// adaptive sampling stays exact)
    Tiles,
}

/// `pathtracer validate`: the scene, the render flags it is checked with,
/// and the checks' budget, references and report.
#[derive(clap::Args, Debug)]
pub struct ValidateArgs {
    #[command(flatten)]
    pub render: RenderArgs,
    /// Wall time for all checks together, e.g. 90s, 5m, 1h [default: 2m];
    /// shared among them, each scaling its rays and samples to its share
    #[arg(long, value_name = "TIME")]
    pub budget: Option<String>,
    /// Reference renderers to compare against, comma-separated (mitsuba,
    /// cycles, povray), or none [default: every one installed]
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    pub references: Vec<String>,
    /// Write summary.json, junit.xml and report.html into DIR
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
}
