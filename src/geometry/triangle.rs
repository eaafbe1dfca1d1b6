//! Watertight ray/triangle intersection (Woop, Benthin, Wald, JCGT 2013).
//!
//! The ray is sheared so that it points down +z from the origin; the triangle
//! is then tested in 2D with edge functions. Adjacent triangles evaluate the
//! same edge function with the same operands, so a ray through a shared edge
//! or vertex hits at least one of them: no cracks. An edge function that is
//! exactly zero in f32 is recomputed in f64 so its sign is decided exactly.

use glam::Vec3;

/// Per-ray shear constants, computed once per ray and reused for every triangle.
#[derive(Clone, Copy, Debug)]
pub struct RayTransform {
    pub origin: Vec3,
    kx: usize,
    ky: usize,
    kz: usize,
    sx: f32,
    sy: f32,
    sz: f32,
}

impl RayTransform {
    /// `dir` must be finite and non-zero (see `Ray::is_valid`).
    #[inline]
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        let a = dir.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        // Indexed as an array: indexing a `Vec3` by a run-time axis (or
        // picking with selects, which compiles the same) gives branches that
        // random rays mispredict: 1 thread, random rays, Mrays/s, cow 10.1 ->
        // 11.3, CBbunny 12.1 -> 13.3, 1M sphere 3.42 -> 3.59 (camera rays
        // within 2 %).
        let d = dir.to_array();
        // Keep the winding of the sheared triangle independent of the sign of dir[kz].
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        // The three quotients in one SIMD division (each lane rounds exactly
        // as the scalar division would): ray setup is a measurable share of
        // a coherent ray's cost.
        let s = glam::Vec3A::new(d[kx], d[ky], 1.0) / glam::Vec3A::splat(d[kz]);
        RayTransform { origin, kx, ky, kz, sx: s.x, sy: s.y, sz: s.z }
    }
}

impl RayTransform {
    /// A transform whose axes `[kx, ky, kz]` and quotients `[sx, sy, sz]`
    /// were computed as `new` computes them (the packet set-up does it for
    /// 16 rays at once).
    pub(crate) fn from_shear(origin: Vec3, k: [usize; 3], s: [f32; 3]) -> Self {
        RayTransform { origin, kx: k[0], ky: k[1], kz: k[2], sx: s[0], sy: s[1], sz: s[2] }
    }

    /// The shear as `([kx, ky, kz], [sx, sy, sz])`, for SIMD versions of the
    /// test that must compute exactly what `intersect_triangle` does.
    pub fn shear(&self) -> ([usize; 3], [f32; 3]) {
        ([self.kx, self.ky, self.kz], [self.sx, self.sy, self.sz])
    }
}

/// Returns `(t, u, v)` for a hit with `tmin < t <= tmax`, where `u` and `v`
/// are the barycentric weights of `p1` and `p2` (so the hit point is
/// `(1-u-v) p0 + u p1 + v p2`). Triangles are two-sided. A degenerate
/// (zero-area, as seen along the ray) triangle is never hit, and a ray lying
/// in the triangle's plane misses it.
#[inline]
pub fn intersect_triangle(
    rt: &RayTransform,
    p0: Vec3,
    p1: Vec3,
    p2: Vec3,
    tmin: f32,
    tmax: f32,
) -> Option<(f32, f32, f32)> {
    let (kx, ky, kz) = (rt.kx, rt.ky, rt.kz);
    // Arrays, not `Vec3`s: a `Vec3` indexed by a run-time axis compiles to
    // branches, which rays of varying direction mispredict.
    let a = (p0 - rt.origin).to_array();
    let b = (p1 - rt.origin).to_array();
    let c = (p2 - rt.origin).to_array();
    let ax = a[kx] - rt.sx * a[kz];
    let ay = a[ky] - rt.sy * a[kz];
    let bx = b[kx] - rt.sx * b[kz];
    let by = b[ky] - rt.sy * b[kz];
    let cx = c[kx] - rt.sx * c[kz];
    let cy = c[ky] - rt.sy * c[kz];

    // Each edge function depends only on its edge (negated when the
    // neighbour walks the edge the other way), so adjacent triangles agree on
    // the sign. An exact zero is ambiguous: only that edge function is redone
    // in f64 (products of floats are exact there), which keeps the agreement;
    // redoing all three would not.
    let edge = |px: f32, py: f32, qx: f32, qy: f32| -> f32 {
        let e = qx * py - qy * px;
        if e != 0.0 {
            return e;
        }
        let e64 = qx as f64 * py as f64 - qy as f64 * px as f64;
        // Keep the sign even where the f64 value is below f32's range.
        if e64 == 0.0 { 0.0 } else { (e64 as f32).abs().max(f32::MIN_POSITIVE).copysign(e64 as f32) }
    };
    let e0 = edge(bx, by, cx, cy); // B->C: weight of p0
    let e1 = edge(cx, cy, ax, ay); // C->A: weight of p1
    let e2 = edge(ax, ay, bx, by); // A->B: weight of p2
    if (e0 < 0.0 || e1 < 0.0 || e2 < 0.0) && (e0 > 0.0 || e1 > 0.0 || e2 > 0.0) {
        return None;
    }
    let det = e0 + e1 + e2;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let az = rt.sz * a[kz];
    let bz = rt.sz * b[kz];
    let cz = rt.sz * c[kz];
    let t_scaled = e0 * az + e1 * bz + e2 * cz;
    // Hits behind the origin (t <= 0) are rejected before the division; valid
    // rays have tmin >= 0, so this never rejects a hit the exact test keeps.
    if (det > 0.0 && t_scaled <= 0.0) || (det < 0.0 && t_scaled >= 0.0) {
        return None;
    }
    let inv = 1.0 / det;
    let t = t_scaled * inv;
    if !(t > tmin && t <= tmax) {
        return None;
    }
    Some((t, e1 * inv, e2 * inv))
}

