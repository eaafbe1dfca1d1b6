//! The four ways strategy (s, t) joins light vertex y(s−1) to camera vertex
//! z(t−1) (Veach ch. 10, pbrt-v4's `ConnectBDPT`); each returns the
//! unweighted contribution, or nothing when it is zero or occluded:
//!
//! * s = 0: the camera subpath ends on an emitter: its radiance toward
//!   z(t−2), times the camera throughput; or it escaped, and a light at
//!   infinity (`Kind::Distant`, one strategy per such light) sends its
//!   radiance along the escape;
//! * t = 1 (light tracing): a lens point chosen toward y(s−1)
//!   (`Sensor::sample_toward`); the contribution lands where that ray meets
//!   the film, usually another pixel (a splat);
//! * s = 1 (next-event estimation): a light picked by power and a point on
//!   it drawn as the path tracer draws light samples (`Light::sample`: by
//!   solid angle where it can), so the point is a fresh vertex;
//! * otherwise: both BSDFs, the adjoint one at the light end, and the
//!   geometry term |cos|·|cos|/d² with shading normals.
//!
//! A connection's value assumes its segment is clear; the segment comes back
//! as `Connection::shadow`, for the caller to trace with the sample's other
//! connections as one batch (`gather` in `mod.rs`).

use super::vertex::{Kind, Mode, Vertex};
use super::Bdpt;
use crate::light::{emitted, EnvAt, Target};
use crate::ray::Ray;
use crate::sampler::{dim, Sampler};
use glam::Vec3;

/// A strategy's unweighted contribution, if `shadow` is clear.
pub(super) struct Connection {
    pub value: Vec3,
    /// The segment that must be unoccluded (none for s = 0).
    pub shadow: Option<Ray>,
    /// The vertex the strategy made afresh: the light point (s = 1) or the
    /// lens point (t = 1).
    pub sampled: Option<Vertex>,
    /// Where a light-tracing contribution lands on the film (t = 1).
    pub film: Option<(f32, f32)>,
    /// s = 1: a_nee / a_emit of the light point (`Bdpt::nee_ratio`), from
    /// the density the light sample drew it with; 1 otherwise.
    pub nee_ratio: f64,
}

