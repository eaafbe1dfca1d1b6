//! Samplers: where each random number a pixel sample uses comes from.
//!
//! One interface, two samplers: `Independent` (uniform random numbers from
//! a counter-based hash, the A/B baseline; CS184 draws independent numbers
//! too) and `Sobol` (Owen-scrambled, shuffled Sobol, `sobol.rs`). Draws are
//! addressed, not streamed: a draw is (pixel, sample index, dimension id),
//! so the integrator gives every use a fixed id (`dim`) and a draw that one
//! path skips never shifts the numbers another draw sees.
//!
//! Status: the module and its tests (nets, decorrelation, uniformity) are
//! here; the integrator still draws from `rng::Rng` (issue 13 wires it in).

pub mod sobol;

use crate::rng::mix64;

/// Which sampler a render draws from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SamplerKind {
    Independent,
    Sobol,
}

/// Fixed dimension ids: the camera's, then 16 per bounce.
pub mod dim {
    /// Position within the pixel.
    pub const CAMERA: u32 = 0;
    /// Point on the lens.
    pub const LENS: u32 = 1;
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

    /// The id of `slot` at path vertex `bounce` (0 = the camera ray's hit),
    /// for the `k`-th of several draws of that slot (light samples).
    pub fn at_bounce(bounce: u32, slot: u32, k: u32) -> u32 {
        16 * (bounce + 1) + slot + (k << 20)
    }
}

/// The draws of one pixel's samples.
#[derive(Clone, Copy, Debug)]
pub struct Sampler {
    kind: SamplerKind,
    pixel_seed: u64,
    index: u32,
}

impl Sampler {
    pub fn for_pixel(kind: SamplerKind, seed: u64, x: u32, y: u32) -> Sampler {
        Sampler { kind, pixel_seed: mix64(seed ^ mix64(((y as u64) << 32) | x as u64)), index: 0 }
    }

    /// Draw from sample `index` on.
    pub fn start(&mut self, index: u32) {
        self.index = index;
    }

    #[inline]
    fn hashed(&self, dim: u32) -> u64 {
        mix64(self.pixel_seed ^ mix64(((self.index as u64) << 32) | dim as u64))
    }

    #[inline]
    pub fn get_1d(&self, dim: u32) -> f32 {
        match self.kind {
            SamplerKind::Independent => sobol::to_unit(self.hashed(dim) as u32),
            SamplerKind::Sobol => sobol::sample_1d(self.pixel_seed, dim, self.index),
        }
    }

    #[inline]
    pub fn get_2d(&self, dim: u32) -> (f32, f32) {
        match self.kind {
            SamplerKind::Independent => {
                let h = self.hashed(dim);
                (sobol::to_unit(h as u32), sobol::to_unit((h >> 32) as u32))
            }
            SamplerKind::Sobol => sobol::sample_2d(self.pixel_seed, dim, self.index),
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
        // 2 samplers x 3 pairings x 20 cases = 120 tests; Šidák at
        // family-wise 1e-3 gives |z| < 4.6.
        let n = 4096;
        for kind in [SamplerKind::Independent, SamplerKind::Sobol] {
            for case in 0..20u32 {
                let draws = |x: u32, y: u32, d: u32, second: bool| -> Vec<f32> {
                    let mut s = Sampler::for_pixel(kind, 9, x, y);
                    (0..n)
                        .map(|i| {
                            s.start(i);
                            let (u, v) = s.get_2d(d);
                            if second { v } else { u }
                        })
                        .collect()
                };
                let (x, y) = (case * 7 % 13, case * 3 % 11);
                let base = draws(x, y, dim::at_bounce(0, dim::LIGHT, 0), false);
                for (what, other) in [
                    ("neighbouring pixel", draws(x + 1, y, dim::at_bounce(0, dim::LIGHT, 0), false)),
                    ("other dimension", draws(x, y, dim::at_bounce(0, dim::BSDF, 0), false)),
                    ("next bounce", draws(x, y, dim::at_bounce(1, dim::LIGHT, 0), false)),
                ] {
                    let z = z_of_products(&base, &other);
                    assert!(z.abs() < 4.6, "{kind:?} case {case}: {what} correlated, z = {z:.2}");
                }
            }
        }
    }

    #[test]
    fn draws_are_uniform_and_repeatable() {
        for kind in [SamplerKind::Independent, SamplerKind::Sobol] {
            let mut s = Sampler::for_pixel(kind, 1, 2, 3);
            let n = 1 << 14;
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
}
