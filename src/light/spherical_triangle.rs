//! Sampling a triangle by solid angle (Arvo, "Stratified Sampling of
//! Spherical Triangles", SIGGRAPH 1995), for emissive meshes that are not
//! one rectangle.
//!
//! Model: from a point `o`, the triangle ABC subtends the spherical triangle
//! of the unit vectors a, b, c with area Ω. The sampler maps (u, v) ∈ [0,1)²
//! to a direction uniform in it: u picks the sub-triangle A B C' of area u·Ω
//! (C' on the arc AC), v a point on the arc from B to C' uniform in the
//! sub-triangle's measure. The pdf is 1/Ω. CS184 samples every emitter by
//! area (pdf r²/(A cos)), which near a big triangle varies wildly.
//!
//! When it pays (pbrt-v4's rule): for Ω between 3·10⁻⁴ sr, below which the
//! arithmetic loses precision and area sampling is nearly uniform in solid
//! angle anyway, and 6.22 sr (just under 2π), above which the point is so
//! close to the plane that the construction degenerates. Outside that range,
//! or from behind the emitting side, `new` returns `None` and the caller
//! samples by area — the same rule in its pdf. All of it is in f64: the
//! angles are differences of nearly equal quantities for small triangles.

use glam::{DVec3, Vec3};

/// Solid angles (sr) outside which the caller samples by area (pbrt-v4's
/// `MinSphericalSampleArea` and `MaxSphericalSampleArea`).
pub const MIN_SOLID_ANGLE: f64 = 3e-4;
pub const MAX_SOLID_ANGLE: f64 = 6.22;

/// A triangle as seen from one point, ready to sample.
pub struct SphericalTriangle {
    o: DVec3,
    a: DVec3,
    b: DVec3,
    /// Unit vector in the plane of a and c, orthogonal to a (towards c).
    c_perp: DVec3,
    /// The interior angle at vertex A (and its sine and cosine), and the
    /// cosine of the arc AB.
    alpha: f64,
    sin_alpha: f64,
    cos_alpha: f64,
    cos_ab: f64,
    /// The triangle's plane (for the point a direction meets): a point and
    /// the unit normal on the emitting side.
    p0: DVec3,
    n: DVec3,
    /// The solid angle.
    pub omega: f64,
}

impl SphericalTriangle {
    /// Triangle (v0, v1, v2), emitting on the side its winding's normal
    /// points to, seen from `o`; `None` from behind, in its plane, or when
    /// Ω is outside [`MIN_SOLID_ANGLE`, `MAX_SOLID_ANGLE`].
    pub fn new(o: Vec3, v0: Vec3, v1: Vec3, v2: Vec3) -> Option<SphericalTriangle> {
        let o = o.as_dvec3();
        let (p0, p1, p2) = (v0.as_dvec3(), v1.as_dvec3(), v2.as_dvec3());
        let n = (p1 - p0).cross(p2 - p0).normalize();
        // In front of the emitting side, clearly off the plane.
        if !((o - p0).dot(n) > 0.0) {
            return None;
        }
        let (a, b, c) = ((p0 - o).normalize(), (p1 - o).normalize(), (p2 - o).normalize());
        // Van Oosterom and Strackee: tan(Ω/2) = |a·(b×c)| / (1 + a·b + b·c + c·a).
        let omega = 2.0 * a.dot(b.cross(c)).abs().atan2(1.0 + a.dot(b) + b.dot(c) + c.dot(a));
        if !(MIN_SOLID_ANGLE..=MAX_SOLID_ANGLE).contains(&omega) {
            return None;
        }
        // The angle at A between the great circles AB and AC: between the
        // components of b and c orthogonal to a.
        let b_perp = (b - a * a.dot(b)).normalize();
        let c_perp = (c - a * a.dot(c)).normalize();
        let alpha = b_perp.cross(c_perp).length().atan2(b_perp.dot(c_perp));
        if !(alpha > 0.0) || !c_perp.is_finite() || !b_perp.is_finite() {
            return None;
        }
        let (sin_alpha, cos_alpha) = alpha.sin_cos();
        Some(SphericalTriangle { o, a, b, c_perp, alpha, sin_alpha, cos_alpha, cos_ab: a.dot(b), p0, n, omega })
    }

