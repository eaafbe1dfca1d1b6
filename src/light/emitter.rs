//! What every emitter kind answers (`Emitter`), and the construction of a
//! light sample that the emissive surfaces share. Each kind — point,
//! directional, hemisphere sky, area rectangle, triangle mesh, sphere,
//! environment map — is a file of its own implementing `Emitter`; `Light`
//! dispatches to them.

use super::emission::{Emission, World};
use super::{EnvAt, LightSample, Target};
use crate::sampling::{cosine_hemisphere, offset_ray_origin, Frame};
use crate::scene::Scene;
use glam::Vec3;
use std::f32::consts::PI;

/// An emitter kind's sampling, densities and power. The defaults are
/// those of an emitter that is not a surface and not at infinity.
pub trait Emitter {
    /// One line for the summary and the notes.
    fn describe(&self) -> String;

    /// A delta light (point, directional): only light sampling finds it.
    fn is_delta(&self) -> bool {
        false
    }

    /// Whether rays can hit this emitter (so hemisphere sampling finds it).
    fn is_visible(&self) -> bool {
        false
    }

    /// Whether it lies at infinity (directional, hemisphere, environment
    /// map): rays from it start on the `World` disk.
    fn is_at_infinity(&self) -> bool {
        false
    }

    /// Whether a ray can hit it as an emissive surface of the scene (a
    /// camera path can then find it by chance, the strategy `s = 0`).
    fn is_hittable(&self) -> bool {
        false
    }

    /// The scene geometry this light is (an emissive mesh's id), or
    /// `u32::MAX`.
    fn geometry(&self) -> u32 {
        u32::MAX
    }

    /// Whether `sample` uses its `u_sel` (to pick a triangle of a mesh).
    fn uses_selection(&self) -> bool {
        false
    }

    /// Light arriving at `p`: `u` two uniforms, `u_sel` a third (triangle
    /// selection); an environment map sampled as `env_at` says. `None` when
    /// the sample carries no light (the back of a one-sided emitter, a
    /// degenerate configuration).
    fn sample(&self, scene: &Scene, p: Vec3, u: (f32, f32), u_sel: f32, env_at: EnvAt) -> Option<LightSample>;

    /// Solid-angle pdf with which `sample` from `p` picks the point `x`
    /// (normal `n`, on primitive `prim`) of this emitter's surface; 0 for
    /// lights that are not surfaces.
    fn pdf_hit(&self, _scene: &Scene, _p: Vec3, _x: Vec3, _n: Vec3, _prim: u32) -> f32 {
        0.0
    }

    /// Whether `sample` from `p` draws directions uniformly over the whole
    /// solid angle this emitter subtends (see `PathTracer::alone`).
    fn covers(&self, _p: Vec3) -> bool {
        false
    }

    /// Radiance sent along `-dir` to a ray escaping along `dir` (0 for
    /// lights that are not at infinity).
    fn escaped(&self, _dir: Vec3) -> Vec3 {
        Vec3::ZERO
    }

    /// Solid-angle pdf of `sample` for an escaping direction, with the same
    /// `env_at` as `sample`.
    fn pdf_escape(&self, _dir: Vec3, _env_at: EnvAt) -> f32 {
        0.0
    }

    /// For a light at infinity, the density with which emission (and
    /// next-event estimation) picks direction `to_light`.
    fn infinite_pdf_dir(&self, to_light: Vec3) -> f32 {
        self.pdf_escape(to_light, EnvAt::Map)
    }

    /// Emitted power (luminance-weighted): what the choice of the emitting
    /// light is proportional to.
    fn power(&self, world: &World) -> f32;

    /// Area density with which emission picks its points (1 for a point
    /// light; per area of the `World` disk for lights at infinity).
    fn emission_pdf_pos(&self, world: &World) -> f32 {
        world.disk_pdf()
    }

    /// Solid-angle density of emission sending `dir` from a point whose
    /// emitting normal is `n` (lights at finite distance).
    fn emission_pdf_dir(&self, _n: Vec3, _dir: Vec3) -> f32 {
        0.0
    }

    /// The area density (at `q`, normal `n`, on primitive `prim`) with
    /// which a light sample from `p` picks `q`; for a point light 1.
    fn sample_pdf_area(&self, _scene: &Scene, _p: Vec3, _q: Vec3, _n: Vec3, _prim: u32) -> f32 {
        0.0
    }

