//! Rays, the validity rule every backend applies to them, and what a
//! backend finds along one (`Hit`).

use glam::Vec3;

/// A ray `origin + t * dir`, restricted to the half-open range `tmin < t <= tmax`.
///
/// `dir` need not be normalised; `t` is then measured in units of `dir`.
///
/// `repr(C)`: the packet traversals load 8 rays as 8 rows of 8 floats
/// (origin, direction, tmin, tmax) and transpose them.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    pub tmin: f32,
    pub tmax: f32,
}

const _: () = assert!(std::mem::size_of::<Ray>() == 32);

impl Ray {
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Ray { origin, dir, tmin: 0.0, tmax: f32::INFINITY }
    }

    pub fn with_range(origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Self {
        Ray { origin, dir, tmin, tmax }
    }

    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }

    /// A ray every backend traces. Anything else (NaN or infinite origin or
    /// direction, a zero direction, a NaN or negative `tmin`, NaN `tmax`,
    /// `tmax < tmin`) hits nothing and is occluded by nothing, in every backend.
    /// Embree's behaviour on such rays is undefined, so the check is ours.
    #[inline]
    pub fn is_valid(&self) -> bool {
        self.origin.is_finite()
            && self.dir.is_finite()
            && self.dir != Vec3::ZERO
            && self.tmin >= 0.0
            && !self.tmax.is_nan()
            && self.tmin <= self.tmax
    }
}

/// What a backend knows about a hit. Geometry ids number the scene's shapes in
/// order (`Scene::shapes`); the primitive id is the triangle index inside its
/// mesh (0 for a sphere). `u`, `v` are the barycentric weights of the
/// triangle's second and third vertices (0 for spheres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub u: f32,
    pub v: f32,
    pub geom_id: u32,
    pub prim_id: u32,
}

impl Hit {
    /// The order used to break exact ties in `t`: lower (geometry, primitive) wins.
    #[inline]
    pub fn key(&self) -> u64 {
        ((self.geom_id as u64) << 32) | self.prim_id as u64
    }
}
