//! Multiple importance sampling over every strategy (s, t) that can make a
//! path: Veach's **power heuristic** (β = 2), computed from ratios of
//! neighbouring strategies' path densities, as pbrt-v4's `MISWeight` does
//! for the balance heuristic.
//!
//! Strategy (s, t) and (s+1, t−1) differ only in how one vertex was made,
//! so their path densities differ by that vertex's `pdf_rev / pdf_fwd`; a
//! running product over the path gives every strategy's density relative to
//! the one used, and the weight is 1 / (1 + Σ ratio²). Through a specular
//! chain the densities change measure (`vertex`): a delta vertex holds its
//! density per projected solid angle at the chain's end it was made from,
//! a vertex made from a delta vertex holds 0, read as 1, so that the
//! chain's generalized geometry term cancels from the products and the
//! ratios are the true ones; any strategy that would connect at a delta
//! vertex (or at a delta neighbour) is left out of the sum.
//!
//! With `LightPaths::Specular` the strategies s ≥ 2 make a path only when
//! its vertex x1 (the one after the light point) is specular: a function
//! of the path, so leaving the others out of the sum keeps the weights of
//! every path summing to 1.
//!
//! With specular light paths a pixel sample traces its light subpath with
//! probability `Bdpt::light_share` (`mod.rs`), so the strategies s ≥ 2 have that
//! share of the camera's sample count: it enters their terms as Veach's
//! n_k p_k, like light tracing's share of a `-p` cell. (Any weights that sum
//! to 1 keep the estimate unbiased; the counts make them the power
//! heuristic's for these sample numbers.)
//!
//! Why the power heuristic: it is the path tracer's (NEE against BSDF
//! samples), so BDPT restricted to s ≤ 1 weighs those two techniques the
//! way the path tracer does, and Veach (thesis §9.2.4) found it better than
//! the balance heuristic where one technique is much better than the others
//! — the caustics this integrator exists for. pbrt-v4 uses the balance heuristic.
//!
//! Sample counts: a pixel takes n camera samples, but light tracing (t = 1)
//! spreads all light subpaths over the whole film, so over a `-p` cell of
//! `share` of the frame's pixels the pixel gets share·n light-tracing
//! samples. The balance of counts enters the t = 1 ratios (Veach's n_k p_k),
//! as pbrt-v4 does since its fix of GitHub issue
//! [347](https://github.com/mmp/pbrt-v4/issues/347), with the factor on the side the count
//! belongs to.
//!
//! The light point y0 has two densities: as the start of a light subpath
//! (pick × area density, the strategies s ≥ 2) and as a next-event sample
//! from y1 (pick × the solid-angle sampling's density converted to area,
//! s = 1). The ratio chain carries the first; the s = 1 terms (and, when s =
//! 1 is the strategy used, every other term) are corrected by the ratio of
//! the two. pbrt-v4 uses the area density for both, which keeps the weights
//! summing to 1 but weighs next-event samples near a light, where solid-angle
//! sampling is far better than area sampling, as if they were area samples.
//! Russian roulette is left out of the densities: the weights are still a
//! function of the path alone, so they sum to 1 and the estimate stays
//! unbiased.

use super::vertex::{Kind, Vertex};
use super::{Bdpt, LightPaths};

/// A vertex's densities and delta flag, as one strategy sees them.
#[derive(Clone, Copy)]
struct Densities {
    fwd: f32,
    rev: f32,
    delta: bool,
}

impl Densities {
    fn of(v: &Vertex) -> Densities {
        Densities { fwd: v.pdf_fwd, rev: v.pdf_rev, delta: v.delta }
    }
}

/// 0 read as 1: a delta vertex's densities cancel from the ratios.
fn remap0(x: f32) -> f32 {
    if x != 0.0 {
        x
    } else {
        1.0
    }
}

/// a_nee / a_emit from the two area densities of a light point (1 where
/// either is not a positive number).
pub(super) fn nee_over_emit(nee: f32, emit: f32) -> f64 {
    if emit > 0.0 && nee > 0.0 && (nee / emit).is_finite() {
        (nee / emit) as f64
    } else {
        1.0
    }
}

