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

use glam::Vec3;

/// Below this solid angle (sr) the caller samples by area instead.
pub const MIN_SOLID_ANGLE: f32 = 1e-4;

/// A rectangle as seen from one point, ready to sample.
///
/// In the rectangle's frame (x, y along its edges, z its normal turned so
/// the rectangle lies at z = z0 < 0 below the point) the corners are
/// (x_i, y_j, z0). Each corner contributes the angle
/// A(x, y) = atan(x·y / (|z0|·√(x² + y² + z0²))), and
/// Ω = A(x1,y1) + A(x0,y0) − A(x1,y0) − A(x0,y1) — Ureña et al.'s
/// Σγ − 2π with γ = π/2 ∓ A, without the cancellation against 2π. The four
/// angles are added as one complex product (one atan2, in f64: Ω is a
/// difference of angles, and a far or grazing rectangle's Ω is small against
/// them); the sampler's
/// angle φ = u·Ω + 2π − γ2 − γ3 becomes π + t0 + u·Ω with t0 = A(x0,y1) −
/// A(x0,y0), and only cos t0 and sin t0 (algebraic) are kept, so a sample
/// costs one sin/cos of u·Ω, which is exact however small Ω is.
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
    cos_t0: f32,
    sin_t0: f32,
    /// The solid angle.
    pub omega: f32,
}

impl SphericalRect {
    /// The rectangle `corner + s·ex + t·ey`, s, t ∈ [0, 1], seen from `o`;
    /// `None` when `o` lies in its plane or the solid angle is below
    /// `MIN_SOLID_ANGLE`. `ex` and `ey` must be orthogonal.
    pub fn new(o: Vec3, corner: Vec3, ex: Vec3, ey: Vec3) -> Option<SphericalRect> {
        let (a, b) = (ex.length(), ey.length());
        let x = ex / a;
        let y = ey / b;
        SphericalRect::framed(o, corner, Frame { x, y, z: x.cross(y), a, b })
    }

    /// `new` with the rectangle's unit edges, normal and edge lengths
    /// computed once per emitter (`RectEmitter`) instead of once per sample.
    fn framed(o: Vec3, corner: Vec3, f: Frame) -> Option<SphericalRect> {
        let Frame { x, y, mut z, a, b } = f;
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
        let (omega, cos_t0, sin_t0) = angles(x0 as f64, x1 as f64, y0 as f64, y1 as f64, z0 as f64);
        let z2 = z0 * z0;
        let (ly0, ly1) = ((z2 + y0 * y0).sqrt(), (z2 + y1 * y1).sqrt());
        if !(omega >= MIN_SOLID_ANGLE) || !omega.is_finite() || !(ly0 > 0.0 && ly1 > 0.0) {
            return None;
        }
        Some(SphericalRect { o, x, y, z, x0, x1, y0, y1, z0, b0: -y0 / ly0, b1: y1 / ly1, cos_t0, sin_t0, omega })
    }

    /// The point for (u, v): uniform in solid angle as (u, v) is uniform.
    pub fn sample(&self, (u, v): (f32, f32)) -> Vec3 {
        // The direction's x: the sub-rectangle [x0, xu] subtends u·Ω. With
        // t = t0 + u·Ω, Ureña et al.'s f = cot-like (cos t·b0 + b1) / sin t
        // = N / D, cu = sign(f) / √(f² + b0²) and xu = −cu·z0 / √(1 − cu²)
        // simplify to xu = −sign(N)·D·z0 / √(N² + (b0² − 1)·D²): one square
        // root and one division where the paper's form chains three of each
        // (a dependency chain of long latencies, once per light sample).
        let (sin_s, cos_s) = (u * self.omega).sin_cos();
        let cos_t = self.cos_t0 * cos_s - self.sin_t0 * sin_s;
        let d = self.sin_t0 * cos_s + self.cos_t0 * sin_s;
        let n = cos_t * self.b0 + self.b1;
        let q = n * n + (self.b0 * self.b0 - 1.0) * d * d;
        let sd = n.signum() * d;
        let xu = if q > 0.0 {
            (-sd * self.z0 / q.sqrt()).clamp(self.x0, self.x1)
        } else if sd > 0.0 {
            self.x0 // |cu| = 1: the edge
        } else {
            self.x1
        };
        // Then y, uniform in the solid angle of the strip at xu: with
        // l² = xu² + z0², h = h0 + v·(h1 − h0) for h_j = y_j / √(l² + y_j²)
        // and yv = h·l / √(1 − h²).
        let l2 = xu * xu + self.z0 * self.z0;
        let h0 = self.y0 / (l2 + self.y0 * self.y0).sqrt();
        let h1 = self.y1 / (l2 + self.y1 * self.y1).sqrt();
        let h = h0 + v * (h1 - h0);
        let h2 = h * h;
        let yv = if h2 < 1.0 - 1e-6 { (h * (l2 / (1.0 - h2)).sqrt()).clamp(self.y0, self.y1) } else { self.y1 };
        self.o + self.x * xu + self.y * yv + self.z * self.z0
    }
}