    /// The unit normal of the emitting side at `q` (on primitive `prim`),
    /// zero where there is none.
    fn normal_at(&self, _scene: &Scene, _q: Vec3, _prim: u32) -> Vec3 {
        Vec3::ZERO
    }

    /// A ray leaving a light at finite distance: `u_sel` picks a mesh's
    /// triangle, `u_pos` the point, `u_dir` the direction (lights at
    /// infinity are emitted by `Light::sample_emission` from their
    /// `sample`).
    fn emit(&self, _scene: &Scene, _world: &World, _u_sel: f32, _u_pos: (f32, f32), _u_dir: (f32, f32)) -> Option<Emission> {
        None
    }

    /// The CS184 way of sampling it instead of ours, for A/B measurements:
    /// by area (`by_area`), the sky uniformly (`uniform_sky`).
    fn use_cs184_sampling(&mut self, _by_area: bool, _uniform_sky: bool) {}

    /// Its unshadowed irradiance at `p` (normal `n`) as the light pick
    /// estimates it; `None` for lights without an estimate (they are then
    /// never picked from).
    fn pick_estimate(&self, _p: Vec3, _n: Vec3) -> Option<f32> {
        None
    }
}

/// A sample at `q` drawn uniformly in solid angle (pdf `pdf`), of a
/// one-sided emitter with normal `n` that `p` is in front of.
pub(super) fn solid_angle_sample(p: Vec3, q: Vec3, n: Vec3, mag: f32, radiance: Vec3, pdf: f32) -> Option<LightSample> {
    let wi = (q - p).normalize_or_zero();
    if !(-n.dot(wi) > 0.0) || !(pdf > 0.0 && pdf.is_finite()) {
        return None;
    }
    Some(LightSample { wi, value: radiance, pdf, target: Target::Point(offset_ray_origin(q, n, mag)), covers: true, prim: 0 })
}

/// Convert an area-measure sample at `q` (normal `n`, one-sided) into a
/// solid-angle sample seen from `p`: pdf_w = pdf_A * dist^2 / |cos_l|.
pub(super) fn area_sample(p: Vec3, q: Vec3, n: Vec3, mag: f32, radiance: Vec3, pdf_area: f32) -> Option<LightSample> {
    let d = q - p;
    let dist2 = d.length_squared();
    if !(dist2 > 0.0) {
        return None;
    }
    let wi = d / dist2.sqrt();
    let cos_l = -n.dot(wi);
    if !(cos_l > 0.0) {
        return None; // the back of a one-sided emitter
    }
    // The shadow ray stops just short of the emitter: its end is pushed off
    // the surface, towards the receiver, by the same ulp offset as origins.
    Some(LightSample { wi, value: radiance, pdf: pdf_area * dist2 / cos_l, target: Target::Point(offset_ray_origin(q, n, mag)), covers: false, prim: 0 })
}

/// The solid-angle pdf of a point at `x` (normal `n`) drawn from a surface
/// with area density `pdf_area`, seen from `p`.
pub(super) fn area_to_solid_angle(pdf_area: f32, p: Vec3, x: Vec3, n: Vec3) -> f32 {
    let d = x - p;
    let dist2 = d.length_squared();
    let cos = n.dot(d).abs() / dist2.sqrt();
    if cos > 0.0 {
        pdf_area * dist2 / cos
    } else {
        0.0
    }
}

/// A ray leaving an emissive surface at `p` (emitting normal `n`), in a
/// cosine-distributed direction about `n`.
#[allow(clippy::too_many_arguments)]
pub(super) fn cosine_emission(p: Vec3, n: Vec3, le: Vec3, magnitude: f32, prim: u32, pdf_pos: f32, u_dir: (f32, f32)) -> Option<Emission> {
    if n == Vec3::ZERO {
        return None;
    }
    let local = cosine_hemisphere(u_dir.0, u_dir.1);
    let dir = Frame::new(n).to_world(local);
    let pdf_dir = local.z / PI;
    (pdf_dir > 0.0).then_some(Emission { p, n, dir, le, pdf_pos, pdf_dir, magnitude, prim })
}

/// The sample's density at `q` converted to area, seen from `p`.
pub(super) fn solid_angle_to_area(pdf_w: f32, p: Vec3, q: Vec3, n: Vec3) -> f32 {
    let d = q - p;
    let d2 = d.length_squared();
    if !(d2 > 0.0) {
        return 0.0;
    }
    pdf_w * n.dot(d).abs() / (d2 * d2.sqrt())
}
