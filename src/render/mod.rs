//! The image loop: tiles over rayon, one RNG stream per pixel, per-pixel mean
//! and variance of the mean, progress bar, ray counts.

pub mod aov;
pub mod normals;
pub mod path;
mod wavefront;

use crate::accel::{Hit, Traversal};
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
/// Side of the pixel blocks a tile is sampled in (see `render`).
const BLOCK: u32 = 4;

/// Radiance along a camera ray. The image loop finds the camera rays' first
/// hits itself, a tile of rays per call to the backend's coherent batch
/// traversal, and hands each hit over: `rays` counts every ray the estimate
/// traces *after* the camera ray.
pub trait Integrator: Sync {
    /// The traversal camera rays are traced with.
    fn accel(&self) -> &dyn Traversal;

    /// Radiance along `ray`, whose closest hit in `(tmin, tmax]` is `hit`.
    fn radiance_from(&self, ray: &Ray, hit: Option<Hit>, rng: &mut Rng, rays: &mut u64) -> Vec3;

    /// `out[i]` = `radiance_from(&rays[i], hits[i], rngs[i], ..)` for a batch
    /// of camera rays; integrators that trace further rays may batch them
    /// (the path tracer does, bounce by bounce), with identical results.
    fn radiance_batch(&self, rays: &[Ray], hits: &[Option<Hit>], rngs: &mut [&mut Rng], out: &mut [Vec3], ray_count: &mut u64) {
        for i in 0..rays.len() {
            out[i] = self.radiance_from(&rays[i], hits[i], rngs[i], ray_count);
        }
    }
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
    /// Trace each round of a tile's camera rays as one coherent batch, and
    /// let the integrator batch the rays that follow (the path tracer traces
    /// each bounce's shadow rays and continuation rays as batches): the
    /// default. Off, every ray is traced on its own. The image is the same
    /// either way.
    pub batch_rays: bool,
}

impl RenderSettings {
    pub fn new(width: u32, height: u32, spp: u32, seed: u64) -> Self {
        RenderSettings { width, height, spp, seed, region: None, adaptive: None, progress: false, batch_rays: true }
    }
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
}

/// Running per-pixel statistics over `n` samples.
struct Moments {
    /// Welford mean and sum of squared deviations, per channel.
    mean: Vec3,
    m2: Vec3,
    n: u32,
}

/// One pixel's sampling state within a tile.
struct PixelState {
    x: u32,
    y: u32,
    rng: Rng,
    m: Moments,
    /// Illuminance moments for the adaptive rule.
    s1: f64,
    s2: f64,
    max: u32,
    done: bool,
}

impl PixelState {
    fn new(x: u32, y: u32, rng: Rng, max: u32) -> Self {
        PixelState { x, y, rng, m: Moments { mean: Vec3::ZERO, m2: Vec3::ZERO, n: 0 }, s1: 0.0, s2: 0.0, max, done: max == 0 }
    }

    /// Add a sample; with `rule`, stop by CS184's criterion, checked every
    /// `batch` samples on the samples taken so far.
    fn add(&mut self, l: Vec3, rule: Option<Adaptive>) {
        let m = &mut self.m;
        m.n += 1;
        let d = l - m.mean;
        m.mean += d / m.n as f32;
        m.m2 += d * (l - m.mean);
        let il = illuminance(l) as f64;
        self.s1 += il;
        self.s2 += il * il;
        if let Some(a) = rule {
            if m.n % a.batch == 0 {
                let nf = m.n as f64;
                let mu = self.s1 / nf;
                let var = ((self.s2 - self.s1 * self.s1 / nf) / (nf - 1.0)).max(0.0);
                if 1.96 * var.sqrt() / nf.sqrt() <= a.tolerance as f64 * mu {
                    self.done = true;
                }
            }
        }
        if m.n >= self.max {
            self.done = true;
        }
    }
}

