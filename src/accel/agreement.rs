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

/// Compare the occlusion answers of `a` and `b` for `r`, and for `r`
/// shortened to end before its closest hit `hit` (by more than the f32
/// uncertainty of t: rays starting a few ulps from a surface have a t that
/// neither backend knows to 0.1 %).
pub fn compare_occlusion(scene: &Scene, r: &Ray, hit: Option<Hit>, a: &dyn Traversal, b: &dyn Traversal) -> Option<String> {
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
    if let Some(o) = o {
        let bound = error_bounds(scene, r, &o).1.max(error_bounds(scene, r, &h).1) / grazing(scene, r, &o).min(grazing(scene, r, &h));
        if h.t - o.t <= bound {
            return None;
        }
    }
    Some(format!("shortened to {}: occluded {oa} against {ob} (the occluder: {o:?}; the closest hit: {h:?})", s.tmax))
}
