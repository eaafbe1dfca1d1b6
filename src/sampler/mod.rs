//! Samplers: where each random number a pixel sample uses comes from.
//!
//! One interface, two samplers: `Independent` (uniform random numbers from
//! a counter-based hash, the A/B baseline; CS184 draws independent numbers
//! too) and Owen-scrambled, shuffled Sobol (`sobol.rs`), in two variants:
//! `SobolPadded`, every 2D draw its own sequence, and `Sobol` (the
//! default), which takes the first vertex's first light sample and the
//! position in the pixel from one 4D point, so the pair is stratified
//! jointly (Burley 2020's 4D sets; Cycles 3.4 pads them apart). Draws are
//! addressed, not streamed: a draw is (pixel, sample index, dimension id),
//! so the integrator gives every use a fixed id (`dim`) and a draw that one
//! path skips never shifts the numbers another draw sees.
//!
//! The 4D pairing, measured (CBspheres_lambertian `-m 1`, 160×120, 8 seeds,
//! 1 thread, against 8192 spp): relMSE padded / paired 3.74e-5 / 3.53e-5 at
//! 16 spp, 5.04e-6 / 3.89e-6 at 64, 8.64e-7 / 5.14e-7 at 256 (1.06×, 1.30×,
//! 1.68×), same time; the copper Cornell bunny `-m 5` (glossy, indirect
//! light) within 0.3 %. The light draw's own 2D projection is Sobol
//! dimensions 2 and 3, a (1,m,2)-net in aligned blocks of 2^m ≥ 16
//! (dimensions 0 and 1: (0,m,2)).
//!
//! The integrator draws through `camera`, `lens` and, at path vertex
//! `bounce` (set with `set_bounce`), `slot_1d`/`slot_2d`.

pub mod sobol;

use crate::rng::mix64;

/// Which sampler a render draws from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SamplerKind {
    Independent,
    /// Owen-scrambled Sobol, the first light sample paired with the pixel.
    Sobol,
    /// Owen-scrambled Sobol, every draw its own sequence.
    SobolPadded,
}

/// Fixed dimension ids: the camera's, then 16 per bounce.
pub mod dim {
    /// Position within the pixel (vertex 0's slots).
    pub const CAMERA: u64 = 0;
    /// Point on the lens.
    pub const LENS: u64 = 1;
    /// Light-sample slots at a vertex (one per light and per `-l` sample:
    /// see `at_bounce`'s `k`).
    pub const LIGHT_CHOICE: u32 = 0;
    pub const LIGHT: u32 = 1;
    /// BSDF lobe choice (glass: reflect or refract) and direction.
    pub const BSDF_LOBE: u32 = 2;
    pub const BSDF: u32 = 3;
    pub const RUSSIAN_ROULETTE: u32 = 4;
    /// `-H` hemisphere directions.
    pub const HEMISPHERE: u32 = 5;
    /// Which light a light sample picks (`light::pick`), per `-l` sample.
    pub const LIGHT_PICK: u32 = 6;
    /// Bidirectional path tracing, at camera vertex `bounce`: the light a
    /// next-event connection (s = 1) picks, its triangle, its point.
    pub const CONNECT_PICK: u32 = 7;
    pub const CONNECT_SELECT: u32 = 8;
    pub const CONNECT_POINT: u32 = 9;
    /// Light subpaths (`light_vertex`): at vertex 0, the light picked, its
    /// triangle, the point and the direction; at vertex i, the lens point a
    /// light-tracing connection (t = 1) of y(i) chooses; `BSDF_LOBE`,
    /// `BSDF` and `RUSSIAN_ROULETTE` as at camera vertices.
    pub const EMIT_PICK: u32 = 10;
    pub const EMIT_SELECT: u32 = 11;
    pub const EMIT_POINT: u32 = 12;
    pub const EMIT_DIRECTION: u32 = 13;
    pub const LENS_CONNECT: u32 = 14;
    /// Whether a pixel sample traces a light subpath at all
    /// (`--bdpt-light-paths specular`).
    pub const EMIT_SHARE: u32 = 15;

    /// The id of `slot` at vertex `vertex` of a light subpath (0 = on the
    /// light): bit 47 set, which no camera-side id below `k` = 2^39 has.
    pub fn light_vertex(vertex: u32, slot: u32) -> u64 {
        (1u64 << 47) | ((vertex as u64) << 16) | (0x80 | slot) as u64
    }

    /// The id of `slot` at path vertex `bounce` (1 = the camera ray's hit),
    /// for the `k`-th of several draws of that slot (light `i`'s sample `j`
    /// of `n`: `k = i·n + j`). Ids are distinct for k < 2^40 and bounces
    /// below 2^16 (`-m` is at most 100000: deeper vertices share ids with
    /// shallower ones, which costs stratification, not correctness).
    pub fn at_bounce(bounce: u32, slot: u32, k: u64) -> u64 {
        ((bounce as u64) << 48) ^ (k << 8) ^ slot as u64
    }
}

