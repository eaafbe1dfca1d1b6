//! An emissive sphere (a CGL sphere whose material emits), emitting
//! outward. Sampled by its cone from outside (`sphere_cone`), else by area
//! (CS184's way).

use super::emission::{Emission, World};
use super::emitter::{area_sample, area_to_solid_angle, cosine_emission, solid_angle_sample, solid_angle_to_area, Emitter};
use super::sphere_cone::SphereCone;
use super::{EnvAt, LightSample};
use crate::color::illuminance;
use crate::sampling::uniform_sphere;
use crate::scene::Scene;
use glam::Vec3;
use std::f32::consts::PI;

#[derive(Clone, Debug)]
pub struct SphereLight {
    pub center: Vec3,
    pub radius: f32,
    pub radiance: Vec3,
    /// Sampled by its cone from outside.
    pub cone: bool,
}

impl SphereLight {
    fn area(&self) -> f32 {
        4.0 * PI * self.radius * self.radius
    }

    /// The cone it subtends from `p`, where sampling by it is on.
    fn cone_from(&self, p: Vec3) -> Option<SphereCone> {
        SphereCone::new(p, self.center, self.radius).filter(|_| self.cone)
    }
}

impl Emitter for SphereLight {
    fn describe(&self) -> String {
        format!("emissive sphere at {} r {} radiance {}", self.center, self.radius, self.radiance)
    }

    fn is_visible(&self) -> bool {
        true
    }

    fn is_hittable(&self) -> bool {
        true
    }

    fn sample(&self, _scene: &Scene, p: Vec3, u: (f32, f32), _u_sel: f32, _env_at: EnvAt) -> Option<LightSample> {
        let mag = self.center.abs().max_element() + self.radius;
        if let Some(cone) = self.cone_from(p) {
            let (_, q) = cone.sample(u);
            let n = (q - self.center).normalize_or_zero();
            return solid_angle_sample(p, q, n, mag, self.radiance, cone.pdf());
        }
        let n = uniform_sphere(u.0, u.1);
        let q = self.center + n * self.radius;
        area_sample(p, q, n, mag, self.radiance, 1.0 / self.area())
    }

    /// The same choice `sample` makes from `p`.
    fn pdf_hit(&self, _scene: &Scene, p: Vec3, x: Vec3, n: Vec3, _prim: u32) -> f32 {
        if let Some(cone) = self.cone_from(p) {
            return cone.pdf();
        }
        area_to_solid_angle(1.0 / self.area(), p, x, n)
    }

    fn covers(&self, p: Vec3) -> bool {
        self.cone_from(p).is_some()
    }

    fn power(&self, _world: &World) -> f32 {
        PI * 4.0 * PI * self.radius * self.radius * illuminance(self.radiance).max(0.0)
    }

    fn emission_pdf_pos(&self, _world: &World) -> f32 {
        1.0 / self.area()
    }

    fn emission_pdf_dir(&self, n: Vec3, dir: Vec3) -> f32 {
        n.dot(dir).max(0.0) / PI
    }

    fn sample_pdf_area(&self, scene: &Scene, p: Vec3, q: Vec3, n: Vec3, prim: u32) -> f32 {
        solid_angle_to_area(self.pdf_hit(scene, p, q, n, prim), p, q, n)
    }

    fn normal_at(&self, _scene: &Scene, q: Vec3, _prim: u32) -> Vec3 {
        (q - self.center).normalize_or_zero()
    }

    fn emit(&self, _scene: &Scene, world: &World, _u_sel: f32, u_pos: (f32, f32), u_dir: (f32, f32)) -> Option<Emission> {
        let n = uniform_sphere(u_pos.0, u_pos.1);
        cosine_emission(self.center + n * self.radius, n, self.radiance, self.center.abs().max_element() + self.radius, 0, self.emission_pdf_pos(world), u_dir)
    }

    fn use_cs184_sampling(&mut self, by_area: bool, _uniform_sky: bool) {
        if by_area {
            self.cone = false;
        }
    }

    fn pick_estimate(&self, p: Vec3, n: Vec3) -> Option<f32> {
        let d = self.center - p;
        let r2 = d.length_squared();
        Some(if r2 > 0.0 { illuminance(self.radiance) * PI * self.radius * self.radius * n.dot(d / r2.sqrt()).max(0.0) / r2 } else { 0.0 })
    }
}
