//! Ray/sphere intersection without catastrophic cancellation.
//!
//! The textbook `b^2 - 4ac` loses all precision when the sphere is small
//! compared to its distance from the ray origin. We use the form of
//! Haines et al. (Ray Tracing Gems, ch. 7): the discriminant is computed from
//! the vector between the centre and the closest point of the line, and the
//! two roots from `q = -(b + sign(b) sqrt(D))` so neither root subtracts two
//! nearly equal numbers. Evaluated in f64: spheres are few, precision is cheap.

use glam::{DVec3, Vec3};

/// Nearest `t` with `tmin < t <= tmax`, if any. Hits from inside count
/// (the far root), so the sphere behaves as a closed two-sided surface.
#[inline]
pub fn intersect_sphere(origin: Vec3, dir: Vec3, center: Vec3, radius: f32, tmin: f32, tmax: f32) -> Option<f32> {
    let f = origin.as_dvec3() - center.as_dvec3();
    let d: DVec3 = dir.as_dvec3();
    let r = radius as f64;
    let a = d.dot(d);
    let b = f.dot(d); // half of the usual b
    let l = f - d * (b / a); // centre -> closest point on the line
    let disc = a * (r * r - l.dot(l));
    if disc < 0.0 {
        return None;
    }
    let c = f.dot(f) - r * r;
    let q = -(b + b.signum() * disc.sqrt());
    let (mut t0, mut t1) = if q == 0.0 { (0.0, 0.0) } else { (c / q, q / a) };
    if t0 > t1 {
        std::mem::swap(&mut t0, &mut t1);
    }
    for t in [t0, t1] {
        let t = t as f32;
        if t > tmin && t <= tmax {
            return Some(t);
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hits_near_and_far_roots() {
        let t = intersect_sphere(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z, Vec3::ZERO, 1.0, 0.0, f32::INFINITY);
        assert_eq!(t, Some(4.0));
        let t = intersect_sphere(Vec3::ZERO, -Vec3::Z, Vec3::ZERO, 1.0, 0.0, f32::INFINITY);
        assert_eq!(t, Some(1.0));
        assert!(intersect_sphere(Vec3::new(0.0, 2.0, 5.0), -Vec3::Z, Vec3::ZERO, 1.0, 0.0, f32::INFINITY).is_none());
    }

    #[test]
    fn distant_small_sphere_is_precise() {
        // The naive quadratic in f32 loses every digit here.
        let c = Vec3::new(0.0, 0.0, -1.0e5);
        let t = intersect_sphere(Vec3::ZERO, -Vec3::Z, c, 0.01, 0.0, f32::INFINITY).unwrap();
        assert_eq!(t, 1.0e5 - 0.01);
    }
}