/// The unit normal of triangle `abc` (right-handed, a→b→c), or zero when
/// it is degenerate. Computed in f64: the f32 cross product of the edges and
/// its squared length overflow from coordinates near 1e9 and underflow near
/// 1e-10 (a scaled copy of a mesh rendered black: zero normals), while f64
/// carries any f32 input.
pub fn face_normal(a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    edge_cross(a, b, c).normalize_or_zero().as_vec3()
}

/// The area of triangle `abc`, computed in f64 (see `face_normal`).
pub fn area(a: Vec3, b: Vec3, c: Vec3) -> f32 {
    (0.5 * edge_cross(a, b, c).length()) as f32
}

/// The point with barycentrics `(u, v)` (weights of `b` and `c`) on triangle
/// `abc`, interpolated from `a` along the edges: where the vertices share a
/// coordinate (an axis-aligned wall or light) it comes out exact, and
/// elsewhere the error scales with the edges, not with the coordinates. As
/// a·w + b·u + c·v it was ~3.5 ulps of the largest coordinate (pbrt's bound),
/// and rays spawned at such hits re-hit their own triangle from 1 ulp off
/// (`sampling::OFFSET_ULPS`).
pub fn point_at(a: Vec3, b: Vec3, c: Vec3, u: f32, v: f32) -> Vec3 {
    a + (b - a) * u + (c - a) * v
}

/// (b − a) × (c − a) in f64.
pub fn edge_cross(a: Vec3, b: Vec3, c: Vec3) -> glam::DVec3 {
    let a = a.as_dvec3();
    (b.as_dvec3() - a).cross(c.as_dvec3() - a)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hit(o: Vec3, d: Vec3, p: [Vec3; 3]) -> Option<(f32, f32, f32)> {
        intersect_triangle(&RayTransform::new(o, d), p[0], p[1], p[2], 0.0, f32::INFINITY)
    }

    const TRI: [Vec3; 3] = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)];

    #[test]
    fn barycentrics_weight_p1_and_p2() {
        let (t, u, v) = hit(Vec3::new(0.25, 0.5, 2.0), Vec3::new(0.0, 0.0, -1.0), TRI).unwrap();
        assert_eq!(t, 2.0);
        assert!((u - 0.25).abs() < 1e-7 && (v - 0.5).abs() < 1e-7, "{u} {v}");
    }

    #[test]
    fn two_sided() {
        assert!(hit(Vec3::new(0.2, 0.2, -1.0), Vec3::Z, TRI).is_some());
        assert!(hit(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, TRI).is_some());
    }

    #[test]
    fn range_is_half_open() {
        let rt = RayTransform::new(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z);
        // t == tmax is a hit, t == tmin is not.
        assert!(intersect_triangle(&rt, TRI[0], TRI[1], TRI[2], 0.0, 1.0).is_some());
        assert!(intersect_triangle(&rt, TRI[0], TRI[1], TRI[2], 1.0, 2.0).is_none());
        assert!(intersect_triangle(&rt, TRI[0], TRI[1], TRI[2], 0.0, 0.999).is_none());
    }

    #[test]
    fn degenerate_and_in_plane_miss() {
        let line = [Vec3::ZERO, Vec3::X, Vec3::X * 2.0];
        assert!(hit(Vec3::new(1.0, 0.0, 1.0), -Vec3::Z, line).is_none());
        let point = [Vec3::ONE; 3];
        assert!(hit(Vec3::new(1.0, 1.0, 2.0), -Vec3::Z, point).is_none());
        // A ray travelling inside the triangle's plane.
        assert!(hit(Vec3::new(-1.0, 0.2, 0.0), Vec3::X, TRI).is_none());
    }
}
