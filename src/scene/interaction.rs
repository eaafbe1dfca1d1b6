//! "Describe the hit": everything shading needs, computed from a backend's
//! `Hit` by code shared by all backends.

use super::{MeshFetch, Scene, Shape};
use crate::ray::Hit;
use crate::geometry::{intersect_triangle, RayTransform};
use crate::sampling::{magnitude, spawn_origin, ulp};
use crate::ray::Ray;
use glam::Vec3;

#[derive(Clone, Copy, Debug)]
pub struct Interaction {
    /// Hit point, from the barycentrics (triangles) or projected onto the
    /// sphere, which is more accurate than `origin + t*dir` far from the origin.
    pub p: Vec3,
    /// Unit geometric normal, as wound (triangles) or outward (spheres);
    /// not flipped towards the ray.
    pub ng: Vec3,
    /// Unit shading normal: interpolated vertex normals, or `ng`.
    pub ns: Vec3,
    pub t: f32,
    /// Largest coordinate magnitude of the primitive hit: the scale of the
    /// hit point's rounding error, which spawned rays step over.
    pub magnitude: f32,
    /// The distance from `p` to its primitive's nearest edge, within its
    /// plane (infinite on a sphere, 0 where unknown): how far a spawned ray
    /// may move along itself before it could pass an edge where another
    /// surface meets this one (`sampling::spawn_origin`).
    pub edge_room: f32,
    /// The side of `ng` the ray that found this point came from: +1 in
    /// front, −1 behind, 0 unknown. A spawned ray leaving to that side
    /// reflects; one leaving to the other side is transmitted.
    pub incoming_side: f32,
    pub geom_id: u32,
    pub prim_id: u32,
}

/// The fraction of a shadow segment left out at its target end (pbrt-v4's
/// `ShadowEpsilon`).
pub const SHADOW_EPSILON: f32 = 1e-4;

impl Interaction {
    pub fn new(scene: &Scene, ray: &Ray, hit: &Hit) -> Self {
        Self::with_barycentrics(scene, ray, hit, false)
    }

    /// `new`, trusting the hit's barycentrics when `exact` (the backend's
    /// `Traversal::exact_barycentrics`): recomputing them then gives the
    /// same bits, at the cost of a triangle test per hit.
    pub fn with_barycentrics(scene: &Scene, ray: &Ray, hit: &Hit, exact: bool) -> Self {
        let (p, ng, ns, magnitude, edge_room) = match &scene.shapes[hit.geom_id as usize] {
            Shape::Mesh(m) => {
                let tri = m.triangles[hit.prim_id as usize];
                let [a, b, c] = tri.map(|i| m.positions[i as usize]);
                // Backends agree on *which* triangle, but Embree's barycentrics
                // differ from ours in the last bits. Recomputing them with our
                // own test makes shading depend only on (ray, primitive), so
                // every backend renders the same image. If our test misses by
                // an ulp at an edge, keep the backend's values.
                let (u, v) = if exact {
                    (hit.u, hit.v)
                } else {
                    let rt = RayTransform::new(ray.origin, ray.dir);
                    intersect_triangle(&rt, a, b, c, ray.tmin, ray.tmax).map_or((hit.u, hit.v), |(_, u, v)| (u, v))
                };
                let mag = magnitude(&[a, b, c]);
                // One f64 edge cross product for both the face normal and
                // the area (`face_normal` and `area` each compute it).
                let cross = crate::geometry::triangle::edge_cross(a, b, c);
                let twice_area = 2.0 * (0.5 * cross.length()) as f32;
                let (u, v) = away_from_edges(a, b, c, u, v, mag, twice_area);
                let w = 1.0 - u - v;
                let p = crate::geometry::triangle::point_at(a, b, c, u, v);
                let ng = cross.normalize_or_zero().as_vec3();
                let [na, nb, nc] = tri.map(|i| m.normals[i as usize]);
                let ns = (na * w + nb * u + nc * v).normalize_or_zero();
                // A vertex's barycentric is its distance to the opposite edge
                // over that edge's height (twice the area over its length).
                let room = [(w, b, c), (u, c, a), (v, a, b)]
                    .iter()
                    .map(|&(bary, q, r)| {
                        let edge = (r - q).length();
                        if edge > 0.0 { bary.max(0.0) * twice_area / edge } else { 0.0 }
                    })
                    .fold(f32::INFINITY, f32::min);
                (p, ng, if ns == Vec3::ZERO { ng } else { ns }, mag, if room.is_finite() { room } else { 0.0 })
            }
            Shape::Sphere { center, radius } => {
                let n = (ray.at(hit.t) - *center).normalize_or_zero();
                (*center + n * *radius, n, n, center.abs().max_element() + radius, f32::INFINITY)
            }
        };
        let towards = ray.dir.dot(ng);
        let incoming_side = if towards < 0.0 { 1.0 } else if towards > 0.0 { -1.0 } else { 0.0 };
        Interaction { p, ng, ns, t: hit.t, magnitude, edge_room, incoming_side, geom_id: hit.geom_id, prim_id: hit.prim_id }
    }
}