/// The draws of one pixel's samples.
#[derive(Clone, Copy, Debug)]
pub struct Sampler {
    kind: SamplerKind,
    pixel_seed: u64,
    index: u32,
    /// `index` as the Sobol draws take it (`sobol::reversed_index`).
    rev_index: u32,
    /// Every sample index of the render is below 2^index_bits.
    index_bits: u32,
    /// The path vertex the slot draws are for (1 = the camera ray's hit).
    bounce: u32,
}

impl Sampler {
    /// The draws of pixel (x, y) of a render of `spp` samples per pixel.
    pub fn for_pixel(kind: SamplerKind, seed: u64, x: u32, y: u32, spp: u32) -> Sampler {
        let index_bits = 32 - spp.saturating_sub(1).leading_zeros();
        Sampler { kind, pixel_seed: mix64(seed ^ mix64(((y as u64) << 32) | x as u64)), index: 0, rev_index: 0, index_bits, bounce: 1 }
    }

    /// Draw for sample `index`, from its camera ray on.
    pub fn start(&mut self, index: u32) {
        debug_assert!(self.index_bits == 32 || index >> self.index_bits == 0, "index {index} of 2^{}", self.index_bits);
        self.index = index;
        self.rev_index = sobol::reversed_index(index, self.index_bits);
        self.bounce = 1;
    }

    /// The path vertex the following slot draws are for (1 = the camera
    /// ray's hit).
    pub fn set_bounce(&mut self, bounce: u32) {
        self.bounce = bounce;
    }

    /// The position in the pixel.
    pub fn camera(&self) -> (f32, f32) {
        self.get_2d(dim::CAMERA)
    }

    /// The point on the lens.
    pub fn lens(&self) -> (f32, f32) {
        self.get_2d(dim::LENS)
    }

    /// Draw `k` of `slot` at the current vertex.
    #[inline]
    pub fn slot_1d(&self, slot: u32, k: u64) -> f32 {
        self.get_1d(dim::at_bounce(self.bounce, slot, k))
    }

    #[inline]
    pub fn slot_2d(&self, slot: u32, k: u64) -> (f32, f32) {
        if self.bounce == 1 && slot == dim::LIGHT && k == 0 && self.kind == SamplerKind::Sobol {
            // The camera's 4D point: its first two coordinates are `camera`.
            let p = sobol::sample_4d(self.pixel_seed, dim::CAMERA, self.rev_index, self.index_bits);
            return (p[2], p[3]);
        }
        self.get_2d(dim::at_bounce(self.bounce, slot, k))
    }

    #[inline]
    fn hashed(&self, dim: u64) -> u64 {
        mix64(self.pixel_seed ^ mix64(mix64(dim) ^ self.index as u64))
    }

    #[inline]
    pub fn get_1d(&self, dim: u64) -> f32 {
        match self.kind {
            SamplerKind::Independent => sobol::to_unit(self.hashed(dim) as u32),
            SamplerKind::Sobol | SamplerKind::SobolPadded => sobol::sample_1d(self.pixel_seed, dim, self.rev_index, self.index_bits),
        }
    }

