//! Environment light sampled in proportion to the map × the receiver's
//! cosine, approximately: the product of the map with a conservative bound
//! of the cosine, per bin of receiver normals.
//!
//! The map's own sampler (`LatLong::sample`) spends about half its samples
//! below the receiver's horizon, where they add nothing. Here the patch grid
//! is cut into tiles (at most 64 × 32) and the sphere of normals into
//! 16 × 32 latitude-longitude bins. For normal bin b and tile t, c(b, t) is
//! an upper bound of n·ω over every normal n in b and direction ω in t
//! (the angle between the two cones' axes less both radii, clamped to
//! [0, π/2]). A sample at a receiver with shading normal n picks the tile
//! with probability ∝ (the tile's share of the map's patch table) × c(b, t)
//! for n's bin b, then a patch inside the tile by the patch table, then a
//! point in the patch as `LatLong::sample` does. Its pdf is the map's pdf ×
//! c(b, t) / Z_b (Z_b = Σ over tiles of share × c). Since c bounds the cosine
//! from above, c > 0 wherever some normal of the bin sees the direction
//! above its horizon: the pdf covers everything the integrand covers, so
//! the estimator stays unbiased, with or without MIS (the BSDF sample's
//! weight uses the same pdf, for the same normal).
//!
//! Not in CS184 (its environment sampler ignores the receiver); nor in
//! Cycles 3.4 or Mitsuba 3's default `envmap` emitter, which sample the map
//! alone. Used only at vertices whose BSDF does not transmit (a transmitting
//! BSDF needs light from below its horizon too).

use super::LatLong;
use glam::Vec3;
use std::f64::consts::PI;

const TILES_X: usize = 64;
const TILES_Y: usize = 32;
const BINS_T: usize = 16;
const BINS_P: usize = 32;
/// Intervals of u per normal bin in the tile search's guide table (a power
/// of two, so that j / GUIDE is exact).
const GUIDE: usize = 256;
/// Angular slack (radians) added to every cone radius, for the rounding of
/// f32 directions.
pub(super) const SLACK: f64 = 1e-3;

#[derive(Debug)]
pub struct EnvProduct {
    /// Patch columns and rows where each tile starts (tiles + 1 entries).
    col_start: Vec<usize>,
    row_start: Vec<usize>,
    /// The tile of each patch column / row.
    tile_col: Vec<u16>,
    tile_row: Vec<u16>,
    /// Per normal bin: the cosine bound of each tile, then the cumulative
    /// tile probabilities (tiles + 1), then Z_b.
    bound: Vec<f32>,
    cdf: Vec<f64>,
    z: Vec<f64>,
    /// Per normal bin, `GUIDE` + 1 entries: guide[j] = how many of the
    /// bin's cdf entries are ≤ j / GUIDE. A sample's u lies between two
    /// of them, so its search runs over the few entries between (most
    /// often one cache line) instead of over the bin's 2049 (16 KiB; 11
    /// dependent loads per sample, from 8 MiB of tables).
    guide: Vec<u16>,
    /// Per tile, the running share of its patch rows in the tile's mass
    /// (its rows + 1 entries, from `row_cdf_at[tile]`): a sample picks its
    /// row here, where summing the rows' masses cost two scattered
    /// column-table reads per row (a third of a courtyard render's
    /// environment sampling).
    row_cdf: Vec<f64>,
    row_cdf_at: Vec<usize>,
    /// Per tile: its share of the map's patch table, and its direction
    /// cone (unit axis, angular radius) in world space (`polar` with
    /// φ' = π − φ is the map's own direction).
    pub(super) share: Vec<f64>,
    pub(super) cones: Vec<([f64; 3], f64)>,
}

/// The unit vector at polar angle θ from +y and azimuth φ (any convention,
/// used for both cones alike).
fn polar(theta: f64, phi: f64) -> [f64; 3] {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    [st * cp, ct, st * sp]
}

fn angle(a: [f64; 3], b: [f64; 3]) -> f64 {
    (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).clamp(-1.0, 1.0).acos()
}

