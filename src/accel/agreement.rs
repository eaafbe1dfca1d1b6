//! Whether two backends found the same hit along a ray, within what the
//! backend contract allows (`docs/design/backend-contract.md`): the same
//! primitive with t and the barycentrics within 1e-5 relative (or, for
//! small triangles seen from far, their f32 error bound), or — a tie — two
//! primitives hit at the same distance (a ray through a shared edge). Used
//! by the cross-check tests and by `pathtracer validate`.

use super::{Hit, Traversal};
use crate::ray::Ray;
use crate::scene::{Scene, Shape};

/// Relative tolerance of t and of the barycentrics.
pub const REL: f32 = 1e-5;

fn close(a: f32, b: f32) -> bool {
    (a - b).abs() <= REL * a.abs().max(b.abs()).max(1e-30)
}

/// How two backends' answers for one ray compare.
#[derive(Clone, Debug, PartialEq)]
pub enum Agreement {
    /// The same answer (both miss, or the same primitive within 1e-5).
    Same,
    /// Different primitives at the same distance.
    Tie,
    /// The same primitive, t or u/v apart by more than 1e-5 but within the
    /// f32 error bound of a small triangle seen from far.
    Widened,
    /// A ray through a vertex one backend passes while the other hits the
    /// vertex (set by a caller that knows the ray's aim and asked brute
    /// force; `compare` never returns it).
    Crack,
    /// A hit within f32 of an edge of an open surface (no other triangle
    /// shares the edge) against a pass: either answer is right (set by a
    /// caller, as `Crack`).
    OpenEdge,
    /// Different answers: why, in words.
    Differ(String),
}

/// f32 error bounds of (u and v, t) for a hit on a triangle seen from distance D.
/// t's absolute error is a few ulps of D (in units of the ray direction),
/// which exceeds 1e-5 relative only when t is tiny compared to D; a ray
/// grazing the triangle's plane stretches both by 1/cos (a plane distance's
/// rounding moves the crossing along the ray by that much more).
pub fn error_bounds(scene: &Scene, r: &Ray, h: &Hit) -> (f32, f32) {
    match &scene.shapes[h.geom_id as usize] {
        Shape::Mesh(m) => {
            let [a, b, c] = m.triangles[h.prim_id as usize].map(|i| m.positions[i as usize]);
            let area2 = (b - a).cross(c - a).length();
            let longest = (b - a).length().max((c - b).length()).max((a - c).length());
            let height = area2 / longest;
            let d = [a, b, c].iter().map(|p| (*p - r.origin).length()).fold(0.0f32, f32::max);
            // Grazing incidence stretches the projected triangle's errors by 1/cos.
            let cos = ((b - a).cross(c - a).normalize().dot(r.dir.normalize())).abs().max(1e-3);
            (16.0 * f32::EPSILON * d / (height * cos), 16.0 * f32::EPSILON * d / (r.dir.length() * cos))
        }
        _ => (REL, 0.0),
    }
}

/// The cosine between the ray and the normal of the triangle hit (1 for
/// other shapes), at least 1e-6: where two triangles meet along an edge
/// the ray grazes, the distances at which it crosses their planes near the
/// edge differ by the hit points' rounding divided by this.
fn grazing(scene: &Scene, r: &Ray, h: &Hit) -> f32 {
    match &scene.shapes[h.geom_id as usize] {
        Shape::Mesh(m) => {
            let [a, b, c] = m.triangles[h.prim_id as usize].map(|i| m.positions[i as usize]);
            (b - a).cross(c - a).normalize_or_zero().dot(r.dir.normalize_or_zero()).abs().max(1e-6)
        }
        _ => 1.0,
    }
}

/// Whether hit `h` lies within its f32 bound of an edge of `h`'s triangle
/// that no other triangle of the mesh shares (none with both ends and a
/// third corner of its own: a flipped copy of the triangle does not count),
/// where a ray may pass or hit by rounding alone.
pub fn on_open_edge(scene: &Scene, r: &Ray, h: &Hit) -> bool {
    let Shape::Mesh(m) = &scene.shapes[h.geom_id as usize] else { return false };
    let corners = |t: &[u32; 3]| t.map(|i| m.positions[i as usize]);
    let [a, b, c] = corners(&m.triangles[h.prim_id as usize]);
    let bound = error_bounds(scene, r, h).0.max(REL);
    // Each edge with the barycentric that vanishes on it.
    let edges = [((a, c), b, h.u), ((a, b), c, h.v), ((b, c), a, 1.0 - h.u - h.v)];
    edges.iter().filter(|e| e.2.abs() <= bound).any(|&((p, q), own, _)| {
        !m.triangles.iter().enumerate().any(|(k, t)| {
            let t = corners(t);
            k != h.prim_id as usize && t.contains(&p) && t.contains(&q) && t.iter().any(|x| *x != p && *x != q && *x != own)
        })
    })
}

