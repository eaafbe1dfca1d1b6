//! Sampling a rectangle by solid angle (Ureña, Fajardo and King, "An
//! Area-Preserving Parametrization for Spherical Rectangles", EGSR 2013).
//!
//! Model: from a point `o`, the rectangle `corner + s·ex + t·ey` (ex ⟂ ey)
//! subtends the solid angle Ω; the sampler maps (u, v) ∈ [0,1)² to a point
//! on the rectangle whose direction is uniform in that solid angle, so the
//! pdf is 1/Ω and a light sample's value is L·cos/Ω-weighted only by the
//! receiver's cosine (no 1/r² or emitter cosine left to vary). CS184 samples
//! the area uniformly (pdf r²/(A cos)): near the light that varies wildly.
//!
//! Where Ω is tiny the formulas lose precision (pbrt-v4 and Cycles switch to
//! area sampling there); `new` returns `None` below `MIN_SOLID_ANGLE` and the
//! caller samples by area — the same rule in `sample` and `pdf`, so MIS
//! stays consistent.

use glam::{DVec3, Vec3};
use std::f64::consts::PI;

/// Below this solid angle (sr) the caller samples by area instead.
pub const MIN_SOLID_ANGLE: f32 = 1e-4;

/// A rectangle as seen from one point, ready to sample. `new` works in f64:
/// Ω is a sum of four angles minus 2π, which in f32 loses ~1e-3 of a small
/// Ω (a grazing view of the Cornell light), and 1/Ω is the pdf. `sample`
/// works in f32 but for the angle φ (profiled: in f64 the two were a
/// quarter of a CBbunny render).
pub struct SphericalRect {
    o: Vec3,
    x: Vec3,
    y: Vec3,
    z: Vec3,
    x0: f32,
    x1: f32,
    y0: f32,
    y1: f32,
    z0: f32,
    b0: f32,
    b1: f32,
    /// 2π − γ2 − γ3, in f64: φ = u·Ω + k must resolve a small Ω.
    k: f64,
    /// The solid angle.
    pub omega: f32,
}

impl SphericalRect {
    /// The rectangle `corner + s·ex + t·ey`, s, t ∈ [0, 1], seen from `o`;
    /// `None` when `o` lies in its plane or the solid angle is below
    /// `MIN_SOLID_ANGLE`. `ex` and `ey` must be orthogonal.
    pub fn new(o: Vec3, corner: Vec3, ex: Vec3, ey: Vec3) -> Option<SphericalRect> {
        let (o, corner, ex, ey) = (o.as_dvec3(), corner.as_dvec3(), ex.as_dvec3(), ey.as_dvec3());
        let (a, b) = (ex.length(), ey.length());
        let x = ex / a;
        let y = ey / b;
        let mut z = x.cross(y);
        let d = corner - o;
        let mut z0 = d.dot(z);
        if z0 > 0.0 {
            z = -z;
            z0 = -z0;
        }
        if !(z0 < 0.0) {
            return None;
        }
        let (x0, y0) = (d.dot(x), d.dot(y));
        let (x1, y1) = (x0 + a, y0 + b);
        // Corner directions' edge-plane normals, in the local frame.
        let v00 = DVec3::new(x0, y0, z0);
        let v01 = DVec3::new(x0, y1, z0);
        let v10 = DVec3::new(x1, y0, z0);
        let v11 = DVec3::new(x1, y1, z0);
        let n0 = v00.cross(v10).normalize();
        let n1 = v10.cross(v11).normalize();
        let n2 = v11.cross(v01).normalize();
        let n3 = v01.cross(v00).normalize();
        let angle = |a: DVec3, b: DVec3| (-a.dot(b)).clamp(-1.0, 1.0).acos();
        let g0 = angle(n0, n1);
        let g1 = angle(n1, n2);
        let g2 = angle(n2, n3);
        let g3 = angle(n3, n0);
        let omega = g0 + g1 + g2 + g3 - 2.0 * PI;
        if !(omega >= MIN_SOLID_ANGLE as f64) || !n0.is_finite() || !n1.is_finite() || !n2.is_finite() || !n3.is_finite() {
            return None;
        }
        let f = |v: f64| v as f32;
        Some(SphericalRect {
            o: o.as_vec3(),
            x: x.as_vec3(),
            y: y.as_vec3(),
            z: z.as_vec3(),
            x0: f(x0),
            x1: f(x1),
            y0: f(y0),
            y1: f(y1),
            z0: f(z0),
            b0: f(n0.z),
            b1: f(n2.z),
            k: 2.0 * PI - g2 - g3,
            omega: f(omega),
        })
    }

