//! Emission sampling: rays leaving a light, for the integrators that trace
//! from the lights (bidirectional path tracing, light tracing).
//!
//! Model (pbrt-v4's `SampleLe`/`PDF_Le`, the same for every integrator):
//! * emissive meshes, emissive spheres and proxy-less rectangles: a point
//!   uniform in area (a mesh's triangle picked by area), then a direction
//!   cosine-distributed about the geometric normal on the emitting side
//!   (emission is one-sided, see `light`): pdf_pos = 1/area, pdf_dir = cos/π;
//! * point lights: the light's position (a delta in position, pdf_pos = 1)
//!   and a uniform direction, pdf_dir = 1/(4π);
//! * lights at infinity (directional, hemisphere, environment map): a
//!   direction toward the light drawn as next-event estimation draws it
//!   (`Light::sample`: the map's importance sampling, uniform over the
//!   hemisphere, the directional light's one direction), then a point
//!   uniform on the disk of the scene's bounding sphere facing it
//!   (`World`), the ray leaving that disk into the scene: pdf_pos =
//!   1/(πR²) per area of the disk, pdf_dir = the direction's density (1 for
//!   the directional light's delta), as pbrt-v4's `SampleLe` for distant
//!   and infinite lights.
//!
//! Which light emits is chosen in proportion to its power (`LightPower`),
//! independent of position, as pbrt-v4's `PowerLightSampler`: the same
//! choice starts light subpaths and picks the light of a next-event
//! connection, so both strategies' densities agree in the MIS weights.

use super::{EnvAt, Light};
use crate::sampling::{concentric_disk, Frame};
use std::f32::consts::PI;
use crate::scene::Scene;
use glam::Vec3;

/// A ray leaving a light.
#[derive(Clone, Copy, Debug)]
pub struct Emission {
    /// Where it leaves: on the emitter's surface, or the point light.
    pub p: Vec3,
    /// The emitting side's unit normal (zero for a point light).
    pub n: Vec3,
    /// Unit direction.
    pub dir: Vec3,
    /// Radiance along `dir` (area lights) or intensity (point lights).
    pub le: Vec3,
    /// Area density of `p` (1 for a point light: a delta in position).
    pub pdf_pos: f32,
    /// Solid-angle density of `dir` given `p`.
    pub pdf_dir: f32,
    /// Largest coordinate magnitude of the emitting primitive, for ray offsets.
    pub magnitude: f32,
    /// The primitive `p` lies on (a mesh's triangle; 0 otherwise).
    pub prim: u32,
}

/// The scene's bounding sphere, which rays from lights at infinity enter
/// through.
#[derive(Clone, Copy, Debug)]
pub struct World {
    pub center: Vec3,
    pub radius: f32,
}

impl World {
    pub fn of(scene: &Scene) -> World {
        let b = scene.bounds();
        let radius = (b.extent().length() * 0.5).max(1e-3);
        World { center: b.center(), radius: if radius.is_finite() { radius } else { 1.0 } }
    }

    /// Area density of a point uniform on the disk facing a direction.
    pub fn disk_pdf(&self) -> f32 {
        1.0 / (PI * self.radius * self.radius)
    }
}

impl Light {
    /// Whether this light lies at infinity (directional, hemisphere,
    /// environment map): rays from it start on the `World` disk.
    pub fn is_at_infinity(&self) -> bool {
        self.kind().is_at_infinity()
    }

    /// For a light at infinity, the solid-angle density with which
    /// `sample_emission` (and next-event estimation) picks direction
    /// `to_light`; 1 for the directional light's delta.
    pub fn infinite_pdf_dir(&self, to_light: Vec3) -> f32 {
        self.kind().infinite_pdf_dir(to_light)
    }

    /// Whether a ray can hit this light (an emissive surface of the scene):
    /// a camera path can then find it by chance, the strategy `s = 0`.
    pub fn is_hittable(&self) -> bool {
        self.kind().is_hittable()
    }

    /// The scene geometry this light is (an emissive mesh's id), or
    /// `u32::MAX` for lights that are not a mesh.
    pub fn geometry(&self) -> u32 {
        self.kind().geometry()
    }

    /// Emitted power (luminance-weighted): what the light choice is
    /// proportional to. Lights at infinity: the power entering the scene's
    /// bounding sphere, πR² × irradiance (directional) or × ∫L dω.
    pub fn power(&self, world: &World) -> f32 {
        self.kind().power(world)
    }

    /// Area density with which `sample_emission` picks its points (1 for a
    /// point light; per area of the `World` disk for lights at infinity).
    pub fn emission_pdf_pos(&self, world: &World) -> f32 {
        self.kind().emission_pdf_pos(world)
    }

    /// Solid-angle density of `sample_emission` sending `dir` from a point
    /// whose emitting normal is `n` (lights at finite distance).
    pub fn emission_pdf_dir(&self, n: Vec3, dir: Vec3) -> f32 {
        self.kind().emission_pdf_dir(n, dir)
    }

    /// The area density (at `q`, normal `n`, on primitive `prim`) with
    /// which a light sample from `p` (`Light::sample`: by solid angle where
    /// it can) picks `q`; for a point light its position density, 1.
    pub fn sample_pdf_area(&self, scene: &Scene, p: Vec3, q: Vec3, n: Vec3, prim: u32) -> f32 {
        self.kind().sample_pdf_area(scene, p, q, n, prim)
    }

