//! Scattering models, one a file (Mitsuba's plugin layout): what a surface
//! does with light, in the local shading frame.
//!
//! Conventions shared by every model:
//! * the frame's +z is the shading normal turned to the side `wo` lies on,
//!   so `wo.z >= 0` up to shading-normal quirks; `front` says whether that
//!   side is the outside (the side the geometric normal, i.e. the triangle
//!   winding or a sphere's outward normal, points to). Dielectrics need it to
//!   know which way light crosses; one-sided models are black from behind;
//! * `wo` and `wi` both point away from the surface (CS184's convention);
//! * `eval` is f(wo, wi) without the cosine; `pdf` is the solid-angle density
//!   with which `sample` picks `wi` (0 for delta lobes, which `eval` never
//!   sees); `sample` returns the weight f·|cos θi|/pdf directly, so delta
//!   lobes need no infinite pdf;
//! * radiance transport: transmitted radiance is scaled by (η_i/η_t)², as in
//!   pbrt and Mitsuba (see `glass`).

pub mod diffuse;
pub mod fresnel;
pub mod glass;
pub mod microfacet;
pub mod mirror;
pub mod refraction;

pub use diffuse::Diffuse;
pub use glass::Glass;
pub use microfacet::Microfacet;
pub use mirror::Mirror;
pub use refraction::Refraction;

use crate::rng::Rng;
use crate::scene::material;
use glam::Vec3;

/// A direction drawn by `sample`.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// Local direction, away from the surface.
    pub wi: Vec3,
    /// f(wo, wi) |cos θi| / pdf.
    pub weight: Vec3,
    /// Solid-angle pdf of `wi`; for a delta lobe, the probability of picking
    /// that lobe (MIS treats delta samples as weight 1 whatever it is).
    pub pdf: f32,
    pub delta: bool,
    /// (η_i/η_t)², the radiance scaling a transmission applied to `weight`
    /// (1 for reflection). Russian roulette divides it back out, so paths
    /// inside glass are not cut for the η² their weight carries until
    /// they leave (pbrt-v4's etaScale).
    pub radiance_scale: f32,
}

/// The scattering model at one surface point.
#[derive(Clone, Copy, Debug)]
pub enum Bsdf {
    Diffuse(Diffuse),
    Mirror(Mirror),
    Glass(Glass),
    Refraction(Refraction),
    Microfacet(Microfacet),
}

impl Bsdf {
    /// The model of `m` seen from the outside (`front`) or the inside;
    /// `None` for materials that do not scatter (emitters: CS184's
    /// EmissionBSDF has f = 0).
    pub fn of(m: &material::Surface, front: bool) -> Option<Bsdf> {
        Some(match *m {
            material::Surface::Diffuse { albedo } => {
                if albedo == Vec3::ZERO {
                    return None;
                }
                Bsdf::Diffuse(Diffuse { albedo })
            }
            material::Surface::Emission { .. } => return None,
            material::Surface::Mirror { reflectance } => Bsdf::Mirror(Mirror { reflectance }),
            material::Surface::Glass { reflectance, transmittance, ior, .. } => Bsdf::Glass(Glass { reflectance, transmittance, ior, front }),
            material::Surface::Refraction { transmittance, ior, .. } => Bsdf::Refraction(Refraction { transmittance, ior, front }),
            material::Surface::Microfacet { alpha, eta, k } => Bsdf::Microfacet(Microfacet { alpha, eta, k, front }),
        })
    }

    /// Whether every lobe is a delta (no light sampling can help).
    pub fn is_delta(&self) -> bool {
        matches!(self, Bsdf::Mirror(_) | Bsdf::Glass(_) | Bsdf::Refraction(_))
    }

    /// Whether light can cross the surface (a dielectric).
    pub fn transmits(&self) -> bool {
        matches!(self, Bsdf::Glass(_) | Bsdf::Refraction(_))
    }

