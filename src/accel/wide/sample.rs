//! The tree's own sample of rays, from which the spatial-split decision
//! (`split_choice`) and the any-hit child order (`single::any_order_of`)
//! are counted rather than timed (so the same scene always gets the same
//! tree): points spread over the scene's triangles by area (as the points
//! a camera or a path reaches are), stratified in the scene's order of
//! triangles so that the sample does not depend on how the build lays the
//! tree out, leaving the side that
//! faces a point just under the top of the scene's box, where lights
//! usually are and where the benchmark's shadow rays go. Two kinds:
//!
//! * shadow-like rays from each point to that point (any hit);
//! * diffuse-like rays from each point in a cosine-distributed direction
//!   (closest hit; fixed seed), the rays a path tracer traces most.
//!
//! The work a ray costs is counted as the traversal counts it: nodes
//! visited plus triangle groups (and spheres) tested.

use super::stack::ChildOrder;
use super::prims::{triangle_area, PrimTable};
use super::{WideBvh, EMPTY};
use crate::ray::Ray;
use crate::rng::Rng;
use glam::Vec3;
use rayon::prelude::*;

/// Rays in a tree's sample: the ratio of two trees' work moved by under
/// 1 % between 512 and 4096 rays on every bench scene (`split_choice`).
pub(super) const SAMPLE_RAYS: usize = 4096;

/// Triangles per run of the cumulative area (`sample`).
const SAMPLE_CHUNK: usize = 128;

/// Where in a sampled triangle its rays start.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Within {
    /// Uniformly over the triangle (the spatial-split decision).
    Uniform,
    /// At its centroid (the any-hit child order: `single::any_order_of`).
    Centroid,
}

/// The two kinds of sampled rays, in the same order (ray `k` of each
/// starts at the same point).
pub(super) struct Sample {
    pub(super) shadow: Vec<Ray>,
    pub(super) diffuse: Vec<Ray>,
}

/// Mean work of a tree per sampled ray.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Work {
    /// Diffuse-like rays, closest hit.
    pub(super) closest: f64,
    /// Shadow-like rays, any hit, in the tree's chosen child order.
    pub(super) any: f64,
}

impl Work {
    /// One number for a path tracer's mix: one shadow ray per diffuse ray
    /// (next-event estimation at every bounce).
    pub(super) fn total(&self) -> f64 {
        self.closest + self.any
    }
}

