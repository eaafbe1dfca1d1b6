//! The latitude-longitude map: its texels, CS184's lookup, and its own
//! importance sampling by the patches of the bilinear lookup (see the
//! parent module for the model).

use crate::color::illuminance;
use glam::Vec3;
use std::f64::consts::PI;

/// sin θ of the f32 directions nearest the poles (1 − 2⁻²⁴ in y): where a
/// direction rounds onto a pole, `sample` and `pdf` both use this value, so
/// they stay consistent (the solid angle involved is ~1e-7 sr).
const POLE_SIN: f64 = 3.4526698e-4;

/// The map's texels and the tables of its own importance sampling.
#[derive(Debug)]
pub struct LatLong {
    pub path: String,
    pub width: usize,
    pub height: usize,
    /// Row 0 is the top (θ = 0).
    pub texels: Vec<Vec3>,
    /// Cumulative probabilities of the h + 1 patch rows (length h + 2,
    /// from 0 to 1).
    pub(super) row_cdf: Vec<f64>,
    /// Per patch row, cumulative probabilities of its w patches within the
    /// row (w + 1 each).
    pub(super) col_cdf: Vec<f64>,
    /// Probability of each patch ((h + 1) × w, row-major).
    pub(super) prob: Vec<f64>,
}

impl LatLong {
    /// The map of `texels` (row-major, row 0 the top) and its sampling
    /// tables; all zero where the map is black.
    pub fn from_texels(path: String, width: usize, height: usize, texels: Vec<Vec3>) -> LatLong {
        let (w, h) = (width, height);
        let mut map = LatLong { path, width, height, texels, row_cdf: vec![0.0; h + 2], col_cdf: vec![0.0; (w + 1) * (h + 1)], prob: vec![0.0; w * (h + 1)] };
        let mut weight = vec![0.0f64; w * (h + 1)];
        for q in 0..=h {
            let (y0, y1) = map.patch_rows(q);
            let sin = (PI * 0.5 * (y0 + y1) / h as f64).sin();
            for p in 0..w {
                let [a, b, c, d] = map.corners(p, q);
                weight[q * w + p] = (y1 - y0) * 0.25 * (a + b + c + d) * sin;
            }
        }
        let total: f64 = weight.iter().sum();
        if total > 0.0 {
            for q in 0..=h {
                let row: f64 = weight[q * w..(q + 1) * w].iter().sum();
                map.row_cdf[q + 1] = map.row_cdf[q] + row / total;
                let mut acc = 0.0;
                for p in 0..w {
                    map.prob[q * w + p] = weight[q * w + p] / total;
                    acc += weight[q * w + p];
                    map.col_cdf[q * (w + 1) + p + 1] = if row > 0.0 { acc / row } else { (p + 1) as f64 / w as f64 };
                }
            }
            map.row_cdf[h + 1] = 1.0;
        }
        map
    }

    /// The y range (texel units) of patch row q: half a row above the first
    /// texel centres, whole rows between centres, half a row below the last.
    pub(super) fn patch_rows(&self, q: usize) -> (f64, f64) {
        let h = self.height as f64;
        match q {
            0 => (0.0, 0.5),
            q if q == self.height => (h - 0.5, h),
            q => (q as f64 - 0.5, q as f64 + 0.5),
        }
    }

    /// The corner luminances [top-left, top-right, bottom-left, bottom-right]
    /// of patch (p, q): texel columns p and p + 1 (wrapping), rows q − 1 and
    /// q (clamped, as the lookup is).
    /// Computed from the texels, which `sample_in_patch`'s lookup reads
    /// next anyway: a table of the luminances cost a second pair of cache
    /// misses per sample (the tables of a 1024 × 512 map are about 30 MB).
    fn corners(&self, p: usize, q: usize) -> [f64; 4] {
        let (w, h) = (self.width, self.height);
        let (top, bottom) = (q.saturating_sub(1), q.min(h - 1));
        let (l, r) = (p, if p + 1 == w { 0 } else { p + 1 });
        let lum = |i: usize| illuminance(self.texels[i].max(Vec3::ZERO)) as f64;
        [lum(top * w + l), lum(top * w + r), lum(bottom * w + l), lum(bottom * w + r)]
    }

