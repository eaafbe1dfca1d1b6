//! Warps from the unit square to directions and points, with their pdfs.

use glam::Vec3;
use std::f32::consts::PI;

/// Uniform on the hemisphere around +z: cos(theta) = u1. pdf 1/(2 pi).
pub fn uniform_hemisphere(u1: f32, u2: f32) -> Vec3 {
    let z = u1;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u2;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

pub const UNIFORM_HEMISPHERE_PDF: f32 = 1.0 / (2.0 * PI);

/// Concentric map of the unit square onto the unit disk (Shirley–Chiu).
pub fn concentric_disk(u: (f32, f32)) -> (f32, f32) {
    let (a, b) = (2.0 * u.0 - 1.0, 2.0 * u.1 - 1.0);
    if a == 0.0 && b == 0.0 {
        return (0.0, 0.0);
    }
    let (r, phi) = if a.abs() > b.abs() { (a, PI / 4.0 * (b / a)) } else { (b, PI / 2.0 - PI / 4.0 * (a / b)) };
    (r * phi.cos(), r * phi.sin())
}


/// Cosine-weighted on the hemisphere around +z (Malley). pdf cos(theta)/pi.
pub fn cosine_hemisphere(u1: f32, u2: f32) -> Vec3 {
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    Vec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u1).max(0.0).sqrt())
}

pub fn cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    if cos_theta > 0.0 {
        cos_theta / PI
    } else {
        0.0
    }
}

/// Uniform on a triangle: barycentric weights (of p1, p2).
pub fn uniform_triangle(u1: f32, u2: f32) -> (f32, f32) {
    let s = u1.sqrt();
    (s * (1.0 - u2), s * u2)
}

/// Uniform on the unit sphere.
pub fn uniform_sphere(u1: f32, u2: f32) -> Vec3 {
    let z = 1.0 - 2.0 * u1;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u2;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// An orthonormal frame with `n` as its z axis (Duff et al. 2017).
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    pub s: Vec3,
    pub t: Vec3,
    pub n: Vec3,
}

impl Frame {
    pub fn new(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Frame { s, t, n }
    }

    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }

    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }
}

/// How far, in ulps, a spawned ray starts off its surface (its height above
/// the surface's tangent plane). Stepped along the normal, as it once was,
/// the step moved the whole ray sideways, so shadow edges cast by nearby
/// objects moved with it: the validation harness's scene moved by 8192
/// (where an ulp is 1 mm in a 2 m box) read brighter than the same scene
/// scaled by 1e-3, whose steps are negligible, by +0.40 % at 32 ulps,
/// +0.05 % at 8, and linearly below that, +0.0124 % per ulp (256x192, 8
/// seeds x 128 spp: −0.034 / −0.022 / −0.010 / +0.003 % at 1 / 2 / 3 / 4
/// ulps, −0.047 % extrapolated to 0, where Mitsuba and Cycles read −0.045 %
/// and −0.051 % for the moved-back scene). Hence `spawn_origin`, which
/// climbs the step along the ray's own line where that is safe: the moved
/// scene then read +0.013 % ± 0.007 % against Cycles (256x192, 1024 spp,
/// z +1.95; +0.061 %, z +9.4, before). The floor is self-intersection (tests/self_intersection.rs):
/// spawned rays never re-hit their own primitive from 1 ulp (hit points are
/// interpolated along the triangle's edges, `scene::interaction`; from the
/// vertices as a·w + b·u + c·v, 109 of 40781 did at 1 ulp), but long
/// shadow segments leaving a huge tilted quad are blocked up to 1.5 ulps
/// (2 of 20000) and not from 1.75. 4 keeps a factor of two over both, for
/// pbrt's bound on the hit point's error is about 3.5 ulps. Hits rounded
/// past an edge, which no step off the surface fixes, are handled in
/// `scene::interaction`.
pub const OFFSET_ULPS: f32 = 4.0;

/// Move `p` off its surface along the unit geometric normal `n` (on the side
/// the new ray leaves to) by `OFFSET_ULPS` ulps of `magnitude`, the largest
/// coordinate magnitude of the primitive `p` lies on.
///
/// This is Wächter and Binder's integer-ulp offset (Ray Tracing Gems ch. 6)
/// with one change: they count ulps of `p` itself and switch to a fixed
/// 1/65536 step near the origin, which is far too large for a millimetre-sized
/// scene and too small for a huge triangle passing near the origin. Both the
/// error of our hit point (interpolated from the vertices) and the error of
/// re-intersecting the same primitive scale with the primitive's coordinates,
/// so we count ulps of those. No scene-dependent epsilon either way.
pub fn offset_ray_origin(p: Vec3, n: Vec3, magnitude: f32) -> Vec3 {
    // Where a component of n is tiny its part of the step may round away;
    // the step along n itself is what keeps the ray off the surface.
    p + n * (OFFSET_ULPS * ulp(magnitude.max(p.abs().max_element())))
}

/// How far along itself a spawned ray may go to climb its step, in steps:
/// a ray leaving at least 30° off the surface (n·d ≥ 1/2) climbs all of it
/// on its own line; a more grazing one goes 2 steps along itself and climbs
/// the rest along the normal.
const ALONG_STEPS: f32 = 2.0;

