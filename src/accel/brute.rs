//! The oracle: every ray against every primitive, no acceleration structure.

use super::prims::{self, closer, Prim};
use super::{Hit, Traversal};
use crate::geometry::RayTransform;
use crate::ray::Ray;
use crate::scene::Shape;

pub struct BruteForce {
    prims: Vec<Prim>,
}

impl BruteForce {
    pub fn new(shapes: &[Shape]) -> Self {
        BruteForce { prims: prims::collect(shapes) }
    }
}

impl Traversal for BruteForce {
    fn name(&self) -> &'static str {
        "brute"
    }

    fn describe(&self) -> String {
        "brute (no acceleration)".into()
    }

    fn exact_barycentrics(&self) -> bool {
        true
    }

    fn memory_bytes(&self) -> usize {
        self.prims.len() * std::mem::size_of::<Prim>()
    }

    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        let rt = RayTransform::new(ray.origin, ray.dir);
        let mut best: Option<Hit> = None;
        let mut tmax = ray.tmax;
        for p in &self.prims {
            if let Some((t, u, v)) = p.intersect(&rt, ray.dir, ray.tmin, tmax) {
                let h = p.hit(t, u, v);
                if closer(h, &best) {
                    tmax = t;
                    best = Some(h);
                }
            }
        }
        best
    }

    fn occluded(&self, ray: &Ray) -> bool {
        if !ray.is_valid() {
            return false;
        }
        let rt = RayTransform::new(ray.origin, ray.dir);
        self.prims.iter().any(|p| p.intersect(&rt, ray.dir, ray.tmin, ray.tmax).is_some())
    }
}
