//! The image loop: tiles over rayon, one RNG stream per pixel, per-pixel mean
//! and variance of the mean, progress bar, ray counts.

pub mod aov;
pub mod normals;
pub mod path;

use crate::camera::Camera;
use crate::image_io::Rgb;
use crate::ray::Ray;
use crate::rng::Rng;
use glam::Vec3;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;
use std::io::IsTerminal;
use std::time::Instant;

const TILE: u32 = 32;

/// Radiance along one camera ray. `rays` counts every ray the estimate traces.
pub trait Integrator: Sync {
    fn radiance(&self, ray: &Ray, rng: &mut Rng, rays: &mut u64) -> Vec3;
}

/// A rectangle of the frame, in CS184's frame coordinates (x right, y up from
/// the bottom row), as `-p X Y DX DY` gives it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Region {
    pub x: u32,
    pub y: u32,
    pub w: u32,
    pub h: u32,
}

/// CS184's adaptive sampling: every `batch` samples, stop a pixel once
/// `1.96 sigma / sqrt(n) <= tolerance * mu` over the illuminance of its samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Adaptive {
    pub batch: u32,
    pub tolerance: f32,
    /// Decide on pilot samples that are then discarded (unbiased, costs
    /// about twice the samples) instead of on the samples averaged (CS184).
    pub pilot: bool,
}

#[derive(Clone, Debug)]
pub struct RenderSettings {
    /// Full frame size (the camera's screen size).
    pub width: u32,
    pub height: u32,
    /// Samples per pixel (the maximum, with adaptive sampling).
    pub spp: u32,
    pub seed: u64,
    pub region: Option<Region>,
    pub adaptive: Option<Adaptive>,
    pub progress: bool,
}

pub struct RenderOutput {
    /// Mean radiance per pixel; the region's size, row 0 at the top.
    pub image: Rgb,
    /// Variance of each pixel's mean, per channel (0 with one sample).
    pub variance: Rgb,
    /// Samples taken per pixel.
    pub samples: Vec<u32>,
    pub rays: u64,
    pub seconds: f64,
}

/// Whether to draw a progress bar: only on a terminal, never under CI.
pub fn progress_wanted() -> bool {
    std::io::stderr().is_terminal() && std::env::var_os("CI").is_none()
}

/// CS184 illuminance (Rec. 709 luminance).
#[inline]
pub fn illuminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

struct PixelResult {
    mean: Vec3,
    var_of_mean: Vec3,
    samples: u32,
    rays: u64,
}

/// Running per-pixel statistics over `n` samples.
struct Moments {
    /// Welford mean and sum of squared deviations, per channel.
    mean: Vec3,
    m2: Vec3,
    n: u32,
}

/// Take up to `max` samples; with `rule`, stop early by CS184's criterion,
/// checked every `batch` samples on the samples taken so far.
fn sample_pixel(
    camera: &Camera,
    integ: &dyn Integrator,
    s: &RenderSettings,
    x: u32,
    y: u32,
    rng: &mut Rng,
    max: u32,
    rule: Option<Adaptive>,
    rays: &mut u64,
) -> Moments {
    let (w, h) = (s.width as f32, s.height as f32);
    let mut m = Moments { mean: Vec3::ZERO, m2: Vec3::ZERO, n: 0 };
    // Illuminance moments for the adaptive rule.
    let (mut s1, mut s2) = (0.0f64, 0.0f64);
    while m.n < max {
        let (jx, jy) = if s.spp == 1 { (0.5, 0.5) } else { rng.uniform2() };
        let ray = camera.generate_ray((x as f32 + jx) / w, (y as f32 + jy) / h);
        let l = integ.radiance(&ray, rng, rays);
        m.n += 1;
        let d = l - m.mean;
        m.mean += d / m.n as f32;
        m.m2 += d * (l - m.mean);
        let il = illuminance(l) as f64;
        s1 += il;
        s2 += il * il;
        if let Some(a) = rule {
            if m.n % a.batch == 0 {
                let nf = m.n as f64;
                let mu = s1 / nf;
                let var = ((s2 - s1 * s1 / nf) / (nf - 1.0)).max(0.0);
                if 1.96 * var.sqrt() / nf.sqrt() <= a.tolerance as f64 * mu {
                    break;
                }
            }
        }
    }
    m
}

