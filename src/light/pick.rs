//! One light per light sample, picked in proportion to a cheap estimate of
//! what each light sends to the vertex, where a scene has several.
//!
//! Model: at a vertex at `p` with normal `n`, light k's estimate e_k is its
//! unshadowed irradiance as if it were a point at its centre: I cos/r² for
//! a point light, E cos for a directional one, L A cos_l cos/r² for a
//! rectangle or an emissive mesh (at its area-weighted centroid, facing its
//! mean normal; cos_l = ½ for a mesh whose normals do not agree), L π r_s²
//! cos/d² for a sphere (luminances). Each `-l` sample
//! picks light k with probability
//!
//!   p_k = (1 − δ) e_k / Σ e + δ / K      (δ = `DEFENSIVE`, K lights)
//!
//! and counts its sample's value / p_k; the sample's MIS pdf is p_k times
//! the light's own, and a BSDF sample that hits light k is weighted against
//! that product. Every p_k > 0, so the estimator is unbiased however rough
//! the estimates; where one light dominates (the point light beside CBcoil's
//! ceiling lamp, the lamp on the far wall) the estimate's share is nearly
//! what the sample would have found, so picking costs little variance and
//! saves the other lights' shadow rays and samples. CS184 samples every
//! light at every vertex; Cycles 3.4 picks one by its power (not by the
//! vertex); pbrt-v4 and Cycles 3.5 by a light tree's bound of the same
//! quantity.
//!
//! Only for scenes whose lights all have such an estimate and at most
//! `MAX_LIGHTS` of them: the environment map and the hemisphere light
//! (estimated by no point) and larger light counts keep one sample per
//! light.

use super::Light;
use crate::color::illuminance;
use glam::Vec3;

/// Up to this many lights are picked from (a probability table on the stack).
pub const MAX_LIGHTS: usize = 8;

/// The uniform share of the pick: keeps every light's probability at least
/// δ/K where its centre estimate says it sends nothing (a grazing rectangle
/// half above the horizon).
pub const DEFENSIVE: f32 = 0.1;

/// Whether `light` has an estimate at all (`Emitter::pick_estimate`; the
/// lights at infinity with a map or a sky have none).
pub fn can_pick(light: &Light) -> bool {
    light.kind().pick_estimate(Vec3::ZERO, Vec3::Z).is_some()
}

/// Luminance × area × the emitter's and the receiver's cosines / r²: the
/// estimate of a patch of emitting surface at `c` (facing `normal`, or
/// any way) seen from `p` with normal `n`.
pub(super) fn patch(p: Vec3, n: Vec3, c: Vec3, area: f32, normal: Option<Vec3>, radiance: Vec3) -> f32 {
    let d = c - p;
    let r2 = d.length_squared();
    if !(r2 > 0.0) {
        return 0.0;
    }
    let w = d / r2.sqrt();
    let cos_l = normal.map_or(0.5, |nl| (-nl.dot(w)).max(0.0));
    illuminance(radiance) * area * cos_l * n.dot(w).max(0.0) / r2
}

/// The pick: which lights a light sample chooses from, and how.
#[derive(Clone, Debug)]
pub struct Picker;

impl Picker {
    /// For `lights`, when they can be picked from: 2 to `MAX_LIGHTS` of
    /// them, all with an estimate.
    pub fn new(lights: &[Light]) -> Option<Picker> {
        ((2..=MAX_LIGHTS).contains(&lights.len()) && lights.iter().all(can_pick)).then_some(Picker)
    }

    /// The pick probabilities of `lights` (those `new` was given) at `p`
    /// with normal `n`; entries past `lights.len()` are 0.
    pub fn probabilities(&self, lights: &[Light], p: Vec3, n: Vec3) -> [f32; MAX_LIGHTS] {
        debug_assert!(lights.len() <= MAX_LIGHTS);
        let mut prob = [0.0f32; MAX_LIGHTS];
        let k = lights.len();
        let mut sum = 0.0;
        for (e, l) in prob.iter_mut().zip(lights) {
            *e = estimate(l, p, n);
            sum += *e;
        }
        let uniform = 1.0 / k as f32;
        for e in &mut prob[..k] {
            *e = if sum > 0.0 && sum.is_finite() { (1.0 - DEFENSIVE) * *e / sum + DEFENSIVE * uniform } else { uniform };
        }
        prob
    }
}

/// A light's unshadowed irradiance estimate at `p` with normal `n`.
fn estimate(light: &Light, p: Vec3, n: Vec3) -> f32 {
    let e = light.kind().pick_estimate(p, n).unwrap_or(0.0);
    if e.is_finite() { e.max(0.0) } else { 0.0 }
}

/// The light `u` ∈ [0, 1) picks from `prob` (the first `k` entries).
pub fn pick(prob: &[f32; MAX_LIGHTS], k: usize, u: f32) -> usize {
    let mut acc = 0.0;
    for (i, p) in prob[..k].iter().enumerate() {
        acc += p;
        if u < acc {
            return i;
        }
    }
    k - 1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::light::spherical_rect::RectEmitter;

    fn probabilities(lights: &[Light], p: Vec3, n: Vec3) -> [f32; MAX_LIGHTS] {
        Picker.probabilities(lights, p, n)
    }

    fn lights() -> Vec<Light> {
        let corner = Vec3::new(-0.3, 2.0, -0.4);
        let (ex, ey) = (Vec3::new(0.6, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.8));
        vec![
            Light::Point(crate::light::PointLight { position: Vec3::new(0.5, 1.0, 0.0), intensity: Vec3::splat(2.0) }),
            Light::Rect(crate::light::RectLight { corner, ex, ey, normal: Vec3::NEG_Y, radiance: Vec3::splat(10.0), solid_angle: RectEmitter::new(corner, ex, ey, Vec3::NEG_Y) }),
            Light::Sphere(crate::light::SphereLight { center: Vec3::new(-1.0, 0.5, 0.0), radius: 0.1, radiance: Vec3::splat(5.0), cone: true }),
        ]
    }

    #[test]
    fn probabilities_sum_to_one_and_stay_positive() {
        let ls = lights();
        for (p, n) in [(Vec3::ZERO, Vec3::Y), (Vec3::new(0.0, 1.9, 0.0), Vec3::NEG_Y), (Vec3::new(3.0, 0.0, 0.0), Vec3::X), (Vec3::new(0.5, 1.0, 0.0), Vec3::Y)] {
            let prob = probabilities(&ls, p, n);
            let sum: f32 = prob[..3].iter().sum();
            assert!((sum - 1.0).abs() < 1e-5, "{prob:?}");
            assert!(prob[..3].iter().all(|&q| q >= DEFENSIVE / 3.0 - 1e-7), "{prob:?} at {p}");
            assert!(prob[3..].iter().all(|&q| q == 0.0));
        }
        // Under the lamp, facing it: the lamp dominates.
        let prob = probabilities(&ls, Vec3::new(0.0, 1.0, 0.0), Vec3::Y);
        assert!(prob[1] > 0.5, "{prob:?}");
    }

    #[test]
    fn picks_follow_the_probabilities() {
        let prob = probabilities(&lights(), Vec3::ZERO, Vec3::Y);
        let n = 100_000;
        let mut counts = [0usize; 3];
        for i in 0..n {
            counts[pick(&prob, 3, (i as f32 + 0.5) / n as f32)] += 1;
        }
        for k in 0..3 {
            assert!((counts[k] as f32 / n as f32 - prob[k]).abs() < 1e-4, "{counts:?} vs {prob:?}");
        }
        assert_eq!(pick(&prob, 3, 0.999_999_9), 2);
    }
}