impl Bdpt<'_> {
    /// a_nee / a_emit of light point `y0` connected to `y1` (see the module
    /// comment); 1 where `y0` is not on a light.
    pub(super) fn nee_ratio(&self, y0: &Vertex, y1: &Vertex) -> f64 {
        // A light at infinity: next-event estimation draws its directions
        // as its light subpaths do (`Light::sample` either way).
        if y0.is_at_infinity() {
            return 1.0;
        }
        let Some(k) = y0.light(self.lights) else { return 1.0 };
        let l = &self.lights.lights[k];
        let emit = l.emission_pdf_pos(self.power.world());
        nee_over_emit(l.sample_pdf_area(self.scene, y1.p(), y0.p(), y0.it.ng, y0.it.prim_id), emit)
    }

    /// The weight of strategy (s, t) for the path `light[..s]` + `camera[..t]`,
    /// with `sampled` standing for `light[0]` (s = 1: the next-event light
    /// point) or `camera[0]` (t = 1: the lens point chosen toward the scene).
    /// `given_nee_ratio`: `nee_ratio` of this path's y0 for s ≥ 1, as the
    /// caller has it: the light subpath's (s ≥ 2, the same for all those
    /// strategies, so computed once per subpath) or the next-event
    /// connection's (s = 1, from the density its light sample had).
    pub(super) fn mis_weight(&self, light: &[Vertex], camera: &[Vertex], sampled: Option<&Vertex>, s: usize, t: usize, given_nee_ratio: f64) -> f32 {
        if s + t == 2 {
            return 1.0;
        }
        // At most -m + 2 vertices a side: on the stack for the usual depths.
        let mut cam: smallvec::SmallVec<[Densities; 16]> = camera[..t].iter().map(Densities::of).collect();
        // s = 1: its next-event point, pushed below (whether or not a light
        // subpath was traced).
        let mut lig: smallvec::SmallVec<[Densities; 16]> = light[..if s == 1 { 0 } else { s }].iter().map(Densities::of).collect();
        fn pick<'v>(i: usize, side: &'v [Vertex], first_sampled: bool, sampled: Option<&'v Vertex>) -> &'v Vertex {
            match (i, first_sampled, sampled) {
                (0, true, Some(v)) => v,
                _ => &side[i],
            }
        }
        let zt = pick(t - 1, camera, t == 1, sampled);
        if t == 1 {
            cam[0] = Densities::of(zt);
        }
        let ys = (s > 0).then(|| pick(s - 1, light, s == 1, sampled));
        if s == 1 {
            lig.push(Densities::of(ys.expect("s = 1")));
        }
        // The connection's ends are not deltas for this strategy.
        cam[t - 1].delta = false;
        if s > 0 {
            lig[s - 1].delta = false;
        }
        let (lights, power, camera_model) = (self.lights, &self.power, &self.camera);
        // z(t-1) made from the light side.
        cam[t - 1].rev = match ys {
            Some(y) => y.pdf(lights, power, camera_model, (s > 1).then(|| &light[s - 2]), zt),
            None => zt.pdf_light_origin(lights, power),
        };
        // z(t-2) made from z(t-1).
        if t > 1 {
            cam[t - 2].rev = match ys {
                Some(y) => zt.pdf(lights, power, camera_model, Some(y), &camera[t - 2]),
                None => zt.pdf_light(lights, power, &camera[t - 2]),
            };
        }
        if let Some(y) = ys {
            // y(s-1) made from the camera side, and y(s-2) from y(s-1).
            lig[s - 1].rev = zt.pdf(lights, power, camera_model, (t > 1).then(|| &camera[t - 2]), y);
            if s > 1 {
                lig[s - 2].rev = y.pdf(lights, power, camera_model, Some(zt), &light[s - 2]);
            }
        }
        // a_nee / a_emit for y0 of this path: the next-event density of y0
        // from y1 over its density as a light subpath's start.
        let nee_ratio = match s {
            0 => self.nee_ratio(zt, &camera[t - 2]),
            _ => given_nee_ratio,
        };
        // Every ratio below is relative to this strategy's density: with
        // s = 1 that density has a_nee where the chain has a_emit.
        let all = if s == 1 { 1.0 / nee_ratio } else { 1.0 };
        // With `LightPaths::Specular`, strategies with s ≥ 2 make only
        // paths whose vertex x1 (after the light point) is specular.
        let x1_specular = match s {
            0 => t >= 2 && camera[t - 2].delta,
            1 => false,
            _ => light[1].delta,
        };
        let light_side = |s_other: usize| s_other < 2 || x1_specular || self.light_paths == LightPaths::All;
        let share = self.light_tracing_share;
        // Light subpaths per camera sample (`Bdpt::light_share`): the count
        // of the strategies s ≥ 2 relative to this one's.
        let light_share = self.light_share() as f64;
        let subpaths = |s_other: usize| if s_other >= 2 { light_share } else { 1.0 };
        let own = subpaths(s);
        let mut sum = 0.0f64;
        // Strategies with fewer camera vertices: (s + t − i, i).
        let mut r = 1.0f64;
        for i in (1..t).rev() {
            r *= remap0(cam[i].rev) as f64 / remap0(cam[i].fwd) as f64;
            if !cam[i].delta && !cam[i - 1].delta && light_side(s + t - i) {
                // (s + t − i, i): s' = 1 when i = t − 1 and s = 0.
                let nee = if s == 0 && i == t - 1 { nee_ratio } else { 1.0 };
                let term = r * all * nee * if i == 1 { share } else { 1.0 } * subpaths(s + t - i) / own;
                sum += term * term;
            }
        }
        // Strategies with fewer light vertices: (i, s + t − i).
        let count = if t == 1 { 1.0 / share } else { 1.0 };
        let mut r = 1.0f64;
        for i in (0..s).rev() {
            r *= remap0(lig[i].rev) as f64 / remap0(lig[i].fwd) as f64;
            let before_is_delta = if i > 0 {
                lig[i - 1].delta
            } else {
                // s' = 0: the camera path must hit the light by chance
                // (or escape toward it, for a light at infinity).
                let y0 = pick(0, light, s == 1, sampled);
                match y0.kind {
                    Kind::Light(k) => !lights.lights[k].is_hittable(),
                    Kind::Distant(k) => !lights.lights[k].is_visible(),
                    _ => true,
                }
            };
            if !lig[i].delta && !before_is_delta && light_side(i) {
                // (i, s + t − i): s' = 1 when i = 1.
                let nee = if i == 1 { nee_ratio } else { 1.0 };
                let term = r * count * all * nee * subpaths(i) / own;
                sum += term * term;
            }
        }
        let w = 1.0 / (1.0 + sum);
        if w.is_finite() {
            w as f32
        } else {
            0.0
        }
    }
}
