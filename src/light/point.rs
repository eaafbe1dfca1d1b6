//! A point light: CS184's `<point>` light, whose colour is its intensity I,
//! falling off as I/r² (CS184 parses an attenuation and ignores it, so its
//! point lights do not fall off; see the deviations table). Emits uniformly
//! in every direction.

use super::emission::{Emission, World};
use super::emitter::Emitter;
use super::{EnvAt, LightSample, Target};
use crate::color::illuminance;
use crate::sampling::{offset_ray_origin, uniform_sphere};
use crate::scene::Scene;
use glam::Vec3;
use std::f32::consts::PI;

#[derive(Clone, Debug)]
pub struct PointLight {
    pub position: Vec3,
    pub intensity: Vec3,
}

impl Emitter for PointLight {
    fn describe(&self) -> String {
        format!("point at {} intensity {}", self.position, self.intensity)
    }

    fn is_delta(&self) -> bool {
        true
    }

    fn sample(&self, _scene: &Scene, p: Vec3, _u: (f32, f32), _u_sel: f32, _env_at: EnvAt) -> Option<LightSample> {
        let d = self.position - p;
        let r2 = d.length_squared();
        // The shadow ray stops short of the light: by OFFSET_ULPS ulps of its
        // position, as for area lights, and by at least 2^-13 of the
        // distance. A point light sitting on a surface (CBempty's lies in
        // the plane of its emissive quad) is then not shadowed by that
        // surface, whatever the rounding of a grazing shadow ray; Mitsuba
        // and Cycles stop short by a similar relative margin.
        (r2 > 0.0).then(|| {
            let dist = r2.sqrt();
            let wi = d / dist;
            let near = offset_ray_origin(self.position, -wi, self.position.abs().max_element());
            let target = if (self.position - near).length() < dist / 8192.0 { self.position - wi * (dist / 8192.0) } else { near };
            LightSample { wi, value: self.intensity / r2, pdf: 1.0, target: Target::Point(target), covers: false, prim: 0 }
        })
    }

    fn power(&self, _world: &World) -> f32 {
        4.0 * PI * illuminance(self.intensity).max(0.0)
    }

    fn emission_pdf_pos(&self, _world: &World) -> f32 {
        1.0
    }

    fn emission_pdf_dir(&self, _n: Vec3, _dir: Vec3) -> f32 {
        1.0 / (4.0 * PI)
    }

    fn sample_pdf_area(&self, _scene: &Scene, p: Vec3, q: Vec3, _n: Vec3, _prim: u32) -> f32 {
        if (q - p).length_squared() > 0.0 { 1.0 } else { 0.0 }
    }

    fn emit(&self, _scene: &Scene, _world: &World, _u_sel: f32, _u_pos: (f32, f32), u_dir: (f32, f32)) -> Option<Emission> {
        let dir = uniform_sphere(u_dir.0, u_dir.1);
        Some(Emission { p: self.position, n: Vec3::ZERO, dir, le: self.intensity, pdf_pos: 1.0, pdf_dir: 1.0 / (4.0 * PI), magnitude: self.position.abs().max_element(), prim: 0 })
    }

    fn pick_estimate(&self, p: Vec3, n: Vec3) -> Option<f32> {
        let d = self.position - p;
        let r2 = d.length_squared();
        Some(if r2 > 0.0 { illuminance(self.intensity) * n.dot(d / r2.sqrt()).max(0.0) / r2 } else { 0.0 })
    }
}
