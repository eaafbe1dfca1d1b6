//! CS184's `<refraction>`: a smooth interface that transmits everything, with
//! no Fresnel reflection, scaled by `transmittance`; total internal
//! reflection ends the path (as in CS184, and Cycles' sharp Refraction BSDF).
//!
//! Differs from CS184 only in the radiance scaling: we multiply by
//! (η_i/η_t)² (pbrt, Mitsuba; see `glass`), CS184 by its inverse. For light
//! sources outside closed refracting objects both give the same image.

use super::{refract, relative_eta, BsdfSample};
use glam::Vec3;

#[derive(Clone, Copy, Debug)]
pub struct Refraction {
    pub transmittance: Vec3,
    pub ior: f32,
    /// Whether `wo` is outside (η_i = 1, η_t = ior) or inside.
    pub front: bool,
}

impl Refraction {
    pub fn sample(&self, wo: Vec3) -> Option<BsdfSample> {
        let eta = relative_eta(self.ior, self.front);
        let wi = refract(wo, eta)?;
        let weight = self.transmittance / (eta * eta);
        (weight != Vec3::ZERO).then_some(BsdfSample { wi, weight, pdf: 1.0, delta: true, radiance_scale: 1.0 / (eta * eta) })
    }
}
