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
use crate::render::illuminance;
use crate::scene::{Scene, Shape};
use glam::Vec3;
use std::f32::consts::PI;

/// Up to this many lights are picked from (a probability table on the stack).
pub const MAX_LIGHTS: usize = 8;

/// The uniform share of the pick: keeps every light's probability at least
/// δ/K where its centre estimate says it sends nothing (a grazing rectangle
/// half above the horizon).
pub const DEFENSIVE: f32 = 0.1;

/// Whether `light` has an estimate at all.
pub fn can_pick(light: &Light) -> bool {
    !matches!(light, Light::Hemisphere { .. } | Light::Environment(_))
}

/// An emissive mesh as the pick sees it: its area at its centroid, facing
/// its mean normal where its normals agree.
#[derive(Clone, Copy, Debug)]
struct MeshProxy {
    center: Vec3,
    normal: Option<Vec3>,
    area: f32,
}

/// What the pick needs beyond the lights: each emissive mesh's proxy.
#[derive(Clone, Debug)]
pub struct Picker {
    meshes: Vec<Option<MeshProxy>>,
}

impl Picker {
    /// For `lights` of `scene`, when they can be picked from: 2 to
    /// `MAX_LIGHTS` of them, all with an estimate.
    pub fn new(scene: &Scene, lights: &[Light]) -> Option<Picker> {
        if !(2..=MAX_LIGHTS).contains(&lights.len()) || !lights.iter().all(can_pick) {
            return None;
        }
        let meshes = lights
            .iter()
            .map(|l| {
                let Light::Mesh { geom_id, .. } = l else { return None };
                let Shape::Mesh(m) = &scene.shapes[*geom_id as usize] else { return None };
                let (mut area, mut center, mut nsum) = (0.0f32, Vec3::ZERO, Vec3::ZERO);
                for t in &m.triangles {
                    let [a, b, c] = t.map(|i| m.positions[i as usize]);
                    let cross = (b - a).cross(c - a);
                    let ai = 0.5 * cross.length();
                    area += ai;
                    center += ai * (a + b + c) / 3.0;
                    nsum += 0.5 * cross;
                }
                (area > 0.0).then(|| MeshProxy { center: center / area, normal: (nsum.length() > 0.9 * area).then(|| nsum.normalize()), area })
            })
            .collect();
        Some(Picker { meshes })
    }

    /// The pick probabilities of `lights` (those `new` was given) at `p`
    /// with normal `n`; entries past `lights.len()` are 0.
    pub fn probabilities(&self, lights: &[Light], p: Vec3, n: Vec3) -> [f32; MAX_LIGHTS] {
        debug_assert!(lights.len() <= MAX_LIGHTS);
        let mut prob = [0.0f32; MAX_LIGHTS];
        let k = lights.len();
        let mut sum = 0.0;
        for (i, (e, l)) in prob.iter_mut().zip(lights).enumerate() {
            *e = self.estimate(i, l, p, n);
            sum += *e;
        }
        let uniform = 1.0 / k as f32;
        for e in &mut prob[..k] {
            *e = if sum > 0.0 && sum.is_finite() { (1.0 - DEFENSIVE) * *e / sum + DEFENSIVE * uniform } else { uniform };
        }
        prob
    }

    /// Light `i`'s unshadowed irradiance estimate at `p` with normal `n`.
    fn estimate(&self, i: usize, light: &Light, p: Vec3, n: Vec3) -> f32 {
        let toward = |c: Vec3| {
            let d = c - p;
            let r2 = d.length_squared();
            (r2 > 0.0).then(|| (d / r2.sqrt(), r2))
        };
        // Luminance × area × the emitter's and the receiver's cosines / r².
        let patch = |c: Vec3, area: f32, normal: Option<Vec3>, radiance: Vec3| {
            toward(c).map_or(0.0, |(w, r2)| {
                let cos_l = normal.map_or(0.5, |nl| (-nl.dot(w)).max(0.0));
                illuminance(radiance) * area * cos_l * n.dot(w).max(0.0) / r2
            })
        };
        let e = match light {
            Light::Point { position, intensity } => toward(*position).map_or(0.0, |(w, r2)| illuminance(*intensity) * n.dot(w).max(0.0) / r2),
            Light::Directional { to_light, irradiance } => illuminance(*irradiance) * n.dot(*to_light).max(0.0),
            Light::Rect { corner, ex, ey, normal, radiance, .. } => patch(*corner + 0.5 * (*ex + *ey), ex.cross(*ey).length(), Some(*normal), *radiance),
            Light::Mesh { radiance, .. } => self.meshes[i].map_or(0.0, |m| patch(m.center, m.area, m.normal, *radiance)),
            Light::Sphere { center, radius, radiance, .. } => toward(*center).map_or(0.0, |(w, r2)| illuminance(*radiance) * PI * radius * radius * n.dot(w).max(0.0) / r2),
            Light::Hemisphere { .. } | Light::Environment(_) => 0.0,
        };
        if e.is_finite() { e.max(0.0) } else { 0.0 }
    }
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
        Picker { meshes: vec![None; lights.len()] }.probabilities(lights, p, n)
    }

    fn lights() -> Vec<Light> {
        let corner = Vec3::new(-0.3, 2.0, -0.4);
        let (ex, ey) = (Vec3::new(0.6, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.8));
        vec![
            Light::Point { position: Vec3::new(0.5, 1.0, 0.0), intensity: Vec3::splat(2.0) },
            Light::Rect { corner, ex, ey, normal: Vec3::NEG_Y, radiance: Vec3::splat(10.0), solid_angle: RectEmitter::new(corner, ex, ey, Vec3::NEG_Y) },
            Light::Sphere { center: Vec3::new(-1.0, 0.5, 0.0), radius: 0.1, radiance: Vec3::splat(5.0), cone: true },
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