    /// The patch holding texel coordinates (x, y), and (x, y) in it as (s, t) ∈ [0, 1]².
    fn patch_at(&self, x: f64, y: f64) -> (usize, usize, f64, f64) {
        let (w, h) = (self.width, self.height);
        let fx = x - 0.5;
        let p0 = fx.floor();
        let s = (fx - p0).clamp(0.0, 1.0);
        let p = (p0 as i64).rem_euclid(w as i64) as usize;
        let q = if y < 0.5 { 0 } else if y >= h as f64 - 0.5 { h } else { ((y + 0.5).floor() as usize).clamp(1, h - 1) };
        let (y0, y1) = self.patch_rows(q);
        (p, q, s, ((y - y0) / (y1 - y0)).clamp(0.0, 1.0))
    }

    /// Whether the map is black everywhere (nothing to sample).
    pub fn is_black(&self) -> bool {
        self.row_cdf[self.height + 1] == 0.0
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
        // The lookup's columns are -1..=w: wrap those without a division.
        let i = if i < 0 && i >= -w {
            i + w
        } else if i >= w && i < 2 * w {
            i - w
        } else {
            i.rem_euclid(w)
        };
        self.texels[(j.clamp(0, h - 1) * w + i) as usize]
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
    pub(super) fn direction(&self, x: f64, y: f64) -> (Vec3, f64) {
        let phi = x / self.width as f64 * 2.0 * PI;
        let theta = y / self.height as f64 * PI;
        let (st, ct) = theta.sin_cos();
        let (sp, cp) = phi.sin_cos();
        (Vec3::new((-cp * st) as f32, ct as f32, (sp * st) as f32), st)
    }

    /// Solid-angle pdf of `sample` for direction `d`.
    pub fn pdf(&self, d: Vec3) -> f32 {
        self.pdf_with_patch(d).map_or(0.0, |(_, _, pdf)| pdf)
    }

    /// `pdf`, with the patch (p, q) the direction falls in.
    pub(super) fn pdf_with_patch(&self, d: Vec3) -> Option<(usize, usize, f32)> {
        if self.is_black() {
            return None;
        }
        let (x, y, sin_t) = self.texel_coords(d);
        let (p, q, s, t) = self.patch_at(x, y);
        Some((p, q, self.patch_pdf(p, q, s, t, sin_t.max(POLE_SIN))))
    }

    /// The solid-angle pdf of the point (s, t) of patch (p, q), at sin θ.
    fn patch_pdf(&self, p: usize, q: usize, s: f64, t: f64, sin_t: f64) -> f32 {
        let prob = self.prob[q * self.width + p];
        if !(prob > 0.0) {
            return 0.0;
        }
        let [a, b, c, d] = self.corners(p, q);
        let mean = 0.25 * (a + b + c + d);
        let f = (1.0 - t) * ((1.0 - s) * a + s * b) + t * ((1.0 - s) * c + s * d);
        let (y0, y1) = self.patch_rows(q);
        // Density in texel units: P · f / ∫f, with ∫f = mean · (y1 − y0).
        let pdf_xy = prob * f / (mean * (y1 - y0));
        (pdf_xy * (self.width * self.height) as f64 / (2.0 * PI * PI * sin_t)) as f32
    }

    /// A direction with probability ∝ the patch table and, inside the patch,
    /// the bilinear luminance; its radiance and its pdf. `None` for a black
    /// map or a sample exactly at a pole.
    pub fn sample(&self, u: (f32, f32)) -> Option<(Vec3, Vec3, f32)> {
        if self.is_black() {
            return None;
        }
        let (w, h) = (self.width, self.height);
        // Patch row from u.1, then the patch from u.0 within it; each
        // uniform's leftover inside the chosen interval places the point.
        let u1 = u.1 as f64;
        let q = (self.row_cdf.partition_point(|&c| c <= u1) - 1).min(h);
        let (r0, r1) = (self.row_cdf[q], self.row_cdf[q + 1]);
        let v_left = if r1 > r0 { ((u1 - r0) / (r1 - r0)).clamp(0.0, 1.0) } else { 0.5 };
        let cdf = &self.col_cdf[q * (w + 1)..(q + 1) * (w + 1)];
        let u0 = u.0 as f64;
        let p = (cdf.partition_point(|&c| c <= u0) - 1).min(w - 1);
        let (c0, c1) = (cdf[p], cdf[p + 1]);
        let u_left = if c1 > c0 { ((u0 - c0) / (c1 - c0)).clamp(0.0, 1.0) } else { 0.5 };
        self.sample_in_patch(p, q, u_left, v_left)
    }

    /// A point of patch (p, q) with density ∝ the bilinear luminance, from
    /// two uniforms; its direction, radiance and the map's pdf.
    pub(super) fn sample_in_patch(&self, p: usize, q: usize, u_left: f64, v_left: f64) -> Option<(Vec3, Vec3, f32)> {
        let w = self.width;
        if !(self.prob[q * w + p] > 0.0) {
            return None;
        }
        // Inside the patch, ∝ f(s, t): t from the linear marginal
        // (a + b)/2 … (c + d)/2, then s from the linear conditional.
        let [a, b, c, d] = self.corners(p, q);
        let t = sample_linear(v_left, a + b, c + d);
        let s = sample_linear(u_left, (1.0 - t) * a + t * c, (1.0 - t) * b + t * d);
        let (y0, y1) = self.patch_rows(q);
        let (x, y) = ((p as f64 + 0.5 + s) % w as f64, y0 + t * (y1 - y0));
        let (dir, sin_exact) = self.direction(x, y);
        if !(sin_exact > 0.0) {
            return None;
        }
        // sin θ of the direction as returned (f32), as `pdf` computes it:
        // near the poles the f64 value differs in the fourth digit. Where
        // the f32 direction rounds onto the pole, keep the exact value.
        let dy = dir.y as f64;
        let sin_t = (1.0 - dy * dy).max(0.0).sqrt().max(POLE_SIN);
        Some((dir, self.bilerp(x, y), self.patch_pdf(p, q, s, t, sin_t)))
    }
}

/// x ∈ [0, 1] with density ∝ (1 − x)·a + x·b (a, b ≥ 0, not both 0), from a
/// uniform u: the inverse of its quadratic CDF, in the form that stays exact
/// as a → b (no cancellation): x = u(a + b) / (a + √((1 − u)a² + u b²)).
fn sample_linear(u: f64, a: f64, b: f64) -> f64 {
    if u == 0.0 && a == 0.0 {
        return 0.0;
    }
    let x = u * (a + b) / (a + ((1.0 - u) * a * a + u * b * b).sqrt());
    x.clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn map(w: usize, h: usize, f: impl Fn(usize, usize) -> Vec3) -> LatLong {
        let t = (0..h).flat_map(|j| (0..w).map(move |i| (i, j))).map(|(i, j)| f(i, j)).collect();
        LatLong::from_texels("test".into(), w, h, t)
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
    fn every_direction_the_lookup_lights_can_be_sampled() {
        // One bright texel: the lookup is non-zero around it (out to the
        // neighbouring texel centres), and every such direction needs a
        // positive pdf; directions farther away have none.
        let m = map(8, 6, |i, j| if (i, j) == (0, 0) { Vec3::ONE } else { Vec3::ZERO });
        let mut rng = Rng::new(4, 4);
        let mut lit = 0;
        for _ in 0..20_000 {
            let (x, y) = (rng.uniform() as f64 * 8.0, rng.uniform() as f64 * 6.0);
            let (d, _) = m.direction(x, y);
            let (l, pdf) = (m.eval(d), m.pdf(d));
            assert_eq!(l.max_element() > 0.0, pdf > 0.0, "at ({x}, {y}): radiance {l}, pdf {pdf}");
            lit += (pdf > 0.0) as u32;
        }
        assert!(lit > 100, "{lit}");
    }

    #[test]
    fn linear_sampling_inverts_its_cdf() {
        for (a, b) in [(1.0, 1.0), (0.0, 1.0), (1.0, 0.0), (0.3, 5.0), (2.0, 1e-9)] {
            for k in 0..=20 {
                let u = k as f64 / 20.0;
                let x = sample_linear(u, a, b);
                // CDF of (1 - x) a + x b, normalised: (a x + (b - a) x²/2) / ((a + b)/2).
                let cdf = (a * x + (b - a) * x * x / 2.0) / ((a + b) / 2.0);
                assert!((cdf - u).abs() < 1e-9, "a {a} b {b} u {u}: x {x} cdf {cdf}");
            }
        }
    }
}
