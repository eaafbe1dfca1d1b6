//! The image loop: tiles over rayon, one random stream per pixel sample,
//! exact per-pixel sums (so any split of the work merges to the same bits),
//! progress bar, ray counts.

pub mod aov;
pub mod bdpt;
pub mod integrator;
pub mod job;
pub mod normals;
pub mod path;
pub mod splat;
pub mod sums;

use crate::accel::{Hit, Traversal};
use crate::camera::Camera;
use crate::image_io::Rgb;
use crate::ray::Ray;
use crate::sampler::{Sampler, SamplerKind};
use splat::{Splat, SplatSums};
use sums::PixelSums;
use glam::Vec3;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;
use std::time::Instant;

/// Side of the square tiles the frame is rendered in (and split by, with
/// `Split::Tiles`).
pub const TILE: u32 = 32;
/// Side of the pixel blocks a tile is sampled in (see `render`).
const BLOCK: u32 = 4;

/// Radiance along a camera ray. The image loop owns the traversal (`render`
/// takes it): it finds the camera rays' first hits itself, a tile of rays
/// per call to the backend's coherent batch traversal, and hands each hit
/// over with the traversal to trace the rest; an integrator holds the scene
/// and its estimator's settings, not a backend. `rays` counts every ray the
/// estimate traces *after* the camera ray.
pub trait Integrator: Sync {
    /// Radiance along `ray`, whose closest hit in `(tmin, tmax]` is `hit`;
    /// further rays are traced with `accel`, the traversal the image loop
    /// found the hit with.
    fn radiance_from(&self, accel: &dyn Traversal, ray: &Ray, hit: Option<Hit>, sampler: &mut Sampler, rays: &mut u64) -> Vec3;

    /// `out[i]` = `radiance_from(&rays[i], hits[i], samplers[i], ..)` for a batch
    /// of camera rays; integrators that trace further rays may batch them
    /// (the path tracer does, bounce by bounce), with identical results.
    #[allow(clippy::too_many_arguments)]
    fn radiance_batch(&self, accel: &dyn Traversal, rays: &[Ray], hits: &[Option<Hit>], samplers: &mut [&mut Sampler], out: &mut [Vec3], ray_count: &mut u64) {
        for i in 0..rays.len() {
            out[i] = self.radiance_from(accel, &rays[i], hits[i], samplers[i], ray_count);
        }
    }

    /// Whether the estimate also lands light on other pixels
    /// (`radiance_splat`: light tracing); the image loop then keeps a film
    /// of splats (`splat`) and calls `radiance_splat` for every sample.
    fn splats(&self) -> bool {
        false
    }

    /// `radiance_from`, pushing the light that lands elsewhere on the film
    /// to `splats`.
    #[allow(clippy::too_many_arguments)]
    fn radiance_splat(&self, accel: &dyn Traversal, ray: &Ray, hit: Option<Hit>, sampler: &mut Sampler, rays: &mut u64, splats: &mut Vec<Splat>) -> Vec3 {
        let _ = splats;
        self.radiance_from(accel, ray, hit, sampler, rays)
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
    /// Where each sample's random numbers come from.
    pub sampler: SamplerKind,
    /// Render only this share of the work (a split render's part).
    pub share: Share,
    /// Return every pixel's exact sums (`RenderOutput::sums`), for a partial.
    pub keep_sums: bool,
    /// At one sample a pixel, trace it through the pixel's centre (CS184's
    /// `-s 1`, the default) rather than through a random point of the pixel.
    /// The centre is a point sample of the image, not an estimate of the
    /// pixel's average, so a render that must agree in expectation with
    /// another estimator (`pathtracer validate`) turns it off.
    pub centre_single_sample: bool,
}

/// Which part of a render's work to do. Every pixel sample has its own
/// random stream, keyed by (seed, pixel, sample index), so the parts of a
/// split are exactly the one-machine render's samples, and their exact sums
/// merge to its bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Share {
    /// All of it.
    #[default]
    All,
    /// Sample indices `[lo, hi)` of every pixel (not with adaptive sampling,
    /// whose stopping decision needs all of a pixel's samples).
    Samples { lo: u32, hi: u32 },
    /// The tiles `k` (in row-major tile order over the region) with
    /// `k % count == index`: interleaved, so every part gets a fair mix of
    /// cheap and expensive parts of the frame.
    Tiles { index: u32, count: u32 },
}

impl Share {
    /// Sample indices `[I·S/N, (I+1)·S/N)`: part `index` of `count` of `spp`.
    pub fn samples_of(index: u32, count: u32, spp: u32) -> Share {
        let at = |i: u32| (i as u64 * spp as u64 / count as u64) as u32;
        Share::Samples { lo: at(index), hi: at(index + 1) }
    }

