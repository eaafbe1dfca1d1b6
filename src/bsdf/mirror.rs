//! A perfect mirror (CS184's MirrorBSDF): all light reflected about the
//! normal, scaled by `reflectance`; two-sided, a delta lobe.
//!
//! Same model as CS184. The integrator differs on `-m 1`: CS184 shows
//! mirrors black there (its one-bounce light sampling sees f = 0); we count
//! the emitter the reflected ray finds, as the references do.

use super::{reflect, BsdfSample};
use glam::Vec3;

#[derive(Clone, Copy, Debug)]
pub struct Mirror {
    pub reflectance: Vec3,
}

impl Mirror {
    pub fn sample(&self, wo: Vec3) -> Option<BsdfSample> {
        let wi = reflect(wo);
        (wi.z > 0.0 && self.reflectance != Vec3::ZERO).then_some(BsdfSample { wi, weight: self.reflectance, pdf: 1.0, delta: true, radiance_scale: 1.0 })
    }
}