/// The axis and angular radius of the latitude-longitude rectangle
/// θ ∈ [t0, t1], φ ∈ [p0, p1]: the farthest point from its centre
/// direction is one of its corners (distance along a meridian or a parallel
/// grows monotonically away from the centre, for rectangles smaller than a
/// hemisphere).
pub(super) fn cone(t0: f64, t1: f64, p0: f64, p1: f64) -> ([f64; 3], f64) {
    let axis = polar(0.5 * (t0 + t1), 0.5 * (p0 + p1));
    let r = [(t0, p0), (t0, p1), (t1, p0), (t1, p1)].iter().map(|&(t, p)| angle(axis, polar(t, p))).fold(0.0, f64::max);
    (axis, r + SLACK)
}

/// Normal bin of a unit vector: θ from +y, φ = atan2(z, x) in the same
/// convention as `polar`.
fn bin_of(n: Vec3) -> usize {
    let theta = (n.y as f64).clamp(-1.0, 1.0).acos();
    let phi = (n.z as f64).atan2(n.x as f64).rem_euclid(2.0 * PI);
    let i = ((theta / PI * BINS_T as f64) as usize).min(BINS_T - 1);
    let j = ((phi / (2.0 * PI) * BINS_P as f64) as usize).min(BINS_P - 1);
    i * BINS_P + j
}

impl EnvProduct {
    pub(super) fn build(env: &LatLong) -> EnvProduct {
        let (w, h) = (env.width, env.height);
        let (tx, ty) = (TILES_X.min(w), TILES_Y.min(h + 1));
        let col_start: Vec<usize> = (0..=tx).map(|i| i * w / tx).collect();
        let row_start: Vec<usize> = (0..=ty).map(|i| i * (h + 1) / ty).collect();
        let mut tile_col = vec![0u16; w];
        let mut tile_row = vec![0u16; h + 1];
        for i in 0..tx {
            tile_col[col_start[i]..col_start[i + 1]].fill(i as u16);
        }
        for j in 0..ty {
            tile_row[row_start[j]..row_start[j + 1]].fill(j as u16);
        }
        // Each tile's share of the patch table and its direction cone. Patch
        // column p spans x ∈ [p + 0.5, p + 1.5) texels, φ = x / w · 2π in the
        // map's convention (`LatLong::direction`: d = (−cos φ sin θ, cos θ,
        // sin φ sin θ)), which is `polar`'s with φ' = π − φ.
        let tiles = tx * ty;
        let mut share = vec![0.0f64; tiles];
        let mut cones = Vec::with_capacity(tiles);
        let (mut row_cdf, mut row_cdf_at) = (Vec::new(), Vec::with_capacity(tiles + 1));
        for j in 0..ty {
            let y0 = env.patch_rows(row_start[j]).0;
            let y1 = env.patch_rows(row_start[j + 1] - 1).1;
            for i in 0..tx {
                row_cdf_at.push(row_cdf.len());
                let first = row_cdf.len();
                row_cdf.push(0.0);
                for q in row_start[j]..row_start[j + 1] {
                    share[j * tx + i] += env.prob[q * w + col_start[i]..q * w + col_start[i + 1]].iter().sum::<f64>();
                    row_cdf.push(share[j * tx + i]);
                }
                if share[j * tx + i] > 0.0 {
                    row_cdf[first..].iter_mut().for_each(|c| *c /= share[j * tx + i]);
                }
                let x0 = col_start[i] as f64 + 0.5;
                let x1 = col_start[i + 1] as f64 + 0.5;
                let (p0, p1) = (PI - x1 / w as f64 * 2.0 * PI, PI - x0 / w as f64 * 2.0 * PI);
                cones.push(cone(y0 / h as f64 * PI, y1 / h as f64 * PI, p0, p1));
            }
        }
        let bins = BINS_T * BINS_P;
        let mut bound = vec![0.0f32; bins * tiles];
        let mut cdf = vec![0.0f64; bins * (tiles + 1)];
        let mut z = vec![0.0f64; bins];
        for bi in 0..BINS_T {
            for bj in 0..BINS_P {
                let b = bi * BINS_P + bj;
                let t = |k: usize| k as f64 * PI / BINS_T as f64;
                let p = |k: usize| k as f64 * 2.0 * PI / BINS_P as f64;
                let (axis, r) = cone(t(bi), t(bi + 1), p(bj), p(bj + 1));
                let mut acc = 0.0;
                for (k, &(ta, tr)) in cones.iter().enumerate() {
                    let gap = (angle(axis, ta) - r - tr).max(0.0);
                    let c = if gap >= 0.5 * PI { 0.0 } else { gap.cos() as f32 };
                    bound[b * tiles + k] = c;
                    acc += share[k] * c as f64;
                    cdf[b * (tiles + 1) + k + 1] = acc;
                }
                z[b] = acc;
                if acc > 0.0 {
                    for v in &mut cdf[b * (tiles + 1) + 1..(b + 1) * (tiles + 1)] {
                        *v /= acc;
                    }
                }
            }
        }
        row_cdf_at.push(row_cdf.len());
        assert!(tiles < u16::MAX as usize, "guide entries are u16");
        let mut guide = Vec::with_capacity(bins * (GUIDE + 1));
        for b in 0..bins {
            let c = &cdf[b * (tiles + 1)..(b + 1) * (tiles + 1)];
            guide.extend((0..=GUIDE).map(|j| c.partition_point(|&v| v <= j as f64 / GUIDE as f64) as u16));
        }
        EnvProduct { col_start, row_start, tile_col, tile_row, bound, cdf, z, guide, row_cdf, row_cdf_at, share, cones }
    }

