//! Normal shading: the shading normal mapped to a colour, `n * 0.5 + 0.5`.

use super::Integrator;
use crate::accel::{Hit, Traversal};
use crate::ray::Ray;
use crate::sampler::Sampler;
use crate::scene::{Interaction, Scene};
use glam::Vec3;

pub struct NormalShading<'a> {
    pub scene: &'a Scene,
}

impl Integrator for NormalShading<'_> {
    fn radiance_from(&self, _accel: &dyn Traversal, ray: &Ray, hit: Option<Hit>, _sampler: &mut Sampler, _rays: &mut u64) -> Vec3 {
        match hit {
            Some(hit) => Interaction::new(self.scene, ray, &hit).ns * 0.5 + Vec3::splat(0.5),
            None => Vec3::ZERO,
        }
    }
}