    #[inline]
    pub fn get_2d(&self, dim: u64) -> (f32, f32) {
        match self.kind {
            SamplerKind::Independent => {
                let h = self.hashed(dim);
                (sobol::to_unit(h as u32), sobol::to_unit((h >> 32) as u32))
            }
            SamplerKind::Sobol | SamplerKind::SobolPadded => sobol::sample_2d(self.pixel_seed, dim, self.rev_index, self.index_bits),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two-sided z test that E[a·b] = 0 for centred draws, with the
    /// standard error taken from the products' own sample variance.
    fn z_of_products(a: &[f32], b: &[f32]) -> f64 {
        let p: Vec<f64> = a.iter().zip(b).map(|(&x, &y)| (x as f64 - 0.5) * (y as f64 - 0.5)).collect();
        let n = p.len() as f64;
        let mean = p.iter().sum::<f64>() / n;
        let var = p.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0);
        mean / (var / n).sqrt()
    }

    #[test]
    fn pixels_and_dimensions_are_uncorrelated() {
        // 2 samplers x 5 pairings x 20 cases = 200 tests; Šidák at
        // family-wise 1e-3 gives |z| < 4.75.
        let n = 4096;
        for kind in [SamplerKind::Independent, SamplerKind::Sobol] {
            for case in 0..20u32 {
                let draws = |x: u32, y: u32, d: u64, second: bool| -> Vec<f32> {
                    let mut s = Sampler::for_pixel(kind, 9, x, y, n);
                    (0..n)
                        .map(|i| {
                            s.start(i);
                            let (u, v) = s.get_2d(d);
                            if second { v } else { u }
                        })
                        .collect()
                };
                let (x, y) = (case * 7 % 13, case * 3 % 11);
                let base = draws(x, y, dim::at_bounce(1, dim::LIGHT, 0), false);
                for (what, other) in [
                    ("neighbouring pixel", draws(x + 1, y, dim::at_bounce(1, dim::LIGHT, 0), false)),
                    ("other dimension", draws(x, y, dim::at_bounce(1, dim::BSDF, 0), false)),
                    ("next bounce", draws(x, y, dim::at_bounce(2, dim::LIGHT, 0), false)),
                    ("second light sample", draws(x, y, dim::at_bounce(1, dim::LIGHT, 1), false)),
                    ("same draw's other coordinate", draws(x, y, dim::at_bounce(1, dim::LIGHT, 0), true)),
                ] {
                    let z = z_of_products(&base, &other);
                    assert!(z.abs() < 4.75, "{kind:?} case {case}: {what} correlated, z = {z:.2}");
                }
            }
        }
    }

    #[test]
    fn scrambled_point_sets_integrate_without_bias() {
        // Per pixel seed, the mean of f over the spp points of one pixel;
        // over 100k pixel seeds, that mean must equal ∫f within 4.5 of its
        // own standard errors (16 tests, Šidák at family-wise 1e-4).
        let n = 100_000u32;
        for spp in [1u32, 2, 4, 16] {
            let fs: [(&str, f64, fn((f32, f32), (f32, f32)) -> f64); 4] = [
                ("a", 0.5, |(a, _), _| a as f64),
                ("[a+b<0.7]", 0.245, |(a, b), _| ((a + b) < 0.7) as u32 as f64),
                ("a·c", 0.25, |(a, _), (c, _)| (a * c) as f64),
                ("[b+d<0.5]", 0.125, |(_, b), (_, d)| ((b + d) < 0.5) as u32 as f64),
            ];
            for (name, exact, f) in fs {
                let (mut sum, mut sum2) = (0.0f64, 0.0f64);
                for p in 0..n {
                    let mut s = Sampler::for_pixel(SamplerKind::Sobol, 5, p % 1000, p / 1000, spp);
                    let mut est = 0.0;
                    for i in 0..spp {
                        s.start(i);
                        est += f(s.camera(), s.slot_2d(dim::LIGHT, 0));
                    }
                    est /= spp as f64;
                    sum += est;
                    sum2 += est * est;
                }
                let mean = sum / n as f64;
                let se = ((sum2 / n as f64 - mean * mean).max(0.0) / n as f64).sqrt().max(1e-12);
                let z = (mean - exact) / se;
                assert!(z.abs() < 4.5, "spp {spp}, E[{name}] = {mean:.5} vs {exact}: z = {z:.2}");
            }
        }
    }

    #[test]
    fn draws_are_uniform_and_repeatable() {
        for kind in [SamplerKind::Independent, SamplerKind::Sobol] {
            let n = 1 << 14;
            let mut s = Sampler::for_pixel(kind, 1, 2, 3, n);
            let mut bins = [0u32; 16];
            for i in 0..n {
                s.start(i);
                let u = s.get_1d(40);
                assert!((0.0..1.0).contains(&u));
                bins[(u * 16.0) as usize] += 1;
                assert_eq!(s.get_2d(7), s.get_2d(7));
            }
            // χ² with 15 degrees of freedom, p = 1e-4 at 42.3 (a net is far below).
            let e = n as f64 / 16.0;
            let chi2: f64 = bins.iter().map(|&b| (b as f64 - e).powi(2) / e).sum();
            assert!(chi2 < 42.3, "{kind:?}: χ² {chi2:.1}");
        }
    }

    /// `Sobol` draws the first vertex's first light sample from the camera's
    /// 4D point (the pixel position its first two coordinates); every other
    /// light draw, and every draw of `SobolPadded`, is its own sequence.
    #[test]
    fn the_first_light_sample_is_paired_with_the_pixel() {
        for index in 0..64 {
            let mut paired = Sampler::for_pixel(SamplerKind::Sobol, 9, 3, 4, 64);
            let mut padded = Sampler::for_pixel(SamplerKind::SobolPadded, 9, 3, 4, 64);
            paired.start(index);
            padded.start(index);
            let p = sobol::sample_4d(paired.pixel_seed, dim::CAMERA, paired.rev_index, paired.index_bits);
            assert_eq!(paired.camera(), (p[0], p[1]));
            assert_eq!(padded.camera(), (p[0], p[1]));
            assert_eq!(paired.slot_2d(dim::LIGHT, 0), (p[2], p[3]));
            assert_ne!(padded.slot_2d(dim::LIGHT, 0), (p[2], p[3]));
            assert_eq!(paired.slot_2d(dim::LIGHT, 1), padded.slot_2d(dim::LIGHT, 1));
            assert_eq!(paired.slot_2d(dim::BSDF, 0), padded.slot_2d(dim::BSDF, 0));
            paired.set_bounce(2);
            padded.set_bounce(2);
            assert_eq!(paired.slot_2d(dim::LIGHT, 0), padded.slot_2d(dim::LIGHT, 0));
        }
    }
}