/// Ω and (cos t0, sin t0) of the corners (x_i, y_j, z0). Corner (x, y) is
/// the complex number q + i·p = |z0|·R + i·x·y (R the corner's distance),
/// whose argument is A(x, y).
fn angles(x0: f64, x1: f64, y0: f64, y1: f64, z0: f64) -> (f32, f32, f32) {
    let (az, z2) = (z0.abs(), z0 * z0);
    let corner = |x: f64, y: f64| (az * (x * x + y * y + z2).sqrt(), x * y);
    let mul = |(a, b): (f64, f64), (p, q): (f64, f64)| (a * p - b * q, a * q + b * p);
    let conj = |(a, b): (f64, f64)| (a, -b);
    let (c00, c01, c10, c11) = (corner(x0, y0), corner(x0, y1), corner(x1, y0), corner(x1, y1));
    let (re, im) = mul(mul(c11, c00), conj(mul(c10, c01)));
    let mut omega = im.atan2(re);
    if omega < 0.0 {
        omega += 2.0 * std::f64::consts::PI; // Ω is in (0, 2π)
    }
    // t0 = A(x0,y1) − A(x0,y0): the argument of c01 · conj(c00).
    let (re, im) = mul(c01, conj(c00));
    let h = (re * re + im * im).sqrt();
    (omega as f32, (re / h) as f32, (im / h) as f32)
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
            let o = o.as_dvec3();
            let (a, b, c) = (a.as_dvec3() - o, b.as_dvec3() - o, c.as_dvec3() - o);
            let (la, lb, lc) = (a.length(), b.length(), c.length());
            let num = a.dot(b.cross(c));
            let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
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
            // Far (Ω ~ 1e-3 sr) and grazing (just above the plane, beside it):
            // Ω is a small difference of corner angles there.
            (Vec3::new(0.3, -20.0, 0.2), Vec3::ZERO, Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.5)),
            (Vec3::new(2.5, -0.02, 0.2), Vec3::ZERO, Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.5)),
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
    fn small_solid_angles_are_precise() {
        // Far, off-axis and grazing views down to just above MIN_SOLID_ANGLE:
        // Ω is a small difference of corner angles there, 1/Ω the pdf.
        for (o, corner) in [
            (Vec3::new(0.3, -40.0, 0.2), Vec3::ZERO),
            (Vec3::new(20.0, -15.0, -9.0), Vec3::ZERO),
            (Vec3::new(6.0, -0.05, 0.25), Vec3::ZERO),
            (Vec3::new(-12.0, -6.0, 15.0), Vec3::ZERO),
        ] {
            let (ex, ey) = (Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.5));
            let exact = omega_exact(o, corner, ex, ey);
            assert!((1.5e-4..2e-3).contains(&exact), "Ω {exact} from {o}");
            let r = SphericalRect::new(o, corner, ex, ey).unwrap();
            assert!((r.omega as f64 - exact).abs() < 1e-6 * exact, "Ω {} vs {exact} from {o}", r.omega);
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
    frame: Frame,
}

/// A rectangle's unit edges `x`, `y`, their normal `z = x × y` and the edge
/// lengths `a`, `b`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Frame {
    x: Vec3,
    y: Vec3,
    z: Vec3,
    a: f32,
    b: f32,
}

impl RectEmitter {
    /// `corner`, `ex`, `ey` as a rectangle, if the edges are orthogonal
    /// (to 1e-5 of their lengths' product).
    pub fn new(corner: Vec3, ex: Vec3, ey: Vec3, normal: Vec3) -> Option<RectEmitter> {
        let (a, b) = (ex.length(), ey.length());
        let scale = a * b;
        let (x, y) = (ex / a, ey / b);
        let frame = Frame { x, y, z: x.cross(y), a, b };
        (scale > 0.0 && scale.is_finite() && ex.dot(ey).abs() <= 1e-5 * scale).then_some(RectEmitter { corner, ex, ey, normal, frame })
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
        SphericalRect::framed(p, self.corner, self.frame)
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