/// Mesh data (vertex indices, positions, normals) above which a path's
/// scattered hits are fetched ahead (`Scene::hits_miss_caches`). Measured
/// (2 threads, 2-vCPU AMD EPYC, 32 spp): the subdivided CBbunny (1.8M
/// triangles, about 40 MiB) renders 2 % faster fetching ahead, CBbunny (28,588
/// triangles, under 1 MiB) 0.5 % slower.
const FETCH_HITS_FROM_BYTES: usize = 8 << 20;

impl Scene {
    /// Whether describing a scattered hit is likely to wait on memory: the
    /// meshes' data is larger than what the caches keep beside a tree.
    pub fn hits_miss_caches(&self) -> bool {
        let bytes: usize = self
            .shapes
            .iter()
            .map(|s| match s {
                Shape::Mesh(m) => std::mem::size_of_val(&m.triangles[..]) + std::mem::size_of_val(&m.positions[..]) + std::mem::size_of_val(&m.normals[..]),
                Shape::Sphere { .. } => 0,
            })
            .sum();
        bytes >= FETCH_HITS_FROM_BYTES
    }

    /// Start loading what describing `hit` will read, `step` of it
    /// (`MeshFetch::Indices`, then `PositionsAndNormals`): on a mesh larger
    /// than the caches each step is a miss that the path tracer otherwise
    /// waits for (a path's hits are scattered). A hint, as
    /// `TriangleMesh::prefetch`; nothing on spheres or unknown ids.
    #[inline]
    pub fn prefetch_hit(&self, hit: &Hit, step: MeshFetch) {
        if let Some(Shape::Mesh(m)) = self.shapes.get(hit.geom_id as usize) {
            m.prefetch(hit.prim_id as usize, step);
        }
    }
}

/// How far, in ulps of the triangle's magnitude, a hit point is kept from
/// the triangle's edges.
const EDGE_ULPS: f32 = 4.0;