/// Compare two closest hits of ray `r`.
pub fn compare(scene: &Scene, r: &Ray, a: Option<Hit>, b: Option<Hit>) -> Agreement {
    match (a, b) {
        (None, None) => Agreement::Same,
        (Some(x), Some(y)) if (x.geom_id, x.prim_id) == (y.geom_id, y.prim_id) => {
            let du = (x.u - y.u).abs().max((x.v - y.v).abs());
            let (bound, t_abs) = error_bounds(scene, r, &x);
            let dt = (x.t - y.t).abs();
            let t_ok = close(x.t, y.t) || dt <= t_abs;
            if !t_ok || du > bound.max(REL) {
                Agreement::Differ(format!("t/u/v differ: {x:?} against {y:?} (uv bound {bound:e})"))
            } else if (du > REL && du <= bound) || !close(x.t, y.t) {
                Agreement::Widened
            } else {
                Agreement::Same
            }
        }
        (Some(x), Some(y)) if close(x.t, y.t) || (x.t - y.t).abs() <= error_bounds(scene, r, &x).1.max(error_bounds(scene, r, &y).1) / grazing(scene, r, &x).min(grazing(scene, r, &y)) => Agreement::Tie,
        _ => Agreement::Differ(format!("{a:?} against {b:?}")),
    }
}

/// Whether `compare_occlusion` lets an occluder within f32 of the closest
/// hit's distance pass as a tie.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OccluderTies {
    /// Any scene (a user's, with nearly coplanar neighbours along edges).
    Allowed,
    /// The shipped scenes, where no such ray has been found: every
    /// disagreement is reported.
    Refused,
}

/// Compare the occlusion answers of `a` and `b` for `r`, and for `r`
/// shortened to end before its closest hit `hit` (by more than the f32
/// uncertainty of t: rays starting a few ulps from a surface have a t that
/// neither backend knows to 0.1 %).
pub fn compare_occlusion(scene: &Scene, r: &Ray, hit: Option<Hit>, a: &dyn Traversal, b: &dyn Traversal, ties: OccluderTies) -> Option<String> {
    let (oa, ob) = (a.occluded(r), b.occluded(r));
    if oa != ob {
        return Some(format!("occluded {oa} against {ob}"));
    }
    let h = hit?;
    let margin = (h.t * 1e-3).max(4.0 * error_bounds(scene, r, &h).1);
    if h.t - margin <= r.tmin {
        return None;
    }
    let s = Ray { tmax: h.t - margin, ..*r };
    let (oa, ob) = (a.occluded(&s), b.occluded(&s));
    if oa == ob {
        return None;
    }
    // The occluder one backend found on the segment may be another
    // triangle at the closest hit's distance within f32 (a ray grazing
    // nearly coplanar neighbours along an edge): the tie rule of `compare`,
    // with both triangles' bounds.
    let o = if oa { a.intersect(&s) } else { b.intersect(&s) };
    if let Some(o) = o.filter(|_| ties == OccluderTies::Allowed) {
        let bound = error_bounds(scene, r, &o).1.max(error_bounds(scene, r, &h).1) / grazing(scene, r, &o).min(grazing(scene, r, &h));
        if h.t - o.t <= bound {
            return None;
        }
    }
    Some(format!("shortened to {}: occluded {oa} against {ob} (the occluder: {o:?}; the closest hit: {h:?})", s.tmax))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{generated::sphere_scene, TriangleMesh};
    use glam::Vec3;

    /// A scene of one mesh: the unit square's two triangles, and what else.
    fn square(extra: Vec<[u32; 3]>) -> Scene {
        let mut s = sphere_scene(10);
        let positions = vec![Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 0.0), Vec3::new(0.0, 1.0, 0.0)];
        let mut triangles = vec![[0, 1, 2], [0, 2, 3]];
        triangles.extend(extra);
        s.shapes = vec![Shape::Mesh(TriangleMesh { positions, triangles, normals: Vec::new() })];
        s
    }

    #[test]
    fn an_edge_is_open_only_where_no_other_triangle_shares_it() {
        let down = Vec3::new(0.0, 0.0, -1.0);
        let at = |prim: u32, u: f32, v: f32| Hit { t: 1.0, u, v, geom_id: 0, prim_id: prim };
        let scene = square(Vec::new());
        // Triangle 0 (a, b, c) = (0, 1, 2): its edge a-c (u = 0) is the diagonal, shared with triangle 1.
        let r = Ray::new(Vec3::new(0.5, 0.5, 1.0), down);
        assert!(!on_open_edge(&scene, &r, &at(0, 0.0, 0.5)));
        // Its edge a-b (v = 0) is the square's border: open.
        let r = Ray::new(Vec3::new(0.5, 0.0, 1.0), down);
        assert!(on_open_edge(&scene, &r, &at(0, 0.5, 0.0)));
        // Inside the triangle, no edge at all.
        assert!(!on_open_edge(&scene, &r, &at(0, 0.3, 0.2)));
        // A flipped copy of triangle 0 does not close its border; a triangle with a corner of its own does.
        let flipped = square(vec![[0, 2, 1]]);
        assert!(on_open_edge(&flipped, &r, &at(0, 0.5, 0.0)));
        let mut closed = square(Vec::new());
        if let Shape::Mesh(m) = &mut closed.shapes[0] {
            m.positions.push(Vec3::new(0.5, -1.0, 0.0));
            m.triangles.push([1, 0, 4]);
        }
        assert!(!on_open_edge(&closed, &r, &at(0, 0.5, 0.0)));
    }
}