    /// The point of the triangle for (u, v): its direction is uniform in
    /// solid angle as (u, v) is uniform.
    pub fn sample(&self, (u, v): (f32, f32)) -> Vec3 {
        let (u, v) = (u as f64, v as f64);
        // C' on the arc AC such that the spherical triangle A B C' has area u·Ω.
        let area = u * self.omega;
        let (s, t) = (area - self.alpha).sin_cos();
        let (sin_alpha, cos_alpha) = (self.sin_alpha, self.cos_alpha);
        let pp = t - cos_alpha;
        let qq = s + sin_alpha * self.cos_ab;
        let cos_b = (((qq * t - pp * s) * cos_alpha - qq) / ((qq * s + pp * t) * sin_alpha)).clamp(-1.0, 1.0);
        let c1 = self.a * cos_b + self.c_perp * (1.0 - cos_b * cos_b).max(0.0).sqrt();
        // Then the direction on the arc from B to C', uniform in measure:
        // its cosine to B is uniform between 1 and c1·b.
        let z = 1.0 - v * (1.0 - c1.dot(self.b));
        let along = (c1 - self.b * c1.dot(self.b)).normalize_or_zero();
        let dir = (self.b * z + along * (1.0 - z * z).max(0.0).sqrt()).normalize();
        // Where that direction meets the triangle's plane.
        let t = (self.p0 - self.o).dot(self.n) / dir.dot(self.n);
        (self.o + dir * t).as_vec3()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Barycentric coordinates of `p` in triangle (a, b, c), in f64.
    fn barycentric(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> (f64, f64) {
        let (p, a, b, c) = (p.as_dvec3(), a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
        let (e1, e2, d) = (b - a, c - a, p - a);
        let (d11, d12, d22, d1, d2) = (e1.dot(e1), e1.dot(e2), e2.dot(e2), d.dot(e1), d.dot(e2));
        let den = d11 * d22 - d12 * d12;
        ((d22 * d1 - d12 * d2) / den, (d11 * d2 - d12 * d1) / den)
    }

    /// Solid angle of (a, b, c) from `o` by Van Oosterom–Strackee, in f64.
    fn omega_of(o: Vec3, a: Vec3, b: Vec3, c: Vec3) -> f64 {
        let o = o.as_dvec3();
        let (a, b, c) = (a.as_dvec3() - o, b.as_dvec3() - o, c.as_dvec3() - o);
        let (la, lb, lc) = (a.length(), b.length(), c.length());
        2.0 * a.dot(b.cross(c)).abs().atan2(la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la)
    }

    #[test]
    fn directions_are_uniform_in_solid_angle() {
        let mut rng = Rng::new(11, 5);
        let (a, b, c) = (Vec3::new(-1.0, 1.0, -0.5), Vec3::new(1.5, 1.0, -0.7), Vec3::new(0.2, 1.0, 1.2));
        // Triangle in the plane y = 1 wound so its normal is -y: lit from below.
        for o in [Vec3::new(0.1, 0.0, 0.0), Vec3::new(0.3, 0.9, 0.2), Vec3::new(-4.0, -1.0, 3.0), Vec3::new(0.0, -30.0, 0.0)] {
            let st = SphericalTriangle::new(o, a, b, c).expect("in front, Ω in range");
            assert!((st.omega - omega_of(o, a, b, c)).abs() < 1e-9 * st.omega);
            // Cells: the triangle split into 16 by its barycentric grid
            // (4 subdivisions per edge), each weighted by its solid angle.
            let k = 4usize;
            let mut cells = Vec::new();
            let mut index = std::collections::HashMap::new();
            let at = |i: usize, j: usize| a + (b - a) * (i as f32 / k as f32) + (c - a) * (j as f32 / k as f32);
            for i in 0..k {
                for j in 0..k - i {
                    index.insert((i, j, false), cells.len());
                    cells.push((at(i, j), at(i + 1, j), at(i, j + 1)));
                    if i + j + 1 < k {
                        index.insert((i, j, true), cells.len());
                        cells.push((at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)));
                    }
                }
            }
            assert_eq!(cells.len(), 16);
            let n = 200_000;
            let mut counts = vec![0f64; cells.len()];
            for _ in 0..n {
                let q = st.sample(rng.uniform2());
                let (u, v) = barycentric(q, a, b, c);
                assert!(u > -1e-5 && v > -1e-5 && u + v < 1.0 + 1e-5, "({u}, {v}) off the triangle from {o}");
                let (su, sv) = ((u * k as f64).clamp(0.0, k as f64 - 1e-9), (v * k as f64).clamp(0.0, k as f64 - 1e-9));
                let (i, j) = (su.floor() as usize, sv.floor() as usize);
                let upper = su.fract() + sv.fract() >= 1.0;
                // A point just past the hypotenuse of a border square by rounding.
                let key = if index.contains_key(&(i, j, upper)) { (i, j, upper) } else { (i, j, false) };
                counts[*index.get(&key).unwrap_or_else(|| panic!("no cell for ({u}, {v})"))] += 1.0;
            }
            let total: f64 = cells.iter().map(|&(p, q2, r)| omega_of(o, p, q2, r)).sum();
            assert!((total - st.omega).abs() < 1e-6 * st.omega);
            let chi2: f64 = cells.iter().zip(&counts).map(|(&(p, q2, r), &cnt)| {
                let e = n as f64 * omega_of(o, p, q2, r) / total;
                (cnt - e) * (cnt - e) / e
            }).sum();
            // 15 degrees of freedom: p = 1e-4 at 42.3.
            assert!(chi2 < 42.3, "χ² {chi2:.1} from {o}");
        }
    }

    #[test]
    fn out_of_range_views_fall_back() {
        let (a, b, c) = (Vec3::new(-1.0, 1.0, -0.5), Vec3::new(1.5, 1.0, -0.7), Vec3::new(0.2, 1.0, 1.2));
        assert!(SphericalTriangle::new(Vec3::new(0.0, 2.0, 0.0), a, b, c).is_none(), "behind");
        assert!(SphericalTriangle::new(Vec3::new(5.0, 1.0, 0.0), a, b, c).is_none(), "in the plane");
        assert!(SphericalTriangle::new(Vec3::new(0.0, -500.0, 0.0), a, b, c).is_none(), "Ω below the minimum");
        assert!(SphericalTriangle::new(Vec3::new(0.2, 0.9999, 0.0), a, b, c).is_none(), "Ω above the maximum");
    }
}