    fn tiles(&self) -> usize {
        (self.col_start.len() - 1) * (self.row_start.len() - 1)
    }

    /// What the map's own pdf is multiplied by for a direction in patch
    /// (p, q), at a receiver in normal bin `b`: the tile's bound / Z_b.
    fn scale(&self, b: usize, p: usize, q: usize) -> f64 {
        let tx = self.col_start.len() - 1;
        let k = self.tile_row[q] as usize * tx + self.tile_col[p] as usize;
        if self.z[b] > 0.0 {
            self.bound[b * self.tiles() + k] as f64 / self.z[b]
        } else {
            0.0
        }
    }

    /// Solid-angle pdf of `sample` for direction `d` at a receiver with
    /// shading normal `n`.
    pub fn pdf(&self, env: &LatLong, n: Vec3, d: Vec3) -> f32 {
        let Some((p, q, pdf)) = env.pdf_with_patch(d) else { return 0.0 };
        (pdf as f64 * self.scale(bin_of(n), p, q)) as f32
    }

    /// A direction for a receiver with shading normal `n`: its radiance
    /// (the lookup escaping rays see) and its pdf. `None` where nothing
    /// can be drawn.
    pub fn sample(&self, env: &LatLong, n: Vec3, u: (f32, f32)) -> Option<(Vec3, Vec3, f32)> {
        let b = bin_of(n);
        if !(self.z[b] > 0.0) || env.is_black() {
            return None;
        }
        let tiles = self.tiles();
        // The tile from u.1, the row in it from the leftover, the patch in
        // the row from u.0; the leftovers place the point in the patch.
        let cdf = &self.cdf[b * (tiles + 1)..(b + 1) * (tiles + 1)];
        let u1 = u.1 as f64;
        let k = (self.count_at_most(b, cdf, u1) - 1).min(tiles - 1);
        let (k0, k1) = (cdf[k], cdf[k + 1]);
        if !(k1 > k0) {
            return None;
        }
        let v = ((u1 - k0) / (k1 - k0)).clamp(0.0, 1.0);
        let (dir, radiance, pdf, p, q) = self.sample_tile(env, k, v, u.0 as f64)?;
        Some((dir, radiance, (pdf as f64 * self.scale(b, p, q)) as f32))
    }

