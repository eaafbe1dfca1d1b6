//! Materials as the CS184 files describe them.
//!
//! Every CGL material is parsed and kept; which ones an integrator can render
//! is decided by the integrator, which refuses the others by name.

use glam::Vec3;

/// The surface model a CS184 material names, with its parameters: the
/// scene's description, from which `bsdf::Bsdf` makes the scattering
/// functions the integrators evaluate.
#[derive(Clone, Debug, PartialEq)]
pub enum Surface {
    Diffuse { albedo: Vec3 },
    Emission { radiance: Vec3 },
    Mirror { reflectance: Vec3 },
    Glass { reflectance: Vec3, transmittance: Vec3, roughness: f32, ior: f32 },
    Refraction { transmittance: Vec3, roughness: f32, ior: f32 },
    Microfacet { alpha: f32, eta: Vec3, k: Vec3 },
}

impl Surface {
    pub fn kind(&self) -> &'static str {
        match self {
            Surface::Diffuse { .. } => "diffuse",
            Surface::Emission { .. } => "emission",
            Surface::Mirror { .. } => "mirror",
            Surface::Glass { .. } => "glass",
            Surface::Refraction { .. } => "refraction",
            Surface::Microfacet { .. } => "microfacet",
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// The COLLADA material id (or `default` for CS184's diffuse 0.5).
    pub name: String,
    pub surface: Surface,
    /// Radiance emitted (one-sided, see `light`). CS184 files only give it to
    /// `<emission>` materials, which do not reflect; scenes built in code may
    /// give it to a diffuse surface too (the closed-form furnace tests do).
    pub emission: Vec3,
}

impl Material {
    /// CS184 gives objects with no material, or no diffuse colour, diffuse 0.5.
    pub fn default_diffuse() -> Self {
        Material { name: "default".into(), surface: Surface::Diffuse { albedo: Vec3::splat(0.5) }, emission: Vec3::ZERO }
    }
}

impl super::Scene {
    /// The path integrator renders every CGL material with the parameters the
    /// shipped scenes use; anything else (rough glass or refraction, values
    /// outside a model's domain) is refused by name rather than approximated.
    pub fn check_materials(&self) -> crate::error::Result<()> {
        let scene = self;
        for obj in &scene.objects {
            let m = &scene.materials[obj.material];
            let refuse = |why: String| -> crate::error::Result<()> {
                crate::bail!("{}: object '{}' uses material '{}' ({}): {why}", scene.source, obj.name, m.name, m.surface.kind())
            };
            let colour_ok = |c: glam::Vec3| c.is_finite() && c.min_element() >= 0.0;
            match m.surface {
                Surface::Diffuse { albedo } if !colour_ok(albedo) => refuse(format!("diffuse colour {albedo} must be finite and non-negative"))?,
                Surface::Mirror { reflectance } if !colour_ok(reflectance) => refuse(format!("reflectance {reflectance} must be finite and non-negative"))?,
                Surface::Glass { roughness, .. } | Surface::Refraction { roughness, .. } if roughness != 0.0 => {
                    refuse(format!("roughness {roughness} is not supported: only smooth (roughness 0) dielectrics are modelled, as in every CS184 scene"))?
                }
                Surface::Glass { ior, reflectance, transmittance, .. } if !(ior > 0.0 && ior.is_finite() && colour_ok(reflectance) && colour_ok(transmittance)) => {
                    refuse(format!("ior {ior}, reflectance {reflectance}, transmittance {transmittance}: the ior must be positive and the colours non-negative"))?
                }
                Surface::Refraction { ior, transmittance, .. } if !(ior > 0.0 && ior.is_finite() && colour_ok(transmittance)) => {
                    refuse(format!("ior {ior}, transmittance {transmittance}: the ior must be positive and the colour non-negative"))?
                }
                Surface::Microfacet { alpha, eta, k } if !(alpha > 0.0 && alpha.is_finite() && colour_ok(eta) && colour_ok(k)) => {
                    refuse(format!("alpha {alpha}, eta {eta}, k {k}: alpha must be positive and eta, k non-negative"))?
                }
                _ => {}
            }
        }
        Ok(())
    }
}