    /// The point for (u, v): uniform in solid angle as (u, v) is uniform.
    pub fn sample(&self, (u, v): (f32, f32)) -> Vec3 {
        // The direction's x: the sub-rectangle [x0, xu] subtends u·Ω.
        let phi = (u as f64 * self.omega as f64 + self.k) as f32;
        let (sin_phi, cos_phi) = phi.sin_cos();
        let f = (cos_phi * self.b0 - self.b1) / sin_phi;
        let cu = (f.signum() / (f * f + self.b0 * self.b0).sqrt()).clamp(-1.0, 1.0);
        let xu = if cu.abs() < 1.0 {
            (-cu * self.z0 / (1.0 - cu * cu).sqrt()).clamp(self.x0, self.x1)
        } else if cu > 0.0 {
            self.x0
        } else {
            self.x1
        };
        // Then y, uniform in the solid angle of the strip at xu.
        let l = (xu * xu + self.z0 * self.z0).sqrt();
        let h0 = self.y0 / (l * l + self.y0 * self.y0).sqrt();
        let h1 = self.y1 / (l * l + self.y1 * self.y1).sqrt();
        let h = h0 + v * (h1 - h0);
        let h2 = h * h;
        let yv = if h2 < 1.0 - 1e-6 { (h * l / (1.0 - h2).sqrt()).clamp(self.y0, self.y1) } else { self.y1 };
        self.o + self.x * xu + self.y * yv + self.z * self.z0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Ω by the exact formula for a rectangle seen from a point on the
    /// normal through one corner (A. Van Oosterom and J. Strackee 1983,
    /// summed over four such rectangles by inclusion–exclusion).
    fn omega_exact(o: Vec3, corner: Vec3, ex: Vec3, ey: Vec3) -> f64 {
        // Solid angle of the triangle (o; a, b, c) by Van Oosterom–Strackee.
        let tri = |a: Vec3, b: Vec3, c: Vec3| -> f64 {
            let (a, b, c) = (a - o, b - o, c - o);
            let (la, lb, lc) = (a.length() as f64, b.length() as f64, c.length() as f64);
            let num = a.dot(b.cross(c)) as f64;
            let den = la * lb * lc + a.dot(b) as f64 * lc + a.dot(c) as f64 * lb + b.dot(c) as f64 * la;
            2.0 * num.atan2(den).abs()
        };
        tri(corner, corner + ex, corner + ex + ey) + tri(corner, corner + ex + ey, corner + ey)
    }

    #[test]
    fn solid_angle_and_uniformity() {
        let mut rng = Rng::new(3, 3);
        let cases = [
            (Vec3::new(0.3, -1.0, 0.2), Vec3::ZERO, Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.5)),
            (Vec3::new(5.0, 0.1, 3.0), Vec3::new(-1.0, 0.0, -1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 2.0)),
            (Vec3::new(0.01, 0.02, 0.03), Vec3::new(-1.0, 1.0, -1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 2.0)),
            // A tilted rectangle (edges not along axes).
            (Vec3::new(0.2, -0.7, 0.1), Vec3::new(-0.5, 0.0, 0.0), Vec3::new(0.6, 0.0, 0.6), Vec3::new(0.0, 0.8, 0.0).cross(Vec3::new(0.6, 0.0, 0.6)).normalize() * 0.4),
        ];
        for (o, corner, ex, ey) in cases {
            let r = SphericalRect::new(o, corner, ex, ey).unwrap();
            let exact = omega_exact(o, corner, ex, ey);
            assert!((r.omega as f64 - exact).abs() < 1e-5 * exact, "Ω {} vs {exact}", r.omega);
            // Points lie on the rectangle; their directions are uniform in
            // solid angle: the rectangle's 4x4 cells get Ω_cell/Ω of them.
            let n = 200_000;
            let mut counts = [0u32; 16];
            let (a, b) = (ex.length(), ey.length());
            for _ in 0..n {
                let p = r.sample(rng.uniform2());
                let (s, t) = ((p - corner).dot(ex) / (a * a), (p - corner).dot(ey) / (b * b));
                assert!((-1e-4..=1.0001).contains(&s) && (-1e-4..=1.0001).contains(&t), "({s}, {t}) off the rectangle");
                assert!(((p - corner).dot(ex.cross(ey).normalize())).abs() < 1e-4 * (1.0 + o.length()), "off the plane");
                let (i, j) = (((s * 4.0) as usize).min(3), ((t * 4.0) as usize).min(3));
                counts[i * 4 + j] += 1;
            }
            let mut chi2 = 0.0;
            for i in 0..4 {
                for j in 0..4 {
                    let cell = omega_exact(o, corner + ex * (i as f32 / 4.0) + ey * (j as f32 / 4.0), ex / 4.0, ey / 4.0);
                    let e = n as f64 * cell / exact;
                    chi2 += (counts[i * 4 + j] as f64 - e).powi(2) / e;
                }
            }
            // χ² with 15 degrees of freedom: p = 1e-4 at 42.3.
            assert!(chi2 < 42.3, "χ² {chi2:.1} for o = {o}");
        }
    }

