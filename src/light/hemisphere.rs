//! The hemisphere light (CS184's "ambient"): uniform radiance over the
//! upper (+y) hemisphere of directions, seen by every ray that escapes
//! upwards (CS184 only samples it; its escaping rays see black). Sampled
//! uniformly over the hemisphere, or by the lune at diffuse vertices
//! (`lune`; the path tracer's `direct`).

use super::emission::World;
use super::emitter::Emitter;
use super::{EnvAt, LightSample, Target};
use crate::color::illuminance;
use crate::sampling::{uniform_hemisphere, UNIFORM_HEMISPHERE_PDF};
use crate::scene::Scene;
use glam::Vec3;
use std::f32::consts::PI;

#[derive(Clone, Debug)]
pub struct HemisphereLight {
    pub radiance: Vec3,
    /// Sampled by the lune (the clipped cosine) at diffuse vertices.
    pub lune: bool,
}

impl Emitter for HemisphereLight {
    fn describe(&self) -> String {
        format!("hemisphere (+y) radiance {}", self.radiance)
    }

    fn is_visible(&self) -> bool {
        true
    }

    fn is_at_infinity(&self) -> bool {
        true
    }

    fn sample(&self, _scene: &Scene, _p: Vec3, u: (f32, f32), _u_sel: f32, _env_at: EnvAt) -> Option<LightSample> {
        // Uniform over the upper hemisphere: local z maps to world +y.
        let l = uniform_hemisphere(u.0, u.1);
        let wi = Vec3::new(l.x, l.z, -l.y);
        Some(LightSample { wi, value: self.radiance, pdf: UNIFORM_HEMISPHERE_PDF, target: Target::Infinite, covers: false, prim: 0 })
    }

    fn escaped(&self, dir: Vec3) -> Vec3 {
        if dir.y > 0.0 { self.radiance } else { Vec3::ZERO }
    }

    fn pdf_escape(&self, dir: Vec3, _env_at: EnvAt) -> f32 {
        if dir.y > 0.0 { UNIFORM_HEMISPHERE_PDF } else { 0.0 }
    }

    /// The power entering the scene's bounding sphere: πR² × ∫L dω.
    fn power(&self, world: &World) -> f32 {
        2.0 * PI * illuminance(self.radiance).max(0.0) / world.disk_pdf()
    }

    fn use_cs184_sampling(&mut self, _by_area: bool, uniform_sky: bool) {
        if uniform_sky {
            self.lune = false;
        }
    }
}