    /// Whether tile number `k` is rendered.
    pub fn has_tile(&self, k: u32) -> bool {
        match *self {
            Share::Tiles { index, count } => k % count == index,
            _ => true,
        }
    }
}

impl RenderSettings {
    pub fn new(width: u32, height: u32, spp: u32, seed: u64) -> Self {
        RenderSettings { width, height, spp, seed, region: None, adaptive: None, progress: false, batch_rays: true, sampler: SamplerKind::Sobol, share: Share::All, keep_sums: false, centre_single_sample: true }
    }

    /// The region rendered: `region`, or the whole frame.
    pub fn region(&self) -> Region {
        self.region.unwrap_or(Region { x: 0, y: 0, w: self.width, h: self.height })
    }
}

/// The tile grid over a region: tile `k` is at column `k % cols`, row `k / cols`.
pub fn tile_grid(region: Region) -> (u32, u32) {
    (region.w.div_ceil(TILE), region.h.div_ceil(TILE))
}

pub struct RenderOutput {
    /// Mean radiance per pixel; the region's size, row 0 at the top.
    pub image: Rgb,
    /// Variance of each pixel's mean, per channel (0 with one sample).
    pub variance: Rgb,
    /// Samples taken per pixel.
    pub samples: Vec<u32>,
    /// With `keep_sums`: every pixel's exact sums, row 0 at the top (pixels
    /// outside a `Share::Tiles` part have none).
    pub sums: Vec<PixelSums>,
    /// With an integrator that splats: every pixel's exact splat sums, row
    /// 0 at the top (empty otherwise).
    pub splats: Vec<SplatSums>,
    /// Samples (and splats) with a NaN or out-of-range channel (see `sums::SAMPLE_LIMIT`).
    pub bad_samples: u64,
    pub rays: u64,
    pub seconds: f64,
}

pub use crate::color::illuminance;

/// One pixel's sampling state within a tile.
struct PixelState {
    x: u32,
    y: u32,
    /// Index of the next sample; the first is `Share::Samples`' `lo`.
    next: u32,
    /// This pixel's draws (the pilot's are seeded apart).
    sampler: Sampler,
    sums: PixelSums,
    /// Illuminance moments for the adaptive rule.
    s1: f64,
    s2: f64,
    /// Samples to take (at most).
    max: u32,
    done: bool,
    bad: u64,
}

impl PixelState {
    fn new(x: u32, y: u32, kind: SamplerKind, seed: u64, spp: u32, first: u32, max: u32) -> Self {
        PixelState { x, y, next: first, sampler: Sampler::for_pixel(kind, seed, x, y, spp), sums: PixelSums::default(), s1: 0.0, s2: 0.0, max, done: max == 0, bad: 0 }
    }

    /// Switch to the draws of the next sample.
    fn start_sample(&mut self) {
        self.sampler.start(self.next);
        self.next += 1;
    }

    /// Add a sample; with `rule`, stop by CS184's criterion, checked every
    /// `batch` samples on the samples taken so far.
    fn add(&mut self, l: Vec3, rule: Option<Adaptive>) {
        self.bad += self.sums.add(l.to_array()) as u64;
        let n = self.sums.n;
        let il = illuminance(l) as f64;
        self.s1 += il;
        self.s2 += il * il;
        if let Some(a) = rule {
            if n % a.batch == 0 {
                let nf = n as f64;
                let mu = self.s1 / nf;
                let var = ((self.s2 - self.s1 * self.s1 / nf) / (nf - 1.0)).max(0.0);
                if 1.96 * var.sqrt() / nf.sqrt() <= a.tolerance as f64 * mu {
                    self.done = true;
                }
            }
        }
        if n >= self.max {
            self.done = true;
        }
    }
}

