//! The render's flags, checked before any work and turned into the values
//! the library takes: the frame, the samples, the integrator's spec
//! (`IntegratorSpec`), how lights are sampled, the lens, the part of a
//! split render. A failure here is a usage error (exit status 2).

use super::args::{BdptLightPaths, EnvSamplingArg, IntegratorKind, LightPickArg, LightSamplingArg, RenderArgs, SamplerArg, SkySamplingArg, SplitArg};
use crate::app::images;
use crate::camera::{DEFAULT_HEIGHT, DEFAULT_WIDTH};
use crate::error::{Error, Result};
use crate::render::bdpt::{LightPaths, Technique};
use crate::render::integrator::{BdptOptions, Bounces, IntegratorSpec, PathOptions};
use crate::render::job::LightSampling;
use crate::render::{self, Adaptive, Region};
use crate::sampler::SamplerKind;
use clap::ValueEnum;

pub(crate) struct Flags {
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub adaptive: Option<Adaptive>,
    /// Said when `-a`'s batch was rounded up for the Sobol sampler.
    pub batch_note: Option<String>,
    pub region: Option<Region>,
    pub lens: (Option<f32>, Option<f32>),
    pub part: Option<Part>,
    pub spec: IntegratorSpec,
    pub sampling: LightSampling,
    pub sampler: SamplerKind,
}

impl Flags {
    /// About how many rays the render traces, for the build's decisions
    /// (`NativeOptions::expected_rays`): pixels × samples × (one closest
    /// and one shadow ray per bounce), the bounces capped at 8, past which
    /// Russian roulette has ended most paths. An upper estimate where
    /// adaptive sampling stops pixels early. A split render's parts count
    /// the whole render's rays, so that every part builds the same tree.
    pub fn expected_rays(&self) -> u64 {
        let pixels = match self.region {
            Some(r) => r.w as u64 * r.h as u64,
            None => self.width as u64 * self.height as u64,
        };
        let bounces = self.spec.bounces().map_or(1, |b| b.max_depth.min(8) as u64 + 1);
        pixels * self.spp as u64 * bounces * 2
    }
}

pub(crate) fn check_flags(a: &RenderArgs) -> Result<Flags> {
    let (width, height) = frame_size(a)?;
    let spp = a.spp.unwrap_or(1);
    if spp == 0 || spp > 1 << 20 {
        crate::bail!("-s {spp}: samples per pixel must be between 1 and 1048576");
    }
    let (adaptive, batch_note) = adaptive_flags(a)?;
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
    let spec = integrator_spec(a, adaptive.is_some())?;
    let lens = lens_flags(a)?;
    images::check_output_names(a.output.as_deref(), a.exr.as_deref(), a.variance_exr.as_deref())?;
    let part = part_flags(a, spp, adaptive.is_some(), region.unwrap_or(Region { x: 0, y: 0, w: width, h: height }))?;
    if a.threads == Some(0) {
        crate::bail!("-t 0: the thread count must be at least 1 (without -t every core renders)");
    }
    let sampling = LightSampling {
        by_area: a.light_sampling == LightSamplingArg::Area,
        uniform_sky: a.sky_sampling == SkySamplingArg::Uniform,
        env_cosine: a.env_sampling != EnvSamplingArg::Map,
        env_lobes: a.env_sampling == EnvSamplingArg::Product,
        pick_one: a.light_pick == LightPickArg::One,
    };
    let sampler = match a.sampler {
        SamplerArg::Sobol => SamplerKind::Sobol,
        SamplerArg::SobolPadded => SamplerKind::SobolPadded,
        SamplerArg::Independent => SamplerKind::Independent,
    };
    Ok(Flags { width, height, spp, adaptive, batch_note, region, lens, part, spec, sampling, sampler })
}

/// `-a BATCH TOL` (with `--adaptive-pilot`), and the note said when the
/// batch is rounded up to a power of two for the Sobol sampler.
fn adaptive_flags(a: &RenderArgs) -> Result<(Option<Adaptive>, Option<String>)> {
    let Some(v) = &a.adaptive else { return Ok((None, None)) };
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
    let (batch, note) = if a.sampler != SamplerArg::Independent && !batch.is_power_of_two() {
        let b = batch.checked_next_power_of_two().unwrap_or(1 << 31);
        (b, Some(format!("-a {batch}: Sobol samples are stratified in blocks of powers of two; checking every {b} samples")))
    } else {
        (batch, None)
    };
    Ok((Some(Adaptive { batch, tolerance: tol, pilot: a.adaptive_pilot }), note))
}

/// `--integrator` and the flags of its options, checked into its spec:
/// every flag given applies to the integrator asked for.
fn integrator_spec(a: &RenderArgs, adaptive: bool) -> Result<IntegratorSpec> {
    let name = a.integrator.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default();
    let transport = matches!(a.integrator, IntegratorKind::Path | IntegratorKind::Bdpt | IntegratorKind::Light);
    if matches!(a.integrator, IntegratorKind::Bdpt | IntegratorKind::Light) {
        let path_only = [
            (a.light_samples.is_some(), "-l"),
            (a.hemisphere, "-H"),
            (a.no_rr, "--no-rr"),
            (adaptive, "-a (a pixel's stopping rule cannot see the light other pixels' samples splat into it)"),
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
            crate::bail!("{flag} applies to light transport; it has no effect with --integrator {name}");
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
    let bounces = Bounces { max_depth, accumulate };
    Ok(match a.integrator {
        IntegratorKind::Path => IntegratorSpec::Path(PathOptions { bounces, light_samples, hemisphere: a.hemisphere, russian_roulette: !a.no_rr, specular_guide: a.specular_guide }),
        IntegratorKind::Bdpt => IntegratorSpec::Bdpt(BdptOptions {
            bounces,
            technique: a.bdpt_strategy.as_deref().map(parse_strategy).transpose()?.unwrap_or(Technique::Bidirectional),
            // Specular light paths by default: the mode that wins on every
            // scene measured (docs/design/bdpt.md).
            light_paths: match a.bdpt_light_paths {
                Some(BdptLightPaths::All) => LightPaths::All,
                None | Some(BdptLightPaths::Specular) => LightPaths::Specular,
            },
            unseen_light_caustics: true,
        }),
        IntegratorKind::Light => IntegratorSpec::LightTracing(bounces),
        IntegratorKind::Normals => IntegratorSpec::Normals,
        IntegratorKind::Depth => IntegratorSpec::Depth,
        IntegratorKind::ObjectId => IntegratorSpec::ObjectId,
    })
}

pub(super) fn parse_pair<T: std::str::FromStr>(v: &[String], flag: &str) -> Result<Vec<T>> {
    v.iter()
        .map(|s| s.parse::<T>().map_err(|_| Error::new(format!("{flag}: '{s}' is not a valid value"))))
        .collect()
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

/// A checked `--part I/N`.
pub(crate) struct Part {
    pub index: u32,
    pub count: u32,
    pub kind: crate::partial::SplitKind,
    pub share: render::Share,
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

/// `-b` and `-d`, checked.
pub(super) fn lens_flags(a: &RenderArgs) -> Result<(Option<f32>, Option<f32>)> {
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

/// The frame size from `-r` (800x600 without it).
pub(super) fn frame_size(a: &RenderArgs) -> Result<(u32, u32)> {
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
