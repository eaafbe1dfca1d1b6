//! The environment light (`-e FILE.exr`): radiance from every direction, read
//! from a latitude-longitude OpenEXR image, seen by every ray that escapes.
//!
//! Mapping (CS184's, exactly): θ = acos(d.y) (+y up, θ = 0 the top row),
//! φ = atan2(−d.z, d.x) + π; texel coordinates x = φ/2π·w, y = θ/π·h, texel
//! centres at half-integers. Lookup is CS184's bilinear filter: wrapping
//! horizontally, clamped vertically (constant above the first row's centres
//! and below the last's). Channels are read by name (R, G, B; any
//! compression the `exr` crate reads, DWAA/DWAB included); negative texels
//! (ringing of lossy compression) are clamped to 0.
//!
//! Importance sampling, where we differ from CS184: CS184 picks a texel by
//! luminance × sin θ and returns its *corner* direction with the unfiltered
//! texel's radiance, a Riemann sum that is biased (w·h discrete directions,
//! an infinite pdf on row 0, a radiance that is not what escaping rays see).
//! Here a texel is picked with probability ∝ (integral of the bilinear
//! luminance over the texel) × sin θ at its centre, the direction is jittered
//! uniformly inside the texel (the leftover of the two uniforms that picked
//! it), and the pdf is the exact density of that direction,
//! p(texel)·w·h / (2π² sin θ) with the sample's own θ. The value returned is
//! the same bilinear lookup escaping rays see. Every texel whose bilinear
//! support can be non-zero has a positive probability (the integral covers
//! the 3×3 neighbourhood), so the estimator is unbiased.

use crate::error::Result;
use crate::render::illuminance;
use glam::Vec3;
use std::f64::consts::PI;
use std::path::Path;

/// sin θ of the f32 directions nearest the poles (1 − 2⁻²⁴ in y): where a
/// direction rounds onto a pole, `sample` and `pdf` both use this value, so
/// they stay consistent (the solid angle involved is ~1e-7 sr).
const POLE_SIN: f64 = 3.4526698e-4;

#[derive(Debug)]
pub struct EnvMap {
    pub path: String,
    pub width: usize,
    pub height: usize,
    /// Row 0 is the top (θ = 0).
    pub texels: Vec<Vec3>,
    /// Cumulative row probabilities (length h + 1, from 0 to 1).
    row_cdf: Vec<f64>,
    /// Per row, cumulative column probabilities within the row (w + 1 each).
    col_cdf: Vec<f64>,
    /// Probability of each texel (row-major).
    prob: Vec<f64>,
}

impl EnvMap {
    pub fn load(path: &Path) -> Result<EnvMap> {
        if !path.exists() {
            crate::bail!("{}: environment map not found", path.display());
        }
        let img = crate::image_io::read_exr(path)?;
        let (w, h) = (img.width as usize, img.height as usize);
        if w < 2 || h < 2 {
            crate::bail!("{}: environment map is {w}x{h}; a latitude-longitude map needs at least 2x2 texels", path.display());
        }
        let mut texels = img.pixels;
        let mut bad = 0usize;
        for t in texels.iter_mut() {
            if !t.is_finite() {
                bad += 1;
            }
            *t = t.max(Vec3::ZERO);
        }
        if bad > 0 {
            crate::bail!("{}: environment map has {bad} texels that are NaN or infinite", path.display());
        }
        Ok(Self::from_texels(path.display().to_string(), w, h, texels))
    }

    pub fn from_texels(path: String, width: usize, height: usize, texels: Vec<Vec3>) -> EnvMap {
        let (w, h) = (width, height);
        let lum: Vec<f64> = texels.iter().map(|&t| illuminance(t.max(Vec3::ZERO)) as f64).collect();
        // Integral of the bilinear function over a texel: in 1D, over
        // [i, i+1] with centres at i + 0.5, it is 1/8, 3/4, 1/8 of texels
        // i-1, i, i+1 (wrapping in x, clamped in y as the lookup is).
        const K: [f64; 3] = [0.125, 0.75, 0.125];
        let mut horiz = vec![0.0f64; w * h];
        for j in 0..h {
            for i in 0..w {
                horiz[j * w + i] = (0..3).map(|k| K[k] * lum[j * w + (i + w + k - 1) % w]).sum();
            }
        }
        let mut weight = vec![0.0f64; w * h];
        for j in 0..h {
            let sin = (PI * (j as f64 + 0.5) / h as f64).sin();
            for i in 0..w {
                let s: f64 = (0..3).map(|k| K[k] * horiz[(j + k).saturating_sub(1).min(h - 1) * w + i]).sum();
                weight[j * w + i] = s * sin;
            }
        }
        let total: f64 = weight.iter().sum();
        let mut prob = vec![0.0f64; w * h];
        let mut row_cdf = vec![0.0f64; h + 1];
        let mut col_cdf = vec![0.0f64; (w + 1) * h];
        if total > 0.0 {
            for j in 0..h {
                let row: f64 = weight[j * w..(j + 1) * w].iter().sum();
                row_cdf[j + 1] = row_cdf[j] + row / total;
                let mut acc = 0.0;
                for i in 0..w {
                    prob[j * w + i] = weight[j * w + i] / total;
                    acc += weight[j * w + i];
                    col_cdf[j * (w + 1) + i + 1] = if row > 0.0 { acc / row } else { (i + 1) as f64 / w as f64 };
                }
            }
            row_cdf[h] = 1.0;
        }
        EnvMap { path, width, height, texels, row_cdf, col_cdf, prob }
    }