    /// A direction in tile `k` drawn by the map's table restricted to the
    /// tile (`v` picks the row, `u0` the patch in it): direction, radiance,
    /// the map's own pdf and the patch.
    pub(super) fn sample_tile(&self, env: &LatLong, k: usize, v: f64, u0: f64) -> Option<(Vec3, Vec3, f32, usize, usize)> {
        let w = env.width;
        let tx = self.col_start.len() - 1;
        let (ti, tj) = (k % tx, k / tx);
        let (c0, c1) = (self.col_start[ti], self.col_start[ti + 1]);
        // The row: rows of zero mass have no step in the tile's row cdf,
        // so the search never lands on one.
        let rows = &self.row_cdf[self.row_cdf_at[k]..self.row_cdf_at[k + 1]];
        let r = (rows.partition_point(|&c| c <= v) - 1).min(rows.len() - 2);
        let (r0, r1) = (rows[r], rows[r + 1]);
        if !(r1 > r0) {
            return None;
        }
        let v_left = ((v - r0) / (r1 - r0)).clamp(0.0, 1.0);
        let q = self.row_start[tj] + r;
        let row = &env.col_cdf[q * (w + 1)..(q + 1) * (w + 1)];
        let (a, z) = (row[c0], row[c1]);
        let u0 = a + u0 * (z - a);
        let p = (c0 + row[c0..=c1].partition_point(|&c| c <= u0)).saturating_sub(1).clamp(c0, c1 - 1);
        let (l0, l1) = (row[p], row[p + 1]);
        let u_left = if l1 > l0 { ((u0 - l0) / (l1 - l0)).clamp(0.0, 1.0) } else { 0.5 };
        let (dir, radiance, pdf) = env.sample_in_patch(p, q, u_left, v_left)?;
        Some((dir, radiance, pdf, p, q))
    }

    /// How many entries of bin `b`'s `cdf` are ≤ u (u ≥ 0): the entries
    /// below guide[j] are ≤ j / GUIDE ≤ u and those from guide[j + 1] on
    /// exceed (j + 1) / GUIDE > u, so only the ones between are searched.
    /// The same count as a search of the whole table.
    fn count_at_most(&self, b: usize, cdf: &[f64], u: f64) -> usize {
        let j = ((u * GUIDE as f64) as usize).min(GUIDE - 1);
        let g = &self.guide[b * (GUIDE + 1)..];
        let (lo, hi) = (g[j] as usize, g[j + 1] as usize);
        if u >= 1.0 {
            // Past the guide's last interval: everything up to the end may be ≤ u.
            return lo + cdf[lo..].partition_point(|&c| c <= u);
        }
        lo + cdf[lo..hi].partition_point(|&c| c <= u)
    }

