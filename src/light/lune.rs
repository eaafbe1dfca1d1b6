//! Sampling the hemisphere ("ambient") light at a diffuse vertex: the
//! clipped cosine over the "lune" of directions both above the surface
//! (around the shading normal n) and in the sky (y > 0).
//!
//! Model: pdf(ω) = (ω·n) / ((π/2)(1 + c)) on H(n) ∩ H(+y), c = n·y. For a
//! diffuse BSDF f = ρ/π the light sample's weight f·L·cos/pdf is then the
//! constant ρL(1+c)/2: zero variance but for visibility. It is the exact
//! product of BSDF and light, so at diffuse vertices it is used *alone*:
//! BSDF-sampled rays there that escape into the sky add nothing (else the
//! sky would be counted twice). Non-diffuse vertices keep uniform
//! hemisphere sampling with MIS. CS184 samples the uniform hemisphere
//! everywhere (pdf 1/2π), whose weight varies with the cosine.
//!
//! Construction (cosine sampling is a uniform disk point lifted onto the
//! hemisphere, Malley): with t the unit projection of +y onto the tangent
//! plane and b = n × t, the disk point (p, q) (p along t) lifts into the sky
//! exactly when p > −c·√(1−q²). So a uniform disk point has its p mapped
//! affinely from the chord [−w, w] onto [−c·w, w], w = √(1−q²): uniform
//! stays uniform, and the lift is cosine-distributed over the lune.

use crate::sampling::concentric_disk;
use glam::Vec3;
use std::f32::consts::PI;

/// The sky's up direction (CS184's hemisphere light is the +y half).
const UP: Vec3 = Vec3::Y;

/// The tangent towards the sky and the other tangent, for normal `n`.
fn tangents(n: Vec3) -> (Vec3, Vec3) {
    let t = UP - n * n.dot(UP);
    let t = if t.length_squared() > 1e-12 { t.normalize() } else { n.any_orthonormal_vector() };
    (t, n.cross(t))
}

/// A direction of the lune of unit normal `n` and its solid-angle pdf;
/// `None` when no direction above the surface sees the sky (c = −1).
pub fn sample(n: Vec3, u: (f32, f32)) -> Option<(Vec3, f32)> {
    let c = n.dot(UP).clamp(-1.0, 1.0);
    if c <= -1.0 + 1e-6 {
        return None;
    }
    let (t, b) = tangents(n);
    let (p, q) = concentric_disk(u);
    let w = (1.0 - q * q).max(0.0).sqrt();
    let p = 0.5 * (1.0 + c) * (p + w) - c * w;
    let h = (1.0 - p * p - q * q).max(0.0).sqrt();
    let wi = (t * p + b * q + n * h).normalize();
    let pdf = pdf(n, wi);
    (pdf > 0.0).then_some((wi, pdf))
}

/// The pdf of `sample` for direction `wi` (0 outside the lune).
pub fn pdf(n: Vec3, wi: Vec3) -> f32 {
    let c = n.dot(UP).clamp(-1.0, 1.0);
    let cos = wi.dot(n);
    if cos <= 0.0 || wi.dot(UP) <= 0.0 || c <= -1.0 + 1e-6 {
        return 0.0;
    }
    cos / (0.5 * PI * (1.0 + c))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn normals() -> Vec<Vec3> {
        vec![Vec3::Y, Vec3::X, Vec3::new(0.3, -0.5, 0.2).normalize(), Vec3::new(-0.2, 0.9, 0.4).normalize(), Vec3::new(0.0, -0.95, 0.3).normalize()]
    }

    #[test]
    fn directions_lie_in_the_lune_and_integrate_its_solid_angle() {
        let mut rng = Rng::new(4, 4);
        for n in normals() {
            let c = n.dot(UP) as f64;
            let exact = 2.0 * (std::f64::consts::PI - c.clamp(-1.0, 1.0).acos());
            let m = 200_000;
            let (mut s1, mut s2) = (0.0f64, 0.0f64);
            for _ in 0..m {
                let (wi, p) = sample(n, rng.uniform2()).unwrap();
                assert!(wi.dot(n) >= -1e-6 && wi.dot(UP) >= -1e-6, "{wi} outside the lune of {n}");
                assert!((p - pdf(n, wi)).abs() <= 1e-4 * p.max(1e-3));
                let x = 1.0 / p as f64;
                s1 += x;
                s2 += x * x;
            }
            // E[1/pdf] = the lune's solid angle, within 5 standard errors.
            let mean = s1 / m as f64;
            let se = ((s2 / m as f64 - mean * mean) / m as f64).sqrt();
            assert!((mean - exact).abs() < 5.0 * se + 1e-4, "n {n}: E[1/pdf] {mean} ± {se} vs {exact}");
        }
    }

    #[test]
    fn directions_follow_the_pdf() {
        // χ² over a (cos θ about n, φ) grid: expected counts from the pdf
        // integrated numerically over each cell.
        let mut rng = Rng::new(8, 8);
        for n in normals() {
            let (t, b) = tangents(n);
            let (rows, cols, m) = (6, 8, 240_000);
            let cell = |w: Vec3| {
                let r = ((w.dot(n).clamp(0.0, 0.999_999) * rows as f32) as usize).min(rows - 1);
                let phi = w.dot(b).atan2(w.dot(t)).rem_euclid(2.0 * PI);
                r * cols + ((phi / (2.0 * PI) * cols as f32) as usize).min(cols - 1)
            };
            let mut counts = vec![0.0f64; rows * cols];
            for _ in 0..m {
                counts[cell(sample(n, rng.uniform2()).unwrap().0)] += 1.0;
            }
            let mut expected = vec![0.0f64; rows * cols];
            let k = 1600;
            for i in 0..k {
                for j in 0..k {
                    // Uniform in (cos θ, φ): dω = d(cos θ) dφ.
                    let (ct, phi) = ((i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32 * 2.0 * PI);
                    let st = (1.0 - ct * ct).sqrt();
                    let w = t * (st * phi.cos()) + b * (st * phi.sin()) + n * ct;
                    expected[cell(w)] += pdf(n, w) as f64 * (2.0 * PI as f64) / (k * k) as f64 * m as f64;
                }
            }
            let chi2: f64 = counts.iter().zip(&expected).filter(|(_, e)| **e > 20.0).map(|(o, e)| (o - e).powi(2) / e).sum();
            let dof = expected.iter().filter(|e| **e > 20.0).count() as f64 - 1.0;
            // Normal approximation of χ² at p ≈ 1e-4: dof + 3.7·sqrt(2 dof).
            assert!(chi2 < dof + 3.7 * (2.0 * dof).sqrt() + 10.0, "n {n}: χ² {chi2:.1} over {dof} dof");
        }
    }

    #[test]
    fn a_diffuse_plane_under_the_sky_has_zero_variance() {
        // The light sample's weight f·L·cos/pdf = ρL(1+c)/2 for every sample.
        let mut rng = Rng::new(1, 2);
        for n in normals() {
            let c = n.dot(UP);
            if c <= -0.99 {
                continue;
            }
            let want = 0.5 * (1.0 + c);
            for _ in 0..10_000 {
                let (wi, p) = sample(n, rng.uniform2()).unwrap();
                let weight = (1.0 / PI) * wi.dot(n) / p;
                assert!((weight - want).abs() < 2e-4 * want.max(1e-2), "n {n}: weight {weight} vs {want}");
            }
        }
    }
}
