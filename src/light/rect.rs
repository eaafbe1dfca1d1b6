//! A CGL area light with no visible emissive proxy: a one-sided rectangle
//! `corner + s*ex + t*ey`, `s, t ∈ [0, 1]`, emitting towards `normal`, not
//! geometry (only light sampling sees it). Sampled by solid angle
//! (`spherical_rect`, when its edges are orthogonal) where it subtends
//! enough, else by area (CS184's way).

use super::emission::{Emission, World};
use super::emitter::{area_sample, cosine_emission, solid_angle_sample, solid_angle_to_area, Emitter};
use super::spherical_rect::RectEmitter;
use super::{EnvAt, LightSample};
use crate::color::illuminance;
use crate::sampling::magnitude;
use crate::scene::Scene;
use glam::Vec3;
use std::f32::consts::PI;

#[derive(Clone, Debug)]
pub struct RectLight {
    pub corner: Vec3,
    pub ex: Vec3,
    pub ey: Vec3,
    pub normal: Vec3,
    pub radiance: Vec3,
    /// The rectangle as `RectEmitter`, when its edges are orthogonal and
    /// sampling by solid angle is on.
    pub solid_angle: Option<RectEmitter>,
}

impl RectLight {
    fn area(&self) -> f32 {
        self.ex.cross(self.ey).length()
    }

    fn corners(&self) -> [Vec3; 4] {
        let c = self.corner;
        [c, c + self.ex + self.ey, c + self.ex, c + self.ey]
    }
}

impl Emitter for RectLight {
    fn describe(&self) -> String {
        format!("rectangle at {} {}x{} radiance {}", self.corner, self.ex.length(), self.ey.length(), self.radiance)
    }

    fn sample(&self, _scene: &Scene, p: Vec3, u: (f32, f32), _u_sel: f32, _env_at: EnvAt) -> Option<LightSample> {
        if let Some(sr) = self.solid_angle.and_then(|r| r.from(p)) {
            return solid_angle_sample(p, sr.sample(u), self.normal, magnitude(&[self.corner, self.corner + self.ex + self.ey]), self.radiance, 1.0 / sr.omega);
        }
        let q = self.corner + self.ex * u.0 + self.ey * u.1;
        area_sample(p, q, self.normal, magnitude(&self.corners()), self.radiance, 1.0 / self.area())
    }

    fn power(&self, _world: &World) -> f32 {
        PI * self.area() * illuminance(self.radiance).max(0.0)
    }

    fn emission_pdf_pos(&self, _world: &World) -> f32 {
        1.0 / self.area()
    }

    fn emission_pdf_dir(&self, n: Vec3, dir: Vec3) -> f32 {
        n.dot(dir).max(0.0) / PI
    }

    fn sample_pdf_area(&self, _scene: &Scene, p: Vec3, q: Vec3, n: Vec3, _prim: u32) -> f32 {
        if !((q - p).length_squared() > 0.0) {
            return 0.0;
        }
        match self.solid_angle.and_then(|r| r.from(p)) {
            Some(sr) => solid_angle_to_area(1.0 / sr.omega, p, q, n),
            None => 1.0 / self.area(),
        }
    }

    fn normal_at(&self, _scene: &Scene, _q: Vec3, _prim: u32) -> Vec3 {
        self.normal
    }

    fn emit(&self, _scene: &Scene, world: &World, _u_sel: f32, u_pos: (f32, f32), u_dir: (f32, f32)) -> Option<Emission> {
        let p = self.corner + self.ex * u_pos.0 + self.ey * u_pos.1;
        cosine_emission(p, self.normal, self.radiance, magnitude(&self.corners()), 0, self.emission_pdf_pos(world), u_dir)
    }

    fn use_cs184_sampling(&mut self, by_area: bool, _uniform_sky: bool) {
        if by_area {
            self.solid_angle = None;
        }
    }

    fn pick_estimate(&self, p: Vec3, n: Vec3) -> Option<f32> {
        Some(super::pick::patch(p, n, self.corner + 0.5 * (self.ex + self.ey), self.area(), Some(self.normal), self.radiance))
    }
}
