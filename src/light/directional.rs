//! A directional light (CS184's `<directional>`, a Blender sun): colour =
//! irradiance, from one direction at infinity. The direction is the sun's
//! axis, the light travelling along its node's −z (CS184 transforms
//! (0,0,−1) as a point, translation included; see the deviations table).

use super::emission::World;
use super::emitter::Emitter;
use super::{EnvAt, LightSample, Target};
use crate::color::illuminance;
use crate::scene::Scene;
use glam::Vec3;

#[derive(Clone, Debug)]
pub struct DirectionalLight {
    /// Unit direction towards the light.
    pub to_light: Vec3,
    pub irradiance: Vec3,
}

impl Emitter for DirectionalLight {
    fn describe(&self) -> String {
        format!("directional towards {} irradiance {}", self.to_light, self.irradiance)
    }

    fn is_delta(&self) -> bool {
        true
    }

    fn is_at_infinity(&self) -> bool {
        true
    }

    fn sample(&self, _scene: &Scene, _p: Vec3, _u: (f32, f32), _u_sel: f32, _env_at: EnvAt) -> Option<LightSample> {
        Some(LightSample { wi: self.to_light, value: self.irradiance, pdf: 1.0, target: Target::Infinite, covers: false, prim: 0 })
    }

    /// The one direction's delta.
    fn infinite_pdf_dir(&self, _to_light: Vec3) -> f32 {
        1.0
    }

    /// The power entering the scene's bounding sphere: πR² × irradiance.
    fn power(&self, world: &World) -> f32 {
        illuminance(self.irradiance).max(0.0) / world.disk_pdf()
    }

    fn pick_estimate(&self, _p: Vec3, n: Vec3) -> Option<f32> {
        Some(illuminance(self.irradiance) * n.dot(self.to_light).max(0.0))
    }
}