    /// The tile of patch (p, q).
    pub(super) fn tile_of(&self, p: usize, q: usize) -> usize {
        self.tile_row[q] as usize * (self.col_start.len() - 1) + self.tile_col[p] as usize
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use super::super::EnvMap;
    use crate::rng::Rng;

    /// A map with a bright patch, a dim gradient and a black band.
    pub(in crate::light) fn map() -> EnvMap {
        let (w, h) = (96, 48);
        let texels = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                if (40..46).contains(&x) && (10..14).contains(&y) {
                    Vec3::splat(50.0)
                } else if y > 40 {
                    Vec3::ZERO
                } else {
                    Vec3::new(0.2 + x as f32 / w as f32, 0.5, 0.3 + y as f32 / h as f32)
                }
            })
            .collect();
        EnvMap::from_texels("test".into(), w, h, texels)
    }

    pub(in crate::light) fn random_unit(rng: &mut Rng) -> Vec3 {
        let z = 1.0 - 2.0 * rng.uniform();
        let phi = 2.0 * std::f32::consts::PI * rng.uniform();
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * phi.cos(), z, r * phi.sin())
    }

    /// The guided tile search counts what a search of the whole table
    /// counts: at random u, at the guide's own boundaries j / GUIDE and
    /// just below them, and at every cdf value (flat runs of equal values
    /// are where the tiles below a bin's horizon are).
    #[test]
    fn guided_search_matches_the_whole_search() {
        let env = map();
        let pr = env.product.as_ref().unwrap();
        let tiles = pr.tiles();
        let mut rng = Rng::new(9, 9);
        let mut checked = 0;
        for b in 0..BINS_T * BINS_P {
            let cdf = &pr.cdf[b * (tiles + 1)..(b + 1) * (tiles + 1)];
            let mut us: Vec<f64> = (0..64).map(|_| rng.uniform() as f64).collect();
            us.extend((0..GUIDE).flat_map(|j| [j as f64 / GUIDE as f64, (j as f64 / GUIDE as f64 - 1e-12).max(0.0)]));
            us.extend(cdf.iter().copied());
            for u in us {
                assert_eq!(pr.count_at_most(b, cdf, u), cdf.partition_point(|&c| c <= u), "bin {b}, u {u}");
                checked += 1;
            }
        }
        assert!(checked > 100_000);
    }

    /// The bound really bounds: every direction above a normal's horizon
    /// (where the map is lit) has a positive pdf, so nothing the integrand
    /// sees is missed; and a sample's pdf is the pdf of its direction.
    #[test]
    fn product_pdf_covers_the_upper_hemisphere_and_matches_sampling() {
        let env = map();
        let prod = EnvProduct::build(&env);
        let mut rng = Rng::new(3, 9);
        for _ in 0..4000 {
            let n = random_unit(&mut rng);
            let d = random_unit(&mut rng);
            if d.dot(n) > 1e-3 && env.eval(d).max_element() > 0.0 {
                assert!(prod.pdf(&env, n, d) > 0.0, "direction {d:?} above normal {n:?} has pdf 0");
            }
            if let Some((s, radiance, pdf)) = prod.sample(&env, n, (rng.uniform(), rng.uniform())) {
                let again = prod.pdf(&env, n, s);
                assert!((again - pdf).abs() <= 2e-3 * pdf, "sampled pdf {pdf} vs pdf {again}");
                let want = env.eval(s);
                assert!((radiance - want).abs().max_element() <= 1e-4 * want.max_element().max(1.0), "radiance {radiance:?} vs lookup {want:?}");
            }
        }
    }

    /// E[f/pdf] = ∫ f for f = the map's luminance × max(0, n·ω): the
    /// estimator is unbiased (checked against a long uniform-sphere
    /// estimate, within both estimates' standard errors), and its variance
    /// is below the map sampler's for the same integrand.
    #[test]
    fn product_estimate_is_unbiased_and_lower_variance_than_the_map_sampler() {
        let env = map();
        let prod = EnvProduct::build(&env);
        let mut rng = Rng::new(5, 2);
        let lum = |d: Vec3| crate::color::illuminance(env.eval(d)) as f64;
        for n in [Vec3::Y, Vec3::new(0.6, -0.8, 0.0), Vec3::new(0.0, 0.28, -0.96)] {
            let f = |d: Vec3| lum(d) * (d.dot(n) as f64).max(0.0);
            let stats = |xs: &[f64]| {
                let m = xs.iter().sum::<f64>() / xs.len() as f64;
                let var = xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (xs.len() - 1) as f64;
                (m, var)
            };
            let uni: Vec<f64> = (0..400_000).map(|_| f(random_unit(&mut rng)) * 4.0 * PI).collect();
            let mut draw = |product: bool| -> Vec<f64> {
                (0..100_000)
                    .map(|_| {
                        let u = (rng.uniform(), rng.uniform());
                        let s = if product { prod.sample(&env, n, u) } else { env.sample(u) };
                        s.map_or(0.0, |(d, _, pdf)| f(d) / pdf as f64)
                    })
                    .collect()
            };
            let (pm, pv) = stats(&draw(true));
            let (_, mv) = stats(&draw(false));
            let (um, uv) = stats(&uni);
            let se = (pv / 100_000.0 + uv / 400_000.0).sqrt();
            assert!((pm - um).abs() < 4.0 * se, "n {n:?}: product mean {pm} vs uniform {um} (se {se})");
            assert!(pv < mv, "n {n:?}: product variance {pv} not below the map sampler's {mv}");
        }
    }
}