    /// The unit normal of this light's emitting side at `q`, a point a light
    /// sample (`Light::sample`, on primitive `prim`) chose; zero for a point light.
    pub fn normal_at(&self, scene: &Scene, q: Vec3, prim: u32) -> Vec3 {
        self.kind().normal_at(scene, q, prim)
    }

    /// A ray leaving this light: `u_sel` picks a mesh's triangle, `u_pos`
    /// the point, `u_dir` the direction. `None` for a degenerate draw. A
    /// light at infinity's ray starts on the `World` disk facing the drawn
    /// direction, `n` zero.
    pub fn sample_emission(&self, scene: &Scene, world: &World, u_sel: f32, u_pos: (f32, f32), u_dir: (f32, f32)) -> Option<Emission> {
        if !self.is_at_infinity() {
            return self.kind().emit(scene, world, u_sel, u_pos, u_dir);
        }
        let ls = self.sample(scene, world.center, u_dir, u_sel, EnvAt::Map)?;
        let to_light = ls.wi;
        if !(ls.pdf > 0.0) || ls.value == Vec3::ZERO {
            return None;
        }
        let (dx, dy) = concentric_disk(u_pos);
        let f = Frame::new(to_light);
        let p = world.center + world.radius * (to_light + f.to_world(Vec3::new(dx, dy, 0.0)));
        Some(Emission { p, n: Vec3::ZERO, dir: -to_light, le: ls.value, pdf_pos: world.disk_pdf(), pdf_dir: ls.pdf, magnitude: p.abs().max_element(), prim: 0 })
    }
}

/// The choice of the emitting light, in proportion to power.
#[derive(Clone, Debug)]
pub struct LightPower {
    /// Running sums of the lights' powers.
    cdf: Vec<f32>,
    total: f32,
    world: World,
}

impl LightPower {
    pub fn new(lights: &[Light], world: World) -> LightPower {
        let mut acc = 0.0f32;
        let cdf = lights
            .iter()
            .map(|l| {
                let p = l.power(&world);
                if p.is_finite() && p > 0.0 {
                    acc += p;
                }
                acc
            })
            .collect();
        LightPower { cdf, total: acc, world }
    }

    /// The bounding sphere rays from lights at infinity enter through.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// Whether any light emits.
    pub fn is_empty(&self) -> bool {
        !(self.total > 0.0)
    }

    /// The light `u` picks, and the probability of picking it.
    pub fn pick(&self, u: f32) -> Option<(usize, f32)> {
        if self.is_empty() {
            return None;
        }
        let k = self.cdf.partition_point(|&c| c <= u * self.total).min(self.cdf.len() - 1);
        let pmf = self.pmf(k);
        (pmf > 0.0).then_some((k, pmf))
    }

    /// The probability of picking light `k`.
    pub fn pmf(&self, k: usize) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let lo = if k == 0 { 0.0 } else { self.cdf[k - 1] };
        (self.cdf[k] - lo) / self.total
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn emission_densities_match_the_draws() {
        // A unit-square rectangle facing +z: every draw lies on it, faces
        // its side, and reports the densities `emission_pdf_*` give.
        let l = Light::Rect(super::super::RectLight { corner: Vec3::ZERO, ex: Vec3::X * 2.0, ey: Vec3::Y, normal: Vec3::Z, radiance: Vec3::ONE, solid_angle: None });
        let scene = crate::scene::builtin::load().unwrap();
        for i in 0..64 {
            let u = |k: u32| ((i * 7 + k * 13) % 64) as f32 / 64.0 + 1.0 / 128.0;
            let e = l.sample_emission(&scene, &World::of(&scene), 0.5, (u(0), u(1)), (u(2), u(3))).unwrap();
            assert!(e.p.x >= 0.0 && e.p.x <= 2.0 && e.p.y >= 0.0 && e.p.y <= 1.0 && e.p.z == 0.0);
            assert!(e.dir.z > 0.0 && (e.dir.length() - 1.0).abs() < 1e-5);
            assert_eq!(e.pdf_pos, 0.5);
            assert!((e.pdf_dir - l.emission_pdf_dir(e.n, e.dir)).abs() < 1e-5);
        }
        assert_eq!(l.emission_pdf_dir(Vec3::Z, -Vec3::Z), 0.0);
    }

    #[test]
    fn lights_are_picked_by_power() {
        let lights = vec![
            Light::Point(super::super::PointLight { position: Vec3::ZERO, intensity: Vec3::ONE }),
            Light::Directional(super::super::DirectionalLight { to_light: Vec3::Y, irradiance: Vec3::ONE }),
            Light::Sphere(super::super::SphereLight { center: Vec3::ZERO, radius: 1.0, radiance: Vec3::ONE, cone: true }),
        ];
        let world = World { center: Vec3::ZERO, radius: 2.0 };
        let p = LightPower::new(&lights, world);
        // Point: 4π; directional: its irradiance over the world's disk, 4π;
        // sphere: 4π².
        let (a, d, b) = (4.0 * PI, 4.0 * PI, 4.0 * PI * PI);
        let total = a + d + b;
        assert!((p.pmf(0) - a / total).abs() < 1e-6 && (p.pmf(1) - d / total).abs() < 1e-6 && (p.pmf(2) - b / total).abs() < 1e-6);
        assert_eq!(p.pick(0.0).unwrap().0, 0);
        assert_eq!(p.pick(0.99).unwrap().0, 2);
        let dark = [Light::Point(super::super::PointLight { position: Vec3::ZERO, intensity: Vec3::ZERO })];
        assert!(LightPower::new(&dark, world).pick(0.5).is_none());
    }
}
