//! The primitive soup the native and brute backends test rays against.

use super::Hit;
use crate::geometry::{intersect_sphere, intersect_triangle, Aabb, RayTransform};
use crate::scene::Shape;
use glam::Vec3;
use rayon::prelude::*;

/// Sphere primitives are flagged in the top bit of `Prim::geom_id`.
const SPHERE_FLAG: u32 = 1 << 31;

/// One primitive, self-contained so a leaf touches one cache line per primitive.
/// Triangles store their three vertices; spheres store the centre in `v[0]`
/// and the radius in `v[1].x`.
#[derive(Clone, Copy, Debug)]
pub struct Prim {
    pub v: [Vec3; 3],
    geom_id: u32,
    pub prim_id: u32,
}

impl Prim {
    #[inline]
    pub fn geom_id(&self) -> u32 {
        self.geom_id & !SPHERE_FLAG
    }

    #[inline]
    pub fn is_sphere(&self) -> bool {
        self.geom_id & SPHERE_FLAG != 0
    }

    pub fn bounds(&self) -> Aabb {
        if self.is_sphere() {
            let r = Vec3::splat(self.v[1].x);
            Aabb { min: self.v[0] - r, max: self.v[0] + r }
        } else {
            let mut b = Aabb::from_point(self.v[0]);
            b.grow(self.v[1]);
            b.grow(self.v[2]);
            b
        }
    }

    /// `(t, u, v)` for a hit with `tmin < t <= tmax`.
    #[inline]
    pub fn intersect(&self, rt: &RayTransform, dir: Vec3, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        if self.is_sphere() {
            if self.v[1].x <= 0.0 {
                return None;
            }
            intersect_sphere(rt.origin, dir, self.v[0], self.v[1].x, tmin, tmax).map(|t| (t, 0.0, 0.0))
        } else {
            intersect_triangle(rt, self.v[0], self.v[1], self.v[2], tmin, tmax)
        }
    }

    #[inline]
    pub fn hit(&self, t: f32, u: f32, v: f32) -> Hit {
        Hit { t, u, v, geom_id: self.geom_id(), prim_id: self.prim_id }
    }
}

/// Every primitive of every shape, in shape order.
pub fn collect(shapes: &[Shape]) -> Vec<Prim> {
    let total = shapes.iter().map(|s| if let Shape::Mesh(m) = s { m.triangles.len() } else { 1 }).sum();
    let mut out = super::huge::vec_with_capacity(total);
    for (g, shape) in shapes.iter().enumerate() {
        let g = g as u32;
        match shape {
            Shape::Mesh(m) => {
                let tri = |(i, t): (usize, &[u32; 3])| Prim { v: [m.positions[t[0] as usize], m.positions[t[1] as usize], m.positions[t[2] as usize]], geom_id: g, prim_id: i as u32 };
                out.par_extend(m.triangles.par_iter().enumerate().map(tri));
            }
            Shape::Sphere { center, radius } => {
                out.push(Prim { v: [*center, Vec3::new(*radius, 0.0, 0.0), Vec3::ZERO], geom_id: g | SPHERE_FLAG, prim_id: 0 });
            }
        }
    }
    out
}

/// Keep `best` the closest hit, breaking exact ties towards the lower id.
#[inline]
pub fn closer(candidate: Hit, best: &Option<Hit>) -> bool {
    match best {
        None => true,
        Some(b) => candidate.t < b.t || (candidate.t == b.t && candidate.key() < b.key()),
    }
}
