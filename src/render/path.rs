//! Light transport: CS184's structure (zero bounce, one bounce, at least one
//! bounce) made physically correct, written as a loop.
//!
//! Emission is counted where a camera ray lands, and otherwise only through
//! the direct-lighting estimate at each vertex: light sampling (default) or
//! uniform hemisphere sampling (`-H`). A continuation ray that happens to hit
//! an emitter adds nothing, because the direct estimate at the previous vertex
//! already accounted for that light: no double counting.
//!
//! Delta lights (point, directional) and proxy-less rectangle lights cannot be
//! hit by a ray, so `-H` still samples them explicitly; everything a ray can
//! hit (emissive surfaces, the hemisphere light) is found by the hemisphere
//! samples. Both modes therefore estimate the same integral.

use super::Integrator;
use crate::accel::Traversal;
use crate::light::{emitted, Light, Lights, Target};
use crate::ray::Ray;
use crate::rng::Rng;
use crate::sampling::{cosine_hemisphere, offset_ray_origin, uniform_hemisphere, Frame, UNIFORM_HEMISPHERE_PDF};
use crate::scene::{Bsdf, Interaction, Scene};
use glam::Vec3;
use std::f32::consts::PI;

pub struct PathTracer<'a> {
    pub scene: &'a Scene,
    pub accel: &'a dyn Traversal,
    pub lights: &'a Lights,
    /// `-m`: 0 emission only, 1 direct, k paths of up to k bounces.
    pub max_depth: u32,
    /// `-o`: true sums bounces 0..=m, false keeps only bounce m.
    pub accumulate: bool,
    /// `-H`: uniform hemisphere sampling for direct light.
    pub hemisphere: bool,
    /// `-l`: samples per non-delta light (per hemisphere-sample group with -H).
    pub light_samples: u32,
    pub russian_roulette: bool,
}

/// The surface seen from the side the ray came from: normals flipped towards `wo`.
struct Vertex {
    it: Interaction,
    /// Geometric and shading normals on the side of `wo`.
    ng: Vec3,
    ns: Vec3,
    albedo: Vec3,
}

