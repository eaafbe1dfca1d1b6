//! Materials as the CS184 files describe them.
//!
//! Every CGL material is parsed and kept; which ones an integrator can render
//! is decided by the integrator, which refuses the others by name.

use glam::Vec3;

#[derive(Clone, Debug, PartialEq)]
pub enum Bsdf {
    Diffuse { albedo: Vec3 },
    Emission { radiance: Vec3 },
    Mirror { reflectance: Vec3 },
    Glass { reflectance: Vec3, transmittance: Vec3, roughness: f32, ior: f32 },
    Refraction { transmittance: Vec3, roughness: f32, ior: f32 },
    Microfacet { alpha: f32, eta: Vec3, k: Vec3 },
}

impl Bsdf {
    pub fn kind(&self) -> &'static str {
        match self {
            Bsdf::Diffuse { .. } => "diffuse",
            Bsdf::Emission { .. } => "emission",
            Bsdf::Mirror { .. } => "mirror",
            Bsdf::Glass { .. } => "glass",
            Bsdf::Refraction { .. } => "refraction",
            Bsdf::Microfacet { .. } => "microfacet",
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// The COLLADA material id (or `default` for CS184's diffuse 0.5).
    pub name: String,
    pub bsdf: Bsdf,
    /// Radiance emitted (one-sided, see `light`). CS184 files only give it to
    /// `<emission>` materials, which do not reflect; scenes built in code may
    /// give it to a diffuse surface too (the closed-form furnace tests do).
    pub emission: Vec3,
}

impl Material {
    /// CS184 gives objects with no material, or no diffuse colour, diffuse 0.5.
    pub fn default_diffuse() -> Self {
        Material { name: "default".into(), bsdf: Bsdf::Diffuse { albedo: Vec3::splat(0.5) }, emission: Vec3::ZERO }
    }
}
