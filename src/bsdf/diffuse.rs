//! Lambertian reflection, two-sided (CS184's DiffuseBSDF): f = albedo/π on
//! the side `wo` lies on, cosine-weighted sampling.

use super::BsdfSample;
use crate::sampling::{cosine_hemisphere, cosine_hemisphere_pdf};
use glam::Vec3;
use std::f32::consts::PI;

#[derive(Clone, Copy, Debug)]
pub struct Diffuse {
    pub albedo: Vec3,
}

impl Diffuse {
    pub fn eval(&self, _wo: Vec3, wi: Vec3) -> Vec3 {
        if wi.z > 0.0 {
            self.albedo / PI
        } else {
            Vec3::ZERO
        }
    }

    pub fn pdf(&self, _wo: Vec3, wi: Vec3) -> f32 {
        cosine_hemisphere_pdf(wi.z)
    }

    pub fn sample(&self, _wo: Vec3, u: (f32, f32)) -> Option<BsdfSample> {
        let wi = cosine_hemisphere(u.0, u.1);
        let pdf = cosine_hemisphere_pdf(wi.z);
        // f cos / pdf = albedo exactly: no rounding from the division.
        (pdf > 0.0).then_some(BsdfSample { wi, weight: self.albedo, pdf, delta: false, radiance_scale: 1.0 })
    }
}