impl Bdpt<'_> {
    pub(super) fn connect(&self, light: &[Vertex], camera: &[Vertex], s: usize, t: usize, sampler: &mut Sampler) -> Option<Connection> {
        let done = |value: Vec3, shadow: Option<Ray>, sampled: Option<Vertex>, film: Option<(f32, f32)>| {
            (value.max_element() > 0.0 && value.is_finite()).then_some(Connection { value, shadow, sampled, film, nee_ratio: 1.0 })
        };
        if s == 0 {
            let z = &camera[t - 1];
            if let Kind::Distant(k) = z.kind {
                return done(z.beta * self.lights.lights[k].escaped(z.it.ns), None, None, None);
            }
            if z.kind != Kind::Surface || z.light(self.lights).is_none() {
                return None;
            }
            return done(z.beta * emitted(self.scene, &z.it, z.wo), None, None, None);
        }
        if t == 1 {
            // An emission sample can fail (a direction of zero density on an
            // environment map): the light subpath is then empty.
            let y = light.get(s - 1)?;
            if !y.connectible() {
                return None;
            }
            // A point light seen directly, or a rectangle that rays cannot
            // hit: no camera ray sees them, and neither does this; nor a
            // light at infinity, which has no point to aim the lens at.
            match y.kind {
                Kind::Light(k) if !self.lights.lights[k].is_hittable() => return None,
                Kind::Distant(_) => return None,
                _ => {}
            }
            let ls = self.camera.sample_toward(y.p(), sampler.get_2d(dim::light_vertex(s as u32 - 1, dim::LENS_CONNECT)))?;
            let value = y.beta * y.f(ls.lens, Mode::Importance) * y.cos(ls.wi) * ls.weight;
            let lens = Vertex::at_point(Kind::Camera, ls.lens, self.camera.view_axis(), ls.lens.abs().max_element(), u32::MAX, 0, Vec3::ONE, 0.0);
            return done(value, Some(y.it.spawn_ray_to(ls.lens)), Some(lens), Some(ls.film));
        }
        let z = &camera[t - 1];
        if !z.connectible() {
            return None;
        }
        if s == 1 {
            sampler.set_bounce(t as u32 - 1);
            let (k, pmf) = self.power.pick(sampler.slot_1d(dim::CONNECT_PICK, 0))?;
            let l = &self.lights.lights[k];
            let ls = l.sample(self.scene, z.p(), sampler.slot_2d(dim::CONNECT_POINT, 0), sampler.slot_1d(dim::CONNECT_SELECT, 0), EnvAt::Map)?;
            if !(ls.pdf > 0.0) {
                return None;
            }
            let beta0 = ls.value / (ls.pdf * pmf);
            // The light point and the shadow segment to it; for a light at
            // infinity, its direction and an unbounded shadow ray.
            let (f, shadow, y0, nee_ratio) = match ls.target {
                Target::Point(target) => {
                    let n = l.normal_at(self.scene, target, ls.prim);
                    let emit = l.emission_pdf_pos(self.power.world());
                    let y0 = Vertex::at_point(Kind::Light(k), target, n, target.abs().max_element(), l.geometry(), ls.prim, beta0, pmf * emit);
                    // The sample's density per area at the light point (a
                    // point light: its position density, 1).
                    let nee = if n == Vec3::ZERO { 1.0 } else { ls.pdf * n.dot(ls.wi).abs() / (target - z.p()).length_squared() };
                    (z.f(target, Mode::Radiance), z.it.spawn_ray_to(target), y0, super::mis::nee_over_emit(nee, emit))
                }
                Target::Infinite => {
                    let y0 = Vertex::distant(k, Vec3::ZERO, ls.wi, beta0, pmf * l.infinite_pdf_dir(ls.wi));
                    (z.f_dir(ls.wi, Mode::Radiance), z.it.spawn_ray(ls.wi), y0, 1.0)
                }
            };
            let value = z.beta * f * z.cos(ls.wi) * ls.value / (ls.pdf * pmf);
            return done(value, Some(shadow), Some(y0), None).map(|c| Connection { nee_ratio, ..c });
        }
        let y = &light[s - 1];
        if !y.connectible() {
            return None;
        }
        let d = y.p() - z.p();
        let d2 = d.length_squared();
        if !(d2 > 0.0) {
            return None;
        }
        let w = d / d2.sqrt();
        let g = y.cos(w) * z.cos(w) / d2;
        let value = y.beta * y.f(z.p(), Mode::Importance) * z.f(y.p(), Mode::Radiance) * z.beta * g;
        if !(value.max_element() > 0.0) {
            return None;
        }
        done(value, Some(z.it.spawn_ray_to(y.offset_toward(z.p()))), None, None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use crate::light::Lights;
    use crate::render::bdpt::Technique;
    use crate::render::Region;
    use crate::sampler::SamplerKind;

    /// Light tracing (t = 1) after an emission sample that failed (a
    /// direction of zero density on an environment map ends the light
    /// subpath before its first vertex) contributes nothing, for every s,
    /// instead of reading past the empty subpath.
    #[test]
    fn light_tracing_from_an_empty_light_subpath_contributes_nothing() {
        let scene = crate::scene::builtin::load().unwrap();
        let lights = Lights::from_scene(&scene).unwrap();
        let camera = Camera::from_scene(&scene);
        let (w, h) = (camera.screen_w, camera.screen_h);
        for technique in [Technique::LightTracing, Technique::Bidirectional] {
            let bdpt = Bdpt::new(&scene, &lights, &camera, w, h, Region { x: 0, y: 0, w, h }, 5, true, technique).unwrap();
            let mut sampler = Sampler::for_pixel(SamplerKind::Independent, 1, 0, 0, 1);
            for s in 1..=3 {
                assert!(bdpt.connect(&[], &[], s, 1, &mut sampler).is_none(), "{technique:?}, s = {s}");
            }
        }
    }
}