impl<const W: usize> WideBvh<W> {
    /// `n` points over the triangles of `prims` (the scene the tree was
    /// built over), spread by area (stratified over the cumulative area in
    /// the scene's order; within a triangle as `at` says; fixed seed),
    /// and the two rays from each. Spread by area rather than weighted by
    /// it: weights as unequal as a Cornell box's two-triangle walls against
    /// its bunny's 28k triangles left the estimate to a few wall points
    /// (CBbunny's ratio of the two trees' work moved from 1.00 to 0.74
    /// between 512 and 4096 rays). Spheres are not sampled.
    pub(super) fn sample(&self, prims: &PrimTable, n: usize, at: Within) -> Sample {
        let mut s = Sample { shadow: Vec::with_capacity(n), diffuse: Vec::with_capacity(n) };
        if self.tree.root == EMPTY || prims.is_empty() || n == 0 {
            return s;
        }
        // The cumulative area over runs of triangles; a sample's triangle
        // is then found by walking its run, so a 10M-triangle scene needs
        // no array of 10M sums.
        let runs = prims.area_runs(SAMPLE_CHUNK);
        let cumulative: Vec<f64> = runs.iter().scan(0.0, |sum, r| {
            *sum += r.2;
            Some(*sum)
        }).collect();
        let total = *cumulative.last().unwrap_or(&0.0);
        if !(total > 0.0) {
            return s;
        }
        let pick = |target: f64| {
            let c = cumulative.partition_point(|&x| x <= target).min(cumulative.len() - 1);
            let mut left = target - if c > 0 { cumulative[c - 1] } else { 0.0 };
            let mut last = None;
            let (first, count, _) = runs[c];
            for i in first..first + count {
                let a = triangle_area(prims.get(i).v);
                if a > 0.0 {
                    if left < a {
                        return i;
                    }
                    left -= a;
                    last = Some(i);
                }
            }
            // Rounding left a sliver past the run's last triangle.
            last.expect("a run with area has a triangle")
        };
        let light = self.sample_light();
        let mut rng = Rng::new(0x5A_4D_91E, 0x7EE);
        for k in 0..n {
            let i = pick(total * (k as f64 + rng.uniform() as f64) / n as f64);
            let (u1, u2) = rng.uniform2();
            let (u3, u4) = rng.uniform2();
            let [a, b, c] = prims.get(i).v;
            let normal = (b - a).cross(c - a).normalize_or_zero();
            let (bu, bv) = match at {
                Within::Uniform => crate::sampling::uniform_triangle(u1, u2),
                Within::Centroid => (1.0 / 3.0, 1.0 / 3.0),
            };
            let p = a + (b - a) * bu + (c - a) * bv;
            if normal == Vec3::ZERO || !p.is_finite() {
                continue;
            }
            let (facing, shadow) = shadow_ray(p, normal, &[a, b, c], light);
            let diffuse = Ray::new(shadow.origin, crate::sampling::Frame::new(facing).to_world(crate::sampling::cosine_hemisphere(u3, u4)));
            if shadow.is_valid() && diffuse.is_valid() {
                s.shadow.push(shadow);
                s.diffuse.push(diffuse);
            }
        }
        s
    }

    /// Where the sampled shadow rays go: just under the middle of the top
    /// of the scene's box, where lights usually are.
    pub(super) fn sample_light(&self) -> Vec3 {
        let b = self.tree.bounds;
        Vec3::new(b.center().x, b.max.y - 0.02 * b.extent().y, b.center().z)
    }

    /// Mean work of any-hit rays in `order`.
    pub(super) fn any_work(&self, rays: &[Ray], order: ChildOrder) -> f64 {
        mean(rays, |r| {
            let mut work = 0;
            self.any_counted::<false>(r, order, &mut work);
            work
        })
    }

    /// Mean work of closest-hit rays: the nodes and four-triangle leaf
    /// groups one query visits (public for profiles that set it beside
    /// another tree's, `examples/trace_rays`).
    pub fn closest_work(&self, rays: &[Ray]) -> f64 {
        mean(rays, |r| {
            let mut work = 0;
            self.closest_counted::<false>(r, &mut work);
            work
        })
    }

    /// The tree's work on `sample` with its policy's any-hit order.
    pub(super) fn work(&self, sample: &Sample) -> Work {
        Work { closest: self.closest_work(&sample.diffuse), any: self.any_work(&sample.shadow, self.policy.any_order) }
    }
}

/// The shadow-like ray from point `p` of a triangle with `corners` and unit
/// normal `n` to `light`, leaving the side that faces it, and that side's
/// normal.
pub(super) fn shadow_ray(p: Vec3, n: Vec3, corners: &[Vec3; 3], light: Vec3) -> (Vec3, Ray) {
    let n = if n.dot(light - p) < 0.0 { -n } else { n };
    let o = crate::sampling::offset_ray_origin(p, n, crate::sampling::magnitude(corners));
    (n, Ray::with_range(o, light - o, 0.0, 1.0 - 1e-4))
}

/// Mean of `work` over `rays`, traced in parallel: the sample runs inside
/// every default build that is given a ray count. Integer sums, so the
/// mean is the same at any thread count.
fn mean(rays: &[Ray], work: impl Fn(&Ray) -> u32 + Sync) -> f64 {
    if rays.is_empty() {
        return 0.0;
    }
    rays.par_iter().map(|r| work(r) as u64).sum::<u64>() as f64 / rays.len() as f64
}