impl PathTracer<'_> {
    fn trace(&self, ray: &Ray, rays: &mut u64) -> Option<Interaction> {
        *rays += 1;
        self.accel.intersect(ray).map(|h| Interaction::new(self.scene, ray, &h))
    }

    fn vertex(&self, it: Interaction, wo: Vec3) -> Vertex {
        let flip = if it.ng.dot(wo) < 0.0 { -1.0 } else { 1.0 };
        let ng = it.ng * flip;
        let mut ns = it.ns * flip;
        if ns.dot(ng) <= 0.0 {
            ns = ng; // an interpolated normal turned past the face: use the face's
        }
        let albedo = match self.scene.material_of(it.geom_id).bsdf {
            Bsdf::Diffuse { albedo } => albedo,
            // Emitters do not reflect (CS184's EmissionBSDF has f = 0).
            _ => Vec3::ZERO,
        };
        Vertex { it, ng, ns, albedo }
    }

    /// A ray leaving `v` along `wi`, its origin moved off the surface.
    fn spawn(v: &Vertex, wi: Vec3) -> Ray {
        let n = if wi.dot(v.ng) >= 0.0 { v.ng } else { -v.ng };
        Ray::new(offset_ray_origin(v.it.p, n), wi)
    }

    fn unoccluded(&self, v: &Vertex, wi: Vec3, target: Target, rays: &mut u64) -> bool {
        *rays += 1;
        let origin = offset_ray_origin(v.it.p, v.ng);
        let ray = match target {
            // Half-open range (0, 1]: the segment ends at the (offset) target.
            Target::Point(q) => Ray::with_range(origin, q - origin, 0.0, 1.0),
            Target::Infinite => Ray::new(origin, wi),
        };
        !self.accel.occluded(&ray)
    }

    /// Light sampling for one light: `n` samples averaged.
    fn sample_light(&self, v: &Vertex, light: &Light, n: u32, rng: &mut Rng, rays: &mut u64) -> Vec3 {
        let f = v.albedo / PI;
        let mut sum = Vec3::ZERO;
        for _ in 0..n {
            let u = rng.uniform2();
            let u_sel = rng.uniform();
            let Some(s) = light.sample(self.scene, v.it.p, u, u_sel) else { continue };
            let cos = s.wi.dot(v.ns);
            if cos <= 0.0 || s.wi.dot(v.ng) <= 0.0 || s.pdf <= 0.0 {
                continue;
            }
            if self.unoccluded(v, s.wi, s.target, rays) {
                sum += f * s.value * cos / s.pdf;
            }
        }
        sum / n as f32
    }

    /// Direct light reflected at `v` towards the previous vertex.
    fn direct(&self, v: &Vertex, rng: &mut Rng, rays: &mut u64) -> Vec3 {
        if v.albedo == Vec3::ZERO {
            return Vec3::ZERO;
        }
        let mut total = Vec3::ZERO;
        if !self.hemisphere {
            for light in &self.lights.lights {
                let n = if light.is_delta() { 1 } else { self.light_samples };
                total += self.sample_light(v, light, n, rng, rays);
            }
            return total;
        }
        // Lights no ray can hit are sampled explicitly even with -H.
        for light in self.lights.lights.iter().filter(|l| !l.is_visible()) {
            let n = if light.is_delta() { 1 } else { self.light_samples };
            total += self.sample_light(v, light, n, rng, rays);
        }
        // CS184: lights x samples-per-light uniform directions about the normal.
        let visible = self.lights.lights.iter().filter(|l| l.is_visible()).count() as u32;
        let n = visible.max(1) * self.light_samples;
        let frame = Frame::new(v.ns);
        let f = v.albedo / PI;
        let mut sum = Vec3::ZERO;
        for _ in 0..n {
            let (u1, u2) = rng.uniform2();
            let wi = frame.to_world(uniform_hemisphere(u1, u2));
            if wi.dot(v.ng) <= 0.0 {
                continue;
            }
            let cos = wi.dot(v.ns);
            let ray = Self::spawn(v, wi);
            let le = match self.trace(&ray, rays) {
                Some(hit) => emitted(self.scene, &hit, -wi),
                None => self.lights.escaped(wi),
            };
            sum += f * le * cos / UNIFORM_HEMISPHERE_PDF;
        }
        total + sum / n as f32
    }
}

impl Integrator for PathTracer<'_> {
    fn radiance(&self, camera_ray: &Ray, rng: &mut Rng, rays: &mut u64) -> Vec3 {
        let m = self.max_depth;
        let counts = |bounce: u32| self.accumulate || bounce == m;
        let wo = -camera_ray.dir.normalize();
        let Some(it) = self.trace(camera_ray, rays) else {
            return if counts(0) { self.lights.escaped(-wo) } else { Vec3::ZERO };
        };
        let mut l = if counts(0) { emitted(self.scene, &it, wo) } else { Vec3::ZERO };
        if m == 0 {
            return l;
        }
        let mut v = self.vertex(it, wo);
        let mut beta = Vec3::ONE;
        let mut bounce = 1;
        loop {
            if counts(bounce) {
                l += beta * self.direct(&v, rng, rays);
            }
            if bounce == m || v.albedo == Vec3::ZERO {
                break;
            }
            // Diffuse BSDF, cosine-weighted: f cos / pdf = albedo.
            let (u1, u2) = rng.uniform2();
            let wi = Frame::new(v.ns).to_world(cosine_hemisphere(u1, u2));
            if wi.dot(v.ng) <= 0.0 {
                break; // below the geometric surface: no light goes that way
            }
            beta *= v.albedo;
            // Russian roulette, from the second indirect bounce on (CS184 always
            // traces one). Continuing with probability max(beta) keeps the
            // weights of surviving paths near 1, so dark paths, which would add
            // little, are the ones cut, and no path's weight can blow up as it
            // can with a constant probability.
            if self.russian_roulette && bounce >= 2 {
                let q = beta.max_element().min(1.0);
                if q <= 0.0 || rng.uniform() >= q {
                    break;
                }
                beta /= q;
            }
            let ray = Self::spawn(&v, wi);
            let Some(next) = self.trace(&ray, rays) else { break };
            v = self.vertex(next, -wi);
            bounce += 1;
        }
        l
    }
}