/// Where a ray leaving `p` along `d` starts: `OFFSET_ULPS` ulps of
/// `magnitude` (as `offset_ray_origin`) above the surface's tangent plane,
/// on the side of the unit geometric normal `n` that `d` leaves to. Where
/// the point lies farther than that move (and a step) from its
/// primitive's edges (`room`, within its plane), the height is climbed
/// along the ray's own line through `p` (`ALONG_STEPS`): on that line the
/// ray meets what the exact ray from `p` meets beyond the step, so shadow
/// edges and contact shadows stay where they are, where a step along the
/// normal moves the ray sideways by the step, and every shadow edge on the
/// surface with it (see `OFFSET_ULPS`). Nearer an edge, where another
/// surface may meet this one at a corner, it steps along the normal, which
/// runs parallel to such a wall and never crosses it; so does a `d` that
/// does not leave to `n`'s side, and a `room` of 0.
pub fn spawn_origin(p: Vec3, n: Vec3, d: Vec3, magnitude: f32, room: f32) -> Vec3 {
    let step = OFFSET_ULPS * ulp(magnitude.max(p.abs().max_element()));
    let normal_step = p + n * step;
    let d = d.normalize_or_zero();
    let c = n.dot(d);
    if !(c > 0.0) {
        return normal_step;
    }
    let along = (step / c).min(ALONG_STEPS * step);
    // How far the move along the ray goes within the surface's plane.
    let sideways = along * (1.0 - c * c).max(0.0).sqrt();
    if !(sideways + step <= room) {
        return normal_step;
    }
    // What the ray's own climb leaves to the normal: 0 from 30° off the
    // surface (rounding aside).
    let rest = (step - along * c).max(0.0);
    p + d * along + n * rest
}

/// The spacing of f32 values at `|x|` (at least the smallest normal's).
pub fn ulp(x: f32) -> f32 {
    let x = x.abs().max(f32::MIN_POSITIVE);
    f32::from_bits(x.to_bits() + 1) - x
}

/// The largest coordinate magnitude of a set of points.
pub fn magnitude(points: &[Vec3]) -> f32 {
    points.iter().fold(0.0f32, |m, p| m.max(p.abs().max_element()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_is_orthonormal() {
        for n in [Vec3::Z, -Vec3::Z, Vec3::X, Vec3::new(0.3, -0.5, 0.8).normalize(), Vec3::new(0.0, 0.0, -1.0)] {
            let f = Frame::new(n);
            assert!((f.s.length() - 1.0).abs() < 1e-6 && (f.t.length() - 1.0).abs() < 1e-6);
            assert!(f.s.dot(f.t).abs() < 1e-6 && f.s.dot(n).abs() < 1e-6 && f.t.dot(n).abs() < 1e-6);
            let v = Vec3::new(0.2, 0.3, 0.9);
            assert!((f.to_local(f.to_world(v)) - v).length() < 1e-6);
        }
    }

    /// The origin is a step above the tangent plane, on the ray's line
    /// through `p` for rays 30° or more off the surface, and for grazing
    /// rays at most `ALONG_STEPS` steps along the ray.
    #[test]
    fn spawned_origins_climb_the_step_on_the_ray_line() {
        let p = Vec3::new(8192.3, 8191.7, 8193.1);
        let n = Vec3::Y;
        let step = OFFSET_ULPS * ulp(p.abs().max_element());
        for (d, on_line) in [(Vec3::Y, true), (Vec3::new(1.0, 1.0, 0.0), true), (Vec3::new(1.0, 0.6, 0.3), true), (Vec3::new(1.0, 0.2, 0.0), false), (Vec3::new(0.0, 1e-4, 1.0), false)] {
            let d = d.normalize();
            let o = spawn_origin(p, n, d, 0.0, f32::INFINITY);
            let rel = (o - p).as_dvec3();
            let height = rel.y;
            assert!(height >= 0.5 * step as f64 && height <= 1.5 * step as f64, "{d}: height {height}, step {step}");
            let along = rel.dot(d.as_dvec3());
            assert!(along <= (ALONG_STEPS * step) as f64 * 1.5, "{d}: {along} along the ray");
            let off_line = (rel - d.as_dvec3() * along).length();
            if on_line {
                // Only the rounding of o's coordinates (half an ulp each).
                assert!(off_line <= 1.5 * ulp(8193.1) as f64, "{d}: {off_line} off the ray's line");
            } else {
                assert!(off_line > 0.1 * step as f64, "{d}: a grazing ray climbs partly along the normal");
            }
        }
        // A direction that does not leave to n's side: the normal step.
        assert_eq!(spawn_origin(p, n, -Vec3::Y, 0.0, f32::INFINITY), p + n * step);
        // Within the move (and a step) of an edge, or with no room known:
        // the normal step.
        let d = Vec3::new(1.0, 1.0, 0.0).normalize();
        assert_eq!(spawn_origin(p, n, d, 0.0, 1.5 * step), p + n * step);
        assert_eq!(spawn_origin(p, n, d, 0.0, 0.0), p + n * step);
    }

    #[test]
    fn offset_moves_to_the_normal_side_by_ulps_of_the_primitive() {
        for p in [Vec3::new(1e5, -3.0, 0.01), Vec3::new(-2.0, 7.5e3, -1e-4), Vec3::new(1e-3, 2e-3, 0.0)] {
            let n = Vec3::new(0.0, 0.0, 1.0);
            let m = p.abs().max_element();
            let q = offset_ray_origin(p, n, m);
            assert!(q.z > p.z && q.x == p.x && q.y == p.y, "{p} -> {q}");
            // OFFSET_ULPS ulps of the magnitude, give or take rounding of the sum.
            let u = ulp(m);
            assert!((q.z - p.z) >= 0.5 * OFFSET_ULPS * u && (q.z - p.z) <= 2.0 * OFFSET_ULPS * u, "{p}: moved {}", q.z - p.z);
            let q = offset_ray_origin(p, -n, m);
            assert!(q.z < p.z);
        }
    }
}