    /// Whether the map is black everywhere (nothing to sample).
    pub fn is_black(&self) -> bool {
        self.row_cdf[self.height] == 0.0
    }

    /// (x, y) texel coordinates of a unit direction, x in [0, w), y in [0, h].
    fn texel_coords(&self, d: Vec3) -> (f64, f64, f64) {
        let d = d.as_dvec3();
        let cos_t = d.y.clamp(-1.0, 1.0);
        let theta = cos_t.acos();
        let phi = (-d.z).atan2(d.x) + PI;
        let x = (phi / (2.0 * PI) * self.width as f64).rem_euclid(self.width as f64);
        let y = theta / PI * self.height as f64;
        (x, y, (1.0 - cos_t * cos_t).max(0.0).sqrt())
    }

    fn texel(&self, i: i64, j: i64) -> Vec3 {
        let (w, h) = (self.width as i64, self.height as i64);
        self.texels[(j.clamp(0, h - 1) * w + i.rem_euclid(w)) as usize]
    }

    /// Radiance arriving from direction `d` (unit, pointing away from the
    /// receiver): CS184's bilinear lookup.
    pub fn eval(&self, d: Vec3) -> Vec3 {
        let (x, y, _) = self.texel_coords(d);
        self.bilerp(x, y)
    }

    fn bilerp(&self, x: f64, y: f64) -> Vec3 {
        let (fx, fy) = (x - 0.5, y - 0.5);
        let (i0, j0) = (fx.floor(), fy.floor());
        let (tx, ty) = ((fx - i0) as f32, (fy - j0) as f32);
        let (i0, j0) = (i0 as i64, j0 as i64);
        let top = self.texel(i0, j0) * (1.0 - tx) + self.texel(i0 + 1, j0) * tx;
        let bottom = self.texel(i0, j0 + 1) * (1.0 - tx) + self.texel(i0 + 1, j0 + 1) * tx;
        top * (1.0 - ty) + bottom * ty
    }

    /// Direction of texel coordinates (x, y).
    fn direction(&self, x: f64, y: f64) -> (Vec3, f64) {
        let phi = x / self.width as f64 * 2.0 * PI;
        let theta = y / self.height as f64 * PI;
        let (st, ct) = theta.sin_cos();
        let (sp, cp) = phi.sin_cos();
        (Vec3::new((-cp * st) as f32, ct as f32, (sp * st) as f32), st)
    }

    /// Solid-angle pdf of `sample` for direction `d`.
    pub fn pdf(&self, d: Vec3) -> f32 {
        if self.is_black() {
            return 0.0;
        }
        let (x, y, sin_t) = self.texel_coords(d);
        let sin_t = sin_t.max(POLE_SIN);
        let i = (x as usize).min(self.width - 1);
        let j = (y as usize).min(self.height - 1);
        self.texel_pdf(self.prob[j * self.width + i], sin_t)
    }

    fn texel_pdf(&self, p: f64, sin_t: f64) -> f32 {
        (p * (self.width * self.height) as f64 / (2.0 * PI * PI * sin_t)) as f32
    }

