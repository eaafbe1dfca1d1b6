//! Sampling an emissive sphere seen from outside by the cone of directions
//! it subtends (as pbrt-v4's `Sphere::Sample` with a reference point).
//!
//! Model: from `p` at distance d > r from the centre, the sphere fills the
//! cone of half-angle θmax, sin θmax = r/d. A direction uniform in that cone
//! has pdf 1/(2π(1 − cos θmax)); the point sampled is where it meets the
//! sphere's near side. Every sample then lands on the visible cap, where
//! CS184's uniform sampling of the whole sphere wastes the half facing away
//! and weights the rest by r²/cos. Inside the sphere (or on it) the caller
//! samples by area.

use glam::Vec3;
use std::f32::consts::PI;

/// The cone from `p` to the sphere, ready to sample.
#[derive(Clone, Copy, Debug)]
pub struct SphereCone {
    p: Vec3,
    dist: f32,
    radius: f32,
    /// sin² θmax.
    sin2_max: f32,
    bound: ConeBound,
}

/// What membership and density need of a cone: its unit axis and
/// 1 − cos θmax (by series where θmax is tiny). A sixth of `SphereCone`'s
/// size, for callers that hold many cones and sample few (`GuideAt`).
#[derive(Clone, Copy, Debug, Default)]
pub struct ConeBound {
    w: Vec3,
    one_minus_cos_max: f32,
}

impl ConeBound {
    /// The cone's solid-angle pdf.
    pub fn pdf(&self) -> f32 {
        1.0 / (2.0 * PI * self.one_minus_cos_max)
    }

    /// Whether unit direction `w` lies in the cone. 1 − cos of its angle to
    /// the axis is taken as |w − axis|²/2: exact to a few ulps of itself,
    /// where 1 − w·axis keeps only an absolute 6e-8, as large as a far
    /// sphere's whole cone.
    pub fn contains(&self, w: Vec3) -> bool {
        0.5 * (w - self.w).length_squared() <= self.one_minus_cos_max
    }
}

impl SphereCone {
    /// `None` when `p` is not clearly outside the sphere.
    pub fn new(p: Vec3, center: Vec3, radius: f32) -> Option<SphereCone> {
        let d = center - p;
        let dist2 = d.length_squared();
        if !(dist2 > radius * radius * 1.0001) || !dist2.is_finite() {
            return None;
        }
        let dist = dist2.sqrt();
        let w = d / dist;
        let sin2_max = radius * radius / dist2;
        // 1 − sqrt(1 − s) loses everything in f32 for small s: series.
        let one_minus_cos_max = if sin2_max < 1e-3 { sin2_max * (0.5 + sin2_max / 8.0) } else { 1.0 - (1.0 - sin2_max).sqrt() };
        Some(SphereCone { p, dist, radius, sin2_max, bound: ConeBound { w, one_minus_cos_max } })
    }

    /// The cone's axis and aperture alone.
    pub fn bound(&self) -> ConeBound {
        self.bound
    }

    /// The cone's solid-angle pdf.
    pub fn pdf(&self) -> f32 {
        self.bound.pdf()
    }

    /// Whether unit direction `w` lies in the cone (`ConeBound::contains`).
    pub fn contains(&self, w: Vec3) -> bool {
        self.bound.contains(w)
    }

    /// A direction uniform in the cone, and the point where it meets the
    /// sphere (its near side).
    pub fn sample(&self, u: (f32, f32)) -> (Vec3, Vec3) {
        // cos θ uniform in [cos θmax, 1]: 1 − cos θ = u·(1 − cos θmax).
        let ConeBound { w, one_minus_cos_max } = self.bound;
        // The frame around the axis is made here, not in `new`: most cones
        // made are only asked `contains` and `pdf`.
        let (t, b) = w.any_orthonormal_pair();
        let one_minus_cos = u.0 * one_minus_cos_max;
        let sin2 = (one_minus_cos * (2.0 - one_minus_cos)).min(self.sin2_max);
        let cos = 1.0 - one_minus_cos;
        let sin = sin2.max(0.0).sqrt();
        let phi = 2.0 * PI * u.1;
        let wi = (w * cos + t * (sin * phi.cos()) + b * (sin * phi.sin())).normalize();
        // Distance along wi to the near side: d cos θ − sqrt(r² − d² sin² θ),
        // the root clamped at 0 for rays grazing the rim.
        let along = self.dist * cos - (self.radius * self.radius - self.dist * self.dist * sin2).max(0.0).sqrt();
        (wi, self.p + wi * along)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    #[test]
    fn directions_fill_the_cone_uniformly_and_points_lie_on_the_near_side() {
        let mut rng = Rng::new(6, 6);
        for (p, c, r) in [(Vec3::ZERO, Vec3::new(0.0, 0.0, 3.0), 1.0), (Vec3::new(1.0, 2.0, 3.0), Vec3::new(-2.0, 0.5, 1.0), 2.5), (Vec3::ZERO, Vec3::new(40.0, 0.0, 0.0), 0.05)] {
            let cone = SphereCone::new(p, c, r).unwrap();
            let (rows, cols, n) = (8usize, 8usize, 160_000);
            let mut counts = vec![0.0f64; rows * cols];
            for _ in 0..n {
                let (wi, q) = cone.sample(rng.uniform2());
                assert!(((q - c).length() - r).abs() < 1e-3 * r, "{q} not on the sphere");
                assert!((q - c).dot(p - q) >= -1e-3 * r * (p - c).length(), "{q} on the far side");
                assert!(((q - p).normalize() - wi).length() < 1e-3);
                // Uniform in the cone: 1 − cos θ uniform over [0, 1 − cos θmax].
                // 1 − cos θ from sin² θ (the tangential part), which f32 keeps
                // for the far sphere's 1e-6-wide cone where 1 − cos would not.
                let (t, b) = cone.bound.w.any_orthonormal_pair();
                let (ct, cb) = (wi.dot(t) as f64, wi.dot(b) as f64);
                let sin2 = ct * ct + cb * cb;
                let one_minus = sin2 / (1.0 + (1.0 - sin2).max(0.0).sqrt());
                let row = ((one_minus / cone.bound.one_minus_cos_max as f64 * rows as f64) as usize).min(rows - 1);
                let phi = (wi.dot(b)).atan2(wi.dot(t)).rem_euclid(2.0 * PI);
                let col = ((phi / (2.0 * PI) * cols as f32) as usize).min(cols - 1);
                counts[row * cols + col] += 1.0;
            }
            let e = n as f64 / (rows * cols) as f64;
            let chi2: f64 = counts.iter().map(|o| (o - e).powi(2) / e).sum();
            // 63 dof: p = 1e-4 near 111.
            assert!(chi2 < 111.0, "χ² {chi2:.1} for the sphere at {c}");
            // The pdf is the inverse of the cone's solid angle 2π(1 − cos θmax),
            // which for the tiny far sphere must match π r²/d² closely.
            let omega = 1.0 / cone.pdf() as f64;
            let d2 = (c - p).length_squared() as f64;
            let exact = 2.0 * std::f64::consts::PI * (1.0 - (1.0 - (r * r) as f64 / d2).sqrt());
            assert!((omega - exact).abs() < 1e-4 * exact, "Ω {omega} vs {exact}");
        }
        assert!(SphereCone::new(Vec3::ZERO, Vec3::ZERO, 1.0).is_none());
    }
}
