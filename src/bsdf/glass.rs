//! CS184's `<glass>`: a smooth dielectric interface that reflects with the
//! exact Fresnel reflectance F (scaled by `reflectance`) and transmits 1 − F
//! (scaled by `transmittance`); total internal reflection reflects
//! everything. Both lobes are deltas; `sample` picks one with probability
//! F and 1 − F, so the weight is the multiplier alone.
//!
//! Differences from CS184 (docs/guide/cs184-users.md's table):
//! * exact Fresnel, not Schlick at the outside angle: inside the glass near
//!   the critical angle Schlick gives 0.035 where the truth is 0.43;
//! * radiance scaling: transmitted radiance is multiplied by (η_i/η_t)²,
//!   where η_i is the index on `wo`'s side (pbrt-v4, Mitsuba 3 in radiance
//!   mode): radiance divided by η² is what is conserved along a ray, so a
//!   camera inside glass sees a light outside η² times brighter. CS184
//!   multiplies by the inverse. A path from a light outside a closed glass
//!   object to a camera outside crosses in as often as out, so the factors
//!   cancel and every convention gives the same image (tested: a closed
//!   glass sphere in a uniform environment renders the environment).
//! * `roughness` must be 0 (every shipped scene's is): the loader's user
//!   refuses anything else rather than render it smooth.

use super::{fresnel, reflect, refract, relative_eta, BsdfSample};
use glam::Vec3;

#[derive(Clone, Copy, Debug)]
pub struct Glass {
    pub reflectance: Vec3,
    pub transmittance: Vec3,
    pub ior: f32,
    /// Whether `wo` is outside (η_i = 1, η_t = ior) or inside.
    pub front: bool,
}

impl Glass {
    /// η_t / η_i for light crossing from `wo`'s side.
    pub fn eta(&self) -> f32 {
        relative_eta(self.ior, self.front)
    }

    /// Fresnel reflectance for `wo`.
    pub fn fresnel(&self, wo: Vec3) -> f32 {
        fresnel::dielectric(wo.z.abs(), self.eta())
    }

    pub fn sample(&self, wo: Vec3, u: f32) -> Option<BsdfSample> {
        let eta = self.eta();
        let f = self.fresnel(wo);
        if u < f {
            let wi = reflect(wo);
            return (self.reflectance != Vec3::ZERO).then_some(BsdfSample { wi, weight: self.reflectance, pdf: f, delta: true, radiance_scale: 1.0 });
        }
        let wi = refract(wo, eta)?;
        let weight = self.transmittance / (eta * eta);
        (weight != Vec3::ZERO).then_some(BsdfSample { wi, weight, pdf: 1.0 - f, delta: true, radiance_scale: 1.0 / (eta * eta) })
    }

    /// Both lobes `sample` picks from, reflection then transmission, each
    /// with its probability of being picked in `pdf`; `None` for a lobe
    /// that cannot be picked (no reflection at F = 0, no transmission
    /// under total internal reflection) or carries nothing.
    pub fn lobes(&self, wo: Vec3) -> [Option<BsdfSample>; 2] {
        let f = self.fresnel(wo);
        // u = 0 picks reflection whenever F > 0, u = 1 transmission whenever F < 1.
        [if f > 0.0 { self.sample(wo, 0.0) } else { None }, if f < 1.0 { self.sample(wo, 1.0) } else { None }]
    }
}