/// Seed tag of the pilot streams, so pilot samples never reuse image samples.
const PILOT_TAG: u64 = 0x7069_6c6f_7420_5f5f;

fn render_pixel(camera: &Camera, integ: &dyn Integrator, s: &RenderSettings, x: u32, y: u32) -> PixelResult {
    let mut rng = Rng::for_pixel(s.seed, x, y);
    let mut rays = 0u64;
    let m = match s.adaptive {
        Some(a) if a.pilot => {
            // Kirk and Arvo's two-stage sampling: decide the count on pilot
            // samples, throw them away, average fresh ones. The stopping
            // decision is then independent of the samples averaged: unbiased.
            let mut pilot = Rng::for_pixel(s.seed ^ PILOT_TAG, x, y);
            let n = sample_pixel(camera, integ, s, x, y, &mut pilot, s.spp, Some(a), &mut rays).n;
            sample_pixel(camera, integ, s, x, y, &mut rng, n, None, &mut rays)
        }
        rule => sample_pixel(camera, integ, s, x, y, &mut rng, s.spp, rule, &mut rays),
    };
    let var_of_mean = if m.n > 1 { m.m2 / (m.n as f32 * (m.n - 1) as f32) } else { Vec3::ZERO };
    PixelResult { mean: m.mean, var_of_mean, samples: m.n, rays }
}

/// Render `settings.region` (or the whole frame) with `integ`.
pub fn render(camera: &Camera, integ: &dyn Integrator, settings: &RenderSettings) -> RenderOutput {
    let start = Instant::now();
    let region = settings.region.unwrap_or(Region { x: 0, y: 0, w: settings.width, h: settings.height });
    let mut tiles = Vec::new();
    for ty in (0..region.h).step_by(TILE as usize) {
        for tx in (0..region.w).step_by(TILE as usize) {
            tiles.push((tx, ty));
        }
    }
    let bar = if settings.progress {
        let b = ProgressBar::with_draw_target(Some(tiles.len() as u64), ProgressDrawTarget::stderr());
        b.set_style(ProgressStyle::with_template("{bar:40} {percent:>3}% tiles {pos}/{len} eta {eta}").unwrap());
        b
    } else {
        ProgressBar::hidden()
    };
    // Local (x, y) count from the region's top-left; the frame's y runs up
    // from the bottom, so local row ly is frame row region.y + region.h - 1 - ly.
    let done: Vec<Vec<(u32, u32, PixelResult)>> = tiles
        .par_iter()
        .map(|&(tx, ty)| {
            let mut out = Vec::with_capacity((TILE * TILE) as usize);
            for ly in ty..(ty + TILE).min(region.h) {
                for lx in tx..(tx + TILE).min(region.w) {
                    let fx = region.x + lx;
                    let fy = region.y + region.h - 1 - ly;
                    out.push((lx, ly, render_pixel(camera, integ, settings, fx, fy)));
                }
            }
            bar.inc(1);
            out
        })
        .collect();
    bar.finish_and_clear();
    let mut image = Rgb::new(region.w, region.h);
    let mut variance = Rgb::new(region.w, region.h);
    let mut samples = vec![0u32; (region.w * region.h) as usize];
    let mut rays = 0;
    for tile in done {
        for (lx, ly, p) in tile {
            let i = (ly * region.w + lx) as usize;
            image.pixels[i] = p.mean;
            variance.pixels[i] = p.var_of_mean;
            samples[i] = p.samples;
            rays += p.rays;
        }
    }
    RenderOutput { image, variance, samples, rays, seconds: start.elapsed().as_secs_f64() }
}