/// Sample every pixel of a tile up to its `max` (or until `rule` stops it),
/// in rounds: one camera ray per unfinished pixel per round, traced as one
/// coherent batch. Each sample draws from its own stream (jitter, then the
/// path), so the image does not depend on batching, tiling, threads or how
/// the samples are split between processes.
#[allow(clippy::too_many_arguments)]
fn sample_tile(camera: &Camera, accel: &dyn Traversal, integ: &dyn Integrator, s: &RenderSettings, px: &mut [PixelState], rule: Option<Adaptive>, rays: &mut u64, splats: &mut Vec<Splat>) {
    let splatting = integ.splats();
    let (w, h) = (s.width as f32, s.height as f32);
    let mut active: Vec<usize> = (0..px.len()).filter(|&i| !px[i].done).collect();
    let mut batch: Vec<Ray> = Vec::with_capacity(active.len());
    let mut hits: Vec<Option<Hit>> = Vec::with_capacity(active.len());
    let mut radiance: Vec<Vec3> = Vec::with_capacity(active.len());
    let plane = camera.image_plane();
    while !active.is_empty() {
        batch.clear();
        for &i in &active {
            let p = &mut px[i];
            p.start_sample();
            // Splats are box-filtered over their pixel: the camera samples
            // must be too, even at one sample per pixel.
            let (jx, jy) = if s.spp == 1 && s.centre_single_sample && !splatting { (0.5, 0.5) } else { p.sampler.camera() };
            let (x, y) = ((p.x as f32 + jx) / w, (p.y as f32 + jy) / h);
            // A pinhole draws nothing more: `-b 0` images are those of a
            // camera without a lens, bit for bit.
            batch.push(if camera.has_lens() { camera.generate_ray_thin_lens_on(plane, x, y, p.sampler.lens()) } else { camera.generate_ray_on(plane, x, y) });
        }
        hits.clear();
        hits.resize(batch.len(), None);
        *rays += batch.len() as u64;
        if s.batch_rays {
            accel.intersect_coherent(&batch, &mut hits);
        } else {
            for (r, h) in batch.iter().zip(hits.iter_mut()) {
                *h = accel.intersect(r);
            }
        }
        if splatting {
            for (k, &i) in active.iter().enumerate() {
                let p = &mut px[i];
                let l = integ.radiance_splat(accel, &batch[k], hits[k], &mut p.sampler, rays, splats);
                p.add(l, rule);
            }
        } else if s.batch_rays {
            // `active` lists exactly the unfinished pixels, in order.
            let mut samplers: Vec<&mut Sampler> = px.iter_mut().filter(|p| !p.done).map(|p| &mut p.sampler).collect();
            debug_assert_eq!(samplers.len(), active.len());
            radiance.clear();
            radiance.resize(batch.len(), Vec3::ZERO);
            integ.radiance_batch(accel, &batch, &hits, &mut samplers, &mut radiance, rays);
            for (k, &i) in active.iter().enumerate() {
                px[i].add(radiance[k], rule);
            }
        } else {
            for (k, &i) in active.iter().enumerate() {
                let p = &mut px[i];
                let l = integ.radiance_from(accel, &batch[k], hits[k], &mut p.sampler, rays);
                p.add(l, rule);
            }
        }
        active.retain(|&i| !px[i].done);
    }
}

/// Seed tag of the pilot streams, so pilot samples never reuse image samples.
const PILOT_TAG: u64 = 0x7069_6c6f_7420_5f5f;

/// The pixels `(x, y)` of one tile, in frame coordinates: their sums, the
/// number of out-of-range samples, the rays traced and the splats made.
fn render_tile(camera: &Camera, accel: &dyn Traversal, integ: &dyn Integrator, s: &RenderSettings, pixels: &[(u32, u32)]) -> (Vec<PixelSums>, u64, u64, Vec<Splat>) {
    let mut rays = 0u64;
    let mut splats = Vec::new();
    let (lo, hi) = match s.share {
        Share::Samples { lo, hi } => (lo, hi),
        _ => (0, s.spp),
    };
    let px = match s.adaptive {
        Some(a) if a.pilot => {
            // Kirk and Arvo's two-stage sampling: decide the count on pilot
            // samples, throw them away, average fresh ones. The stopping
            // decision is then independent of the samples averaged: unbiased.
            let mut pilot: Vec<PixelState> = pixels.iter().map(|&(x, y)| PixelState::new(x, y, s.sampler, s.seed ^ PILOT_TAG, s.spp, 0, s.spp)).collect();
            sample_tile(camera, accel, integ, s, &mut pilot, Some(a), &mut rays, &mut Vec::new());
            let mut px: Vec<PixelState> =
                pixels.iter().zip(&pilot).map(|(&(x, y), p)| PixelState::new(x, y, s.sampler, s.seed, s.spp, 0, p.sums.n)).collect();
            sample_tile(camera, accel, integ, s, &mut px, None, &mut rays, &mut splats);
            px
        }
        rule => {
            let mut px: Vec<PixelState> = pixels.iter().map(|&(x, y)| PixelState::new(x, y, s.sampler, s.seed, s.spp, lo, hi - lo)).collect();
            sample_tile(camera, accel, integ, s, &mut px, rule, &mut rays, &mut splats);
            px
        }
    };
    let bad = px.iter().map(|p| p.bad).sum();
    (px.into_iter().map(|p| p.sums).collect(), bad, rays, splats)
}