    #[test]
    fn degenerate_views_fall_back() {
        // In the plane, and so far away that Ω is below the threshold.
        assert!(SphericalRect::new(Vec3::new(3.0, 0.0, 0.0), Vec3::ZERO, Vec3::X, Vec3::Z).is_none());
        assert!(SphericalRect::new(Vec3::new(0.0, 1000.0, 0.0), Vec3::ZERO, Vec3::X * 0.1, Vec3::Z * 0.1).is_none());
    }
}

/// A one-sided rectangular emitter `corner + s·ex + t·ey` (ex ⟂ ey)
/// emitting towards `normal`: CS184's area light, or an emissive mesh of two
/// triangles forming a rectangle (the Cornell boxes' ceiling light).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RectEmitter {
    pub corner: Vec3,
    pub ex: Vec3,
    pub ey: Vec3,
    pub normal: Vec3,
}

impl RectEmitter {
    /// `corner`, `ex`, `ey` as a rectangle, if the edges are orthogonal
    /// (to 1e-5 of their lengths' product).
    pub fn new(corner: Vec3, ex: Vec3, ey: Vec3, normal: Vec3) -> Option<RectEmitter> {
        let scale = ex.length() * ey.length();
        (scale > 0.0 && scale.is_finite() && ex.dot(ey).abs() <= 1e-5 * scale).then_some(RectEmitter { corner, ex, ey, normal })
    }

    /// The rectangle two triangles form: four distinct corners, the two
    /// triangles sharing a diagonal, facing the same way, the other
    /// diagonal bisecting it (a parallelogram) and the edges orthogonal.
    pub fn of_triangles(t: &[[Vec3; 3]]) -> Option<RectEmitter> {
        let [t0, t1] = t else { return None };
        let n0 = (t0[1] - t0[0]).cross(t0[2] - t0[0]);
        let n1 = (t1[1] - t1[0]).cross(t1[2] - t1[0]);
        if !(n0.dot(n1) > 0.0) {
            return None;
        }
        let normal = n0.normalize();
        // The shared diagonal: two corners of t0 that t1 has too.
        let shared: Vec<Vec3> = t0.iter().copied().filter(|p| t1.contains(p)).collect();
        let [p, q] = shared[..] else { return None };
        let r = *t0.iter().find(|v| **v != p && **v != q)?;
        let s = *t1.iter().find(|v| **v != p && **v != q)?;
        let size = (p - q).length();
        if ((r + s) - (p + q)).length() > 1e-5 * size {
            return None;
        }
        RectEmitter::new(r, p - r, q - r, normal)
    }

    /// The solid-angle sampler from `p`, when `p` is in front and the
    /// rectangle subtends enough; `None` means "sample by area".
    pub fn from(&self, p: Vec3) -> Option<SphericalRect> {
        if !(self.normal.dot(p - self.corner) > 0.0) {
            return None;
        }
        SphericalRect::new(p, self.corner, self.ex, self.ey)
    }
}

#[cfg(test)]
mod emitter_tests {
    use super::*;

    #[test]
    fn two_triangles_of_a_rectangle_are_recognised() {
        let (a, b, c, d) = (Vec3::new(0.0, 2.0, 0.0), Vec3::new(1.0, 2.0, 0.0), Vec3::new(1.0, 2.0, 0.5), Vec3::new(0.0, 2.0, 0.5));
        let r = RectEmitter::of_triangles(&[[a, b, c], [a, c, d]]).expect("a rectangle");
        assert!((r.ex.cross(r.ey).length() - 0.5).abs() < 1e-6);
        assert!(r.normal.dot(Vec3::NEG_Y) > 0.99, "{}", r.normal);
        // A parallelogram that is not a rectangle, a non-planar pair and
        // triangles facing opposite ways are not.
        let e = Vec3::new(0.3, 2.0, 0.5);
        let f = Vec3::new(1.3, 2.0, 0.5);
        assert!(RectEmitter::of_triangles(&[[a, b, f], [a, f, e]]).is_none());
        assert!(RectEmitter::of_triangles(&[[a, b, c], [a, c, d + Vec3::Y * 0.1]]).is_none());
        assert!(RectEmitter::of_triangles(&[[a, b, c], [a, d, c]]).is_none());
        // From behind (the light emits downwards), no solid-angle sampler.
        assert!(r.from(Vec3::new(0.5, 3.0, 0.2)).is_none());
        assert!(r.from(Vec3::new(0.5, 1.0, 0.2)).is_some());
    }
}
