//! obvhs (crates.io), timed by `pathtracer bench` as a peer on the same rays
//! as our backends; built only with `--features peers`. Not a renderer
//! backend: it answers `Traversal`'s queries so the benchmark can time it
//! exactly as it times ours, but its hits carry no barycentrics (u = v = 0)
//! and it has no spheres.
//!
//! Configuration, as its author uses it in his own comparison (tray_racing):
//! the compressed 8-wide BVH (`CwBvh`, PLOC build + reinsertion,
//! `BvhBuildParams::medium_build`, "around the same build time as Embree
//! but with faster traversal"), triangles reordered into leaf order, its own
//! Möller–Trumbore test (`Triangle::intersect`), closest hit with
//! `ray_traverse`, shadow rays with `ray_traverse_miss` (stops at the first
//! hit). Our `(tmin, tmax]` range is applied around its closed one.

use super::{Hit, Traversal};
use crate::error::Result;
use crate::ray::Ray;
use crate::scene::Shape;
use obvhs::cwbvh::{builder::build_cwbvh_from_tris, CwBvh};
use obvhs::ray::{Ray as ORay, RayHit};
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;
use obvhs_glam::Vec3A;

pub struct ObvhsPeer {
    bvh: CwBvh,
    /// Triangles in the BVH's primitive order, and their (geometry, primitive) ids.
    tris: Vec<Triangle>,
    ids: Vec<(u32, u32)>,
}

fn v3(p: glam::Vec3) -> Vec3A {
    Vec3A::new(p.x, p.y, p.z)
}

impl ObvhsPeer {
    pub fn build(shapes: &[Shape]) -> Result<Self> {
        let mut tris = Vec::new();
        let mut ids = Vec::new();
        for (g, s) in shapes.iter().enumerate() {
            match s {
                Shape::Mesh(m) => {
                    for (i, t) in m.triangles.iter().enumerate() {
                        let [a, b, c] = t.map(|k| v3(m.positions[k as usize]));
                        tris.push(Triangle { v0: a, v1: b, v2: c });
                        ids.push((g as u32, i as u32));
                    }
                }
                Shape::Sphere { .. } => crate::bail!("obvhs peer: spheres are not supported (triangle meshes only)"),
            }
        }
        if tris.is_empty() {
            crate::bail!("obvhs peer: no triangles");
        }
        let bvh = build_cwbvh_from_tris(&tris, BvhBuildParams::medium_build(), &mut std::time::Duration::default());
        // Leaf order, as tray_racing does: the traversal's primitive index
        // then addresses the triangle directly.
        let tris = bvh.primitive_indices.iter().map(|&i| tris[i as usize]).collect();
        let ids = bvh.primitive_indices.iter().map(|&i| ids[i as usize]).collect();
        Ok(ObvhsPeer { bvh, tris, ids })
    }

    fn oray(r: &Ray) -> ORay {
        ORay::new(v3(r.origin), v3(r.dir), r.tmin, r.tmax)
    }

    /// Triangle `id`'s hit distance along `r` within our `(tmin, ...)`
    /// range (obvhs's own range is closed, so it keeps a hit at `tmin`),
    /// infinity for none.
    #[inline(always)]
    fn hit_t(&self, r: &ORay, id: usize, tmin: f32) -> f32 {
        let t = self.tris[id].intersect(r);
        if t > tmin { t } else { f32::INFINITY }
    }

    /// The node tests and triangle tests of one closest-hit query, counted
    /// on obvhs's own walk (its `traverse!`, run as `ray_traverse` runs
    /// it): for profiles that set its work per ray beside native's
    /// (`examples/trace_rays`).
    pub fn closest_work(&self, ray: &Ray) -> (u32, u32) {
        use obvhs_glam::UVec2;
        if !ray.is_valid() {
            return (0, 0);
        }
        let mut r = Self::oray(ray);
        let (mut nodes, mut tests) = (0u32, 0u32);
        let mut state = self.bvh.new_traversal(r.direction);
        let mut node;
        obvhs::traverse!(
            self.bvh,
            node,
            state,
            {
                nodes += 1;
                node.intersect_ray(&r, state.oct_inv4)
            },
            {
                tests += 1;
                let t = self.hit_t(&r, state.primitive_id as usize, ray.tmin);
                if t < r.tmax {
                    r.tmax = t;
                }
            }
        );
        (nodes, tests)
    }
}

impl Traversal for ObvhsPeer {
    fn name(&self) -> &'static str {
        "obvhs"
    }

    fn describe(&self) -> String {
        format!("obvhs 0.4 (CwBvh, medium_build, {} nodes)", self.bvh.nodes.len())
    }

    fn memory_bytes(&self) -> usize {
        self.bvh.nodes.len() * std::mem::size_of_val(&self.bvh.nodes[0])
            + self.bvh.primitive_indices.len() * 4
            + self.tris.len() * std::mem::size_of::<Triangle>()
            + self.ids.len() * 8
    }

    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        let mut hit = RayHit::none();
        let found = self.bvh.ray_traverse(Self::oray(ray), &mut hit, |r, id| self.hit_t(r, id, ray.tmin));
        found.then(|| {
            let (geom_id, prim_id) = self.ids[hit.primitive_id as usize];
            Hit { t: hit.t, u: 0.0, v: 0.0, geom_id, prim_id }
        })
    }

    fn occluded(&self, ray: &Ray) -> bool {
        if !ray.is_valid() {
            return false;
        }
        !self.bvh.ray_traverse_miss(Self::oray(ray), |r, id| self.hit_t(r, id, ray.tmin))
    }
}