/// Render `settings.region` (or the whole frame) with `integ`, tracing with
/// `accel`: all of it, or the share `settings.share` names.
pub fn render(camera: &Camera, accel: &dyn Traversal, integ: &dyn Integrator, settings: &RenderSettings) -> RenderOutput {
    let start = Instant::now();
    let region = settings.region();
    let (cols, rows) = tile_grid(region);
    let tiles: Vec<(u32, u32)> =
        (0..cols * rows).filter(|&k| settings.share.has_tile(k)).map(|k| ((k % cols) * TILE, (k / cols) * TILE)).collect();
    let bar = if settings.progress {
        let b = ProgressBar::with_draw_target(Some(tiles.len() as u64), ProgressDrawTarget::stderr());
        b.set_style(ProgressStyle::with_template("{bar:40} {percent:>3}% tiles {pos}/{len} eta {eta}").unwrap());
        b
    } else {
        ProgressBar::hidden()
    };
    // Local (x, y) count from the region's top-left; the frame's y runs up
    // from the bottom, so local row ly is frame row region.y + region.h - 1 - ly.
    let done: Vec<(Vec<(u32, u32)>, Vec<PixelSums>, u64, u64, Vec<Splat>)> = tiles
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
            let (sums, bad, rays, splats) = render_tile(camera, accel, integ, settings, &frame);
            bar.inc(1);
            (local, sums, bad, rays, splats)
        })
        .collect();
    bar.finish_and_clear();
    let mut out = RenderOutput::blank(region.w, region.h);
    if settings.keep_sums {
        out.sums = vec![PixelSums::default(); (region.w * region.h) as usize];
    }
    let mut cam_sums = vec![PixelSums::default(); (region.w * region.h) as usize];
    let mut film = if integ.splats() { vec![SplatSums::default(); cam_sums.len()] } else { Vec::new() };
    for (local, sums, bad, tile_rays, splats) in done {
        for ((lx, ly), p) in local.into_iter().zip(sums) {
            cam_sums[(ly * region.w + lx) as usize] = p;
        }
        out.bad_samples += bad;
        out.rays += tile_rays;
        // Splats landing outside the region are dropped (each light
        // subpath estimates the whole frame; the region is part of it).
        for sp in splats {
            let inside = sp.x >= region.x && sp.x < region.x + region.w && sp.y >= region.y && sp.y < region.y + region.h;
            if inside {
                let (lx, ly) = (sp.x - region.x, region.y + region.h - 1 - sp.y);
                out.bad_samples += film[(ly * region.w + lx) as usize].add(sp.l) as u64;
            }
        }
    }
    out.fill(&cam_sums, &film, settings.width as u64 * settings.height as u64);
    if settings.keep_sums {
        out.sums = cam_sums;
        out.splats = film;
    }
    out.seconds = start.elapsed().as_secs_f64();
    out
}

impl RenderOutput {
    /// The images of a render from every pixel's sums (`merge` makes its
    /// output with this, so it writes exactly what the render would have).
    /// `splats`: the film of splats (empty for integrators without), for a
    /// frame of `frame_pixels`.
    pub fn from_sums(width: u32, height: u32, sums: Vec<PixelSums>, splats: Vec<SplatSums>, frame_pixels: u64) -> RenderOutput {
        let mut out = RenderOutput::blank(width, height);
        out.fill(&sums, &splats, frame_pixels);
        out.sums = sums;
        out.splats = splats;
        out
    }

    /// The images from every pixel's sums and, when there are splats, the
    /// film's estimate added (normalised by the light subpaths traced: one
    /// per sample of every pixel, see `splat`).
    fn fill(&mut self, sums: &[PixelSums], splats: &[SplatSums], frame_pixels: u64) {
        for (i, p) in sums.iter().enumerate() {
            self.set_pixel(i, p);
        }
        if splats.is_empty() {
            return;
        }
        let light_paths: u64 = sums.iter().map(|p| p.n as u64).sum();
        for (i, sp) in splats.iter().enumerate() {
            let (m, v) = sp.estimate(light_paths, frame_pixels);
            self.image.pixels[i] += Vec3::from_array(m);
            self.variance.pixels[i] += Vec3::from_array(v);
        }
    }

    /// Black images, no samples, no sums.
    fn blank(width: u32, height: u32) -> RenderOutput {
        RenderOutput {
            image: Rgb::new(width, height),
            variance: Rgb::new(width, height),
            samples: vec![0u32; (width * height) as usize],
            sums: Vec::new(),
            splats: Vec::new(),
            bad_samples: 0,
            rays: 0,
            seconds: 0.0,
        }
    }

    fn set_pixel(&mut self, i: usize, p: &PixelSums) {
        self.image.pixels[i] = Vec3::from_array(p.mean());
        self.variance.pixels[i] = Vec3::from_array(p.var_of_mean());
        self.samples[i] = p.n;
    }
}