/// Barycentrics `(u, v)` moved, where needed, so that the interpolated point
/// lies at least `EDGE_ULPS` ulps inside every edge. Rounding can put a hit
/// next to an edge an ulp or two beyond it, that is, behind the neighbouring
/// surface where two walls meet; a ray spawned from there starts outside a
/// closed room (the step along the normal does not help: it moves the point
/// parallel to the neighbour). Measured: a sealed room 2000 units from the
/// origin leaked light through its edges at 64 spp. Points farther from the
/// edges do not move, so shading elsewhere is unchanged.
fn away_from_edges(a: Vec3, b: Vec3, c: Vec3, u: f32, v: f32, magnitude: f32, twice_area: f32) -> (f32, f32) {
    let step = EDGE_ULPS * ulp(magnitude);
    let w = 1.0 - u - v;
    // Most hits lie far inside: u·2A ≥ step·|edge| with a margin far above
    // the rounding of either side (compared squared in f64, no square roots
    // and no overflow) proves u ≥ the bound below, whatever it rounds to.
    let clear = |bary: f32, p: Vec3, q: Vec3| {
        let lhs = bary as f64 * twice_area as f64;
        bary > 0.0 && lhs * lhs >= 1.0001 * (step as f64 * step as f64) * (q - p).as_dvec3().length_squared()
    };
    if clear(u, c, a) && clear(v, a, b) && clear(w, b, c) {
        return (u, v);
    }
    // Barycentric of a vertex = distance to the opposite edge / that height.
    let min_bary = |p: Vec3, q: Vec3| {
        let edge = (q - p).length();
        if twice_area > 0.0 && edge > 0.0 { (step * edge / twice_area).min(1.0 / 3.0) } else { 0.0 }
    };
    let (mu, mv, mw) = (min_bary(c, a), min_bary(a, b), min_bary(b, c));
    if u >= mu && v >= mv && w >= mw {
        return (u, v);
    }
    let (u, v, w) = (u.max(mu), v.max(mv), w.max(mw));
    let s = u + v + w;
    (u / s, v / s)
}

impl Interaction {
    /// A ray leaving the surface along `wi`, its origin stepped off the
    /// surface to the side `wi` goes (see `spawn_origin`): on the ray's own
    /// line where it leaves to the side it came from, along the normal where
    /// it is transmitted (there the exact line would put exits near the
    /// critical angle on its wrong side as often as not: a lossless sphere at
    /// 8192 lost paths to total internal reflection).
    pub fn spawn_ray(&self, wi: Vec3) -> Ray {
        let n = if wi.dot(self.ng) >= 0.0 { self.ng } else { -self.ng };
        let reflected = self.incoming_side != 0.0 && wi.dot(self.ng) * self.incoming_side > 0.0;
        Ray::new(spawn_origin(self.p, n, wi, self.magnitude, if reflected { self.edge_room } else { 0.0 }), wi)
    }

    /// A segment from the surface to `target` (already stepped off its own
    /// surface), ending `SHADOW_EPSILON` of its length short of the target.
    /// Why short: the target's offset from its surface is a few ulps of its
    /// position, while a hit's `t` is rounded to a few ulps of 1, so over a
    /// long segment the target's own surface could still be hit at
    /// `t == 1.0` — by one backend and not another (a CBgems pixel differed
    /// between native and Embree). pbrt-v4 ends shadow rays the same way.
    pub fn spawn_ray_to(&self, target: Vec3) -> Ray {
        let n = if (target - self.p).dot(self.ng) >= 0.0 { self.ng } else { -self.ng };
        let o = spawn_origin(self.p, n, target - self.p, self.magnitude, self.edge_room);
        Ray::with_range(o, target - o, 0.0, 1.0 - SHADOW_EPSILON)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Prefetching is a hint: any id, valid or not, on any shape, returns
    /// quietly (a hit past the scene's shapes or primitives must not panic
    /// where its description would be refused).
    #[test]
    fn prefetch_hit_takes_any_ids() {
        let scene = crate::scene::builtin::load().expect("built-in scene");
        let mesh = scene.shapes.iter().position(|s| matches!(s, Shape::Mesh(_))).expect("a mesh") as u32;
        let sphere = scene.shapes.iter().position(|s| matches!(s, Shape::Sphere { .. })).expect("a sphere") as u32;
        assert!(!scene.hits_miss_caches(), "the built-in Cornell box fits the caches");
        for (geom_id, prim_id) in [(mesh, 0), (mesh, u32::MAX), (sphere, 0), (u32::MAX, 0)] {
            let hit = Hit { t: 1.0, u: 0.25, v: 0.25, geom_id, prim_id };
            for step in [MeshFetch::Indices, MeshFetch::Positions, MeshFetch::PositionsAndNormals] {
                scene.prefetch_hit(&hit, step);
            }
        }
    }
}