    /// A direction with probability ∝ the table, its radiance and its pdf;
    /// `None` for a black map or a sample exactly at a pole.
    pub fn sample(&self, u: (f32, f32)) -> Option<(Vec3, Vec3, f32)> {
        if self.is_black() {
            return None;
        }
        let (w, h) = (self.width, self.height);
        // Row from u.1, then column from u.0 within it; each uniform's
        // leftover inside the chosen interval jitters the point in the texel.
        let u1 = u.1 as f64;
        let j = (self.row_cdf.partition_point(|&c| c <= u1) - 1).min(h - 1);
        let (r0, r1) = (self.row_cdf[j], self.row_cdf[j + 1]);
        let dy = if r1 > r0 { ((u1 - r0) / (r1 - r0)).clamp(0.0, 1.0) } else { 0.5 };
        let cdf = &self.col_cdf[j * (w + 1)..(j + 1) * (w + 1)];
        let u0 = u.0 as f64;
        let i = (cdf.partition_point(|&c| c <= u0) - 1).min(w - 1);
        let (c0, c1) = (cdf[i], cdf[i + 1]);
        let dx = if c1 > c0 { ((u0 - c0) / (c1 - c0)).clamp(0.0, 1.0) } else { 0.5 };
        let p = self.prob[j * w + i];
        if !(p > 0.0) {
            return None;
        }
        let (x, y) = (i as f64 + dx, j as f64 + dy);
        let (d, sin_exact) = self.direction(x, y);
        // sin θ of the direction as returned (f32), as `pdf` computes it:
        // near the poles the f64 value differs in the fourth digit. Where
        // the f32 direction rounds onto the pole, keep the exact value.
        let dy = d.y as f64;
        let sin_t = (1.0 - dy * dy).max(0.0).sqrt().max(POLE_SIN);
        if !(sin_exact > 0.0) {
            return None;
        }
        Some((d, self.bilerp(x, y), self.texel_pdf(p, sin_t)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn map(w: usize, h: usize, f: impl Fn(usize, usize) -> Vec3) -> EnvMap {
        let t = (0..h).flat_map(|j| (0..w).map(move |i| (i, j))).map(|(i, j)| f(i, j)).collect();
        EnvMap::from_texels("test".into(), w, h, t)
    }

    #[test]
    fn mapping_matches_cs184_landmarks_and_round_trips() {
        let m = map(8, 4, |_, _| Vec3::ONE);
        // u = x/w: 0 at -X, 0.25 at +Z, 0.5 at +X, 0.75 at -Z; +Y is row 0.
        for (d, u) in [(-Vec3::X, 0.0), (Vec3::Z, 0.25), (Vec3::X, 0.5), (-Vec3::Z, 0.75)] {
            let (x, y, _) = m.texel_coords(d);
            assert!(((x / 8.0) - u).abs() < 1e-6 || (u == 0.0 && (x / 8.0 - 1.0).abs() < 1e-6), "{d}: {x}");
            assert!((y - 2.0).abs() < 1e-6);
        }
        assert!(m.texel_coords(Vec3::Y).1.abs() < 1e-6);
        let mut rng = Rng::new(1, 2);
        for _ in 0..1000 {
            let (x, y) = (rng.uniform() as f64 * 8.0, rng.uniform() as f64 * 4.0);
            let (d, _) = m.direction(x, y);
            let (x2, y2, _) = m.texel_coords(d);
            assert!((x - x2).abs() < 1e-4 || (x - x2).abs() > 8.0 - 1e-4, "{x} {x2}");
            assert!((y - y2).abs() < 1e-4);
        }
    }

    #[test]
    fn bilinear_lookup_wraps_horizontally_and_clamps_vertically() {
        let m = map(4, 2, |i, j| Vec3::splat((i + 10 * j) as f32));
        // Texel centres return their value.
        assert_eq!(m.bilerp(1.5, 0.5), Vec3::splat(1.0));
        // Between the last and first columns: the mean.
        assert!((m.bilerp(4.0, 0.5).x - 1.5).abs() < 1e-6, "{}", m.bilerp(4.0, 0.5));
        assert!((m.bilerp(0.0, 0.5).x - 1.5).abs() < 1e-6);
        // Above the first row's centres: constant.
        assert_eq!(m.bilerp(1.5, 0.1), Vec3::splat(1.0));
        assert_eq!(m.bilerp(1.5, 1.9), Vec3::splat(11.0));
        assert!((m.bilerp(1.5, 1.0).x - 6.0).abs() < 1e-6);
    }

    #[test]
    fn sampled_pdf_matches_pdf_and_integrates_to_one() {
        let m = map(16, 8, |i, j| Vec3::new(((i * 7 + j * 3) % 5) as f32, 0.5, if i == 3 && j == 2 { 50.0 } else { 0.0 }));
        let mut rng = Rng::new(3, 3);
        for _ in 0..10_000 {
            let (d, l, pdf) = m.sample(rng.uniform2()).unwrap();
            assert!((d.length() - 1.0).abs() < 1e-5);
            let p2 = m.pdf(d);
            assert!((pdf - p2).abs() <= 1e-3 * pdf, "{pdf} vs {p2}");
            assert!((l - m.eval(d)).abs().max_element() <= 1e-4 * l.max_element().max(1.0));
        }
        // ∫ pdf dω = 1, by quadrature in (x, y).
        let (nx, ny) = (640, 320);
        let mut s = 0.0f64;
        for b in 0..ny {
            for a in 0..nx {
                let (d, sin_t) = m.direction((a as f64 + 0.5) / nx as f64 * 16.0, (b as f64 + 0.5) / ny as f64 * 8.0);
                s += m.pdf(d) as f64 * sin_t * (2.0 * PI / nx as f64) * (PI / ny as f64);
            }
        }
        assert!((s - 1.0).abs() < 1e-3, "{s}");
    }

    #[test]
    fn every_texel_the_lookup_can_light_can_be_sampled() {
        // One bright texel: the lookup is non-zero in its 3x3 neighbourhood
        // of texels, so all of them need a positive probability.
        let m = map(8, 6, |i, j| if (i, j) == (0, 0) { Vec3::ONE } else { Vec3::ZERO });
        for (i, j) in [(7usize, 0usize), (0, 0), (1, 0), (7, 1), (0, 1), (1, 1)] {
            assert!(m.prob[j * 8 + i] > 0.0, "texel {i},{j}");
        }
        assert_eq!(m.prob[3 * 8 + 4], 0.0);
    }
}