    /// f(wo, wi), without the cosine; 0 for delta models.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        match self {
            Bsdf::Diffuse(b) => b.eval(wo, wi),
            Bsdf::Microfacet(b) => b.eval(wo, wi),
            Bsdf::Mirror(_) | Bsdf::Glass(_) | Bsdf::Refraction(_) => Vec3::ZERO,
        }
    }

    /// Solid-angle pdf of `sample` picking `wi`; 0 for delta models.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        match self {
            Bsdf::Diffuse(b) => b.pdf(wo, wi),
            Bsdf::Microfacet(b) => b.pdf(wo, wi),
            Bsdf::Mirror(_) | Bsdf::Glass(_) | Bsdf::Refraction(_) => 0.0,
        }
    }

    /// Draw `wi` for `wo`; `None` when the path ends (absorbed, total
    /// internal reflection in CS184's `<refraction>`, a sample below the
    /// surface of a one-sided model).
    pub fn sample(&self, wo: Vec3, rng: &mut Rng) -> Option<BsdfSample> {
        match self {
            Bsdf::Diffuse(b) => b.sample(wo, rng.uniform2()),
            Bsdf::Mirror(b) => b.sample(wo),
            Bsdf::Glass(b) => b.sample(wo, rng.uniform()),
            Bsdf::Refraction(b) => b.sample(wo),
            Bsdf::Microfacet(b) => b.sample(wo, rng.uniform2()),
        }
    }

    /// The lobes of a model that picks between two delta lobes (glass:
    /// reflection and transmission), each with the probability `sample`
    /// picks it in `pdf`, for an integrator that follows both (splitting:
    /// each branch's throughput is `weight × pdf`); `None` for every other
    /// model.
    pub fn delta_lobes(&self, wo: Vec3) -> Option<[Option<BsdfSample>; 2]> {
        match self {
            Bsdf::Glass(b) => Some(b.lobes(wo)),
            _ => None,
        }
    }

    /// Which numbers `sample_with` uses: (the lobe choice, the 2D draw).
    pub fn draws(&self) -> (bool, bool) {
        match self {
            Bsdf::Diffuse(_) | Bsdf::Microfacet(_) => (false, true),
            Bsdf::Glass(_) => (true, false),
            Bsdf::Mirror(_) | Bsdf::Refraction(_) => (false, false),
        }
    }

    /// `sample` with the numbers given: `lobe` picks between reflection and
    /// transmission (glass), `u` is the direction's 2D draw; each model uses
    /// only what it needs, so the integrator can give both fixed slots.
    pub fn sample_with(&self, wo: Vec3, lobe: f32, u: (f32, f32)) -> Option<BsdfSample> {
        debug_assert!(lobe >= 0.0 && u.0 >= 0.0);
        match self {
            Bsdf::Diffuse(b) => b.sample(wo, u),
            Bsdf::Mirror(b) => b.sample(wo),
            Bsdf::Glass(b) => b.sample(wo, lobe),
            Bsdf::Refraction(b) => b.sample(wo),
            Bsdf::Microfacet(b) => b.sample(wo, u),
        }
    }
}

/// η_t / η_i for light crossing a dielectric of index `ior` from `wo`'s
/// side: from outside (`front`) into it, or from inside out.
#[inline]
pub fn relative_eta(ior: f32, front: bool) -> f32 {
    if front {
        ior
    } else {
        1.0 / ior
    }
}

/// Mirror `w` about the local normal.
#[inline]
pub fn reflect(w: Vec3) -> Vec3 {
    Vec3::new(-w.x, -w.y, w.z)
}

/// Refract `wo` (local, `wo.z > 0`) through the local normal with relative
/// index `eta` = η_t/η_i (η_i on wo's side): `None` under total internal
/// reflection. The result lies below the surface.
#[inline]
pub fn refract(wo: Vec3, eta: f32) -> Option<Vec3> {
    let cos_t = fresnel::cos_transmitted(wo.z, eta)?;
    Some(Vec3::new(-wo.x / eta, -wo.y / eta, -cos_t))
}

#[cfg(test)]
pub(crate) mod tests;