/// Sample every pixel of a tile up to its `max` (or until `rule` stops it),
/// in rounds: one camera ray per unfinished pixel per round, traced as one
/// coherent batch. Each pixel draws from its own stream in the order a
/// pixel-at-a-time loop would (jitter, then the path, sample after sample),
/// so the image does not depend on batching, tiling or threads.
fn sample_tile(camera: &Camera, integ: &dyn Integrator, s: &RenderSettings, px: &mut [PixelState], rule: Option<Adaptive>, rays: &mut u64) {
    let (w, h) = (s.width as f32, s.height as f32);
    let accel = integ.accel();
    let mut active: Vec<usize> = (0..px.len()).filter(|&i| !px[i].done).collect();
    let mut batch: Vec<Ray> = Vec::with_capacity(active.len());
    let mut hits: Vec<Option<Hit>> = Vec::with_capacity(active.len());
    let mut radiance: Vec<Vec3> = Vec::with_capacity(active.len());
    while !active.is_empty() {
        batch.clear();
        for &i in &active {
            let p = &mut px[i];
            let (jx, jy) = if s.spp == 1 { (0.5, 0.5) } else { p.rng.uniform2() };
            let (x, y) = ((p.x as f32 + jx) / w, (p.y as f32 + jy) / h);
            // A pinhole draws nothing more: `-b 0` images are those of a
            // camera without a lens, bit for bit.
            batch.push(if camera.has_lens() { camera.generate_ray_thin_lens(x, y, p.rng.uniform2()) } else { camera.generate_ray(x, y) });
        }
        hits.clear();
        hits.resize(batch.len(), None);
        *rays += batch.len() as u64;
        if s.batch_rays {
            accel.intersect_coherent(&batch, &mut hits);
            // `active` lists exactly the unfinished pixels, in order.
            let mut rngs: Vec<&mut Rng> = px.iter_mut().filter(|p| !p.done).map(|p| &mut p.rng).collect();
            debug_assert_eq!(rngs.len(), active.len());
            radiance.clear();
            radiance.resize(batch.len(), Vec3::ZERO);
            integ.radiance_batch(&batch, &hits, &mut rngs, &mut radiance, rays);
            for (k, &i) in active.iter().enumerate() {
                px[i].add(radiance[k], rule);
            }
        } else {
            for (r, h) in batch.iter().zip(hits.iter_mut()) {
                *h = accel.intersect(r);
            }
            for (k, &i) in active.iter().enumerate() {
                let p = &mut px[i];
                let l = integ.radiance_from(&batch[k], hits[k], &mut p.rng, rays);
                p.add(l, rule);
            }
        }
        active.retain(|&i| !px[i].done);
    }
}

/// Seed tag of the pilot streams, so pilot samples never reuse image samples.
const PILOT_TAG: u64 = 0x7069_6c6f_7420_5f5f;

/// The pixels `(x, y)` of one tile, in frame coordinates.
fn render_tile(camera: &Camera, integ: &dyn Integrator, s: &RenderSettings, pixels: &[(u32, u32)]) -> (Vec<PixelResult>, u64) {
    let mut rays = 0u64;
    let fresh = |max: &dyn Fn(usize) -> u32| -> Vec<PixelState> {
        pixels.iter().enumerate().map(|(i, &(x, y))| PixelState::new(x, y, Rng::for_pixel(s.seed, x, y), max(i))).collect()
    };
    let px = match s.adaptive {
        Some(a) if a.pilot => {
            // Kirk and Arvo's two-stage sampling: decide the count on pilot
            // samples, throw them away, average fresh ones. The stopping
            // decision is then independent of the samples averaged: unbiased.
            let mut pilot: Vec<PixelState> =
                pixels.iter().map(|&(x, y)| PixelState::new(x, y, Rng::for_pixel(s.seed ^ PILOT_TAG, x, y), s.spp)).collect();
            sample_tile(camera, integ, s, &mut pilot, Some(a), &mut rays);
            let mut px = fresh(&|i| pilot[i].m.n);
            sample_tile(camera, integ, s, &mut px, None, &mut rays);
            px
        }
        rule => {
            let mut px = fresh(&|_| s.spp);
            sample_tile(camera, integ, s, &mut px, rule, &mut rays);
            px
        }
    };
    let out = px
        .iter()
        .map(|p| {
            let m = &p.m;
            let var_of_mean = if m.n > 1 { m.m2 / (m.n as f32 * (m.n - 1) as f32) } else { Vec3::ZERO };
            PixelResult { mean: m.mean, var_of_mean, samples: m.n }
        })
        .collect();
    (out, rays)
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
    let done: Vec<(Vec<(u32, u32)>, Vec<PixelResult>, u64)> = tiles
        .par_iter()
        .map(|&(tx, ty)| {
            let mut local = Vec::with_capacity((TILE * TILE) as usize);
            let mut frame = Vec::with_capacity((TILE * TILE) as usize);
            // Pixels in 4x4 blocks, so the backends' 16-ray packets of
            // camera rays are square frusta rather than 16x1 strips. Each
            // pixel has its own random stream: the order changes no pixel.
            let (x_end, y_end) = ((tx + TILE).min(region.w), (ty + TILE).min(region.h));
            for by in (ty..y_end).step_by(BLOCK as usize) {
                for bx in (tx..x_end).step_by(BLOCK as usize) {
                    for ly in by..(by + BLOCK).min(y_end) {
                        for lx in bx..(bx + BLOCK).min(x_end) {
                            local.push((lx, ly));
                            frame.push((region.x + lx, region.y + region.h - 1 - ly));
                        }
                    }
                }
            }
            let (results, rays) = render_tile(camera, integ, settings, &frame);
            bar.inc(1);
            (local, results, rays)
        })
        .collect();
    bar.finish_and_clear();
    let mut image = Rgb::new(region.w, region.h);
    let mut variance = Rgb::new(region.w, region.h);
    let mut samples = vec![0u32; (region.w * region.h) as usize];
    let mut rays = 0;
    for (local, results, tile_rays) in done {
        for ((lx, ly), p) in local.into_iter().zip(results) {
            let i = (ly * region.w + lx) as usize;
            image.pixels[i] = p.mean;
            variance.pixels[i] = p.var_of_mean;
            samples[i] = p.samples;
        }
        rays += tile_rays;
    }
    RenderOutput { image, variance, samples, rays, seconds: start.elapsed().as_secs_f64() }
}
