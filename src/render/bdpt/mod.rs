//! Bidirectional path tracing (`--integrator bdpt`, Veach ch. 10, after
//! pbrt-v4's `BDPTIntegrator`) and light tracing (`--integrator light`, the
//! t = 1 strategies alone, as Mitsuba 3's `ptracer`: like it, blind to what
//! the camera sees in or through mirrors and glass, since no connection
//! can end at a delta vertex).
//!
//! Each pixel sample traces a camera subpath from its camera ray (two or
//! more where the camera sees glass through mirrors and glass alone: it
//! follows both lobes there, `subpath::Branch`) and a light subpath from a
//! light (`subpath`), then joins every prefix of one to every prefix of the
//! other (`connect`): strategy (s, t) uses s light vertices
//! and t camera vertices, a path of s + t − 2 bounces. Each strategy's
//! contribution is weighted against all the others that could have made the
//! same path (`mis`, the power heuristic), so their sum estimates the image.
//! Light-tracing strategies (t = 1) land on whatever pixel their ray meets,
//! as splats (`render::splat`), kept in exact sums so that renders split by
//! samples merge to the bits of one render.
//!
//! `--bdpt-light-paths specular` (`LightPaths::Specular`) keeps only the
//! light subpaths whose first bounce is a mirror or glass: the strategies
//! s ≥ 2 then make only paths L S …, the caustics a path tracer finds badly,
//! the rest is left to s ≤ 1 (next-event estimation and emitters hit, as in
//! a path tracer), and the weights count only the strategies that can make
//! each path (`mis`). Most light subpaths then end after one ray, and only
//! half the pixel samples trace one (`SPECULAR_LIGHT_SHARE`; the strategies
//! s ≥ 2 divide by that share), so a sample costs 1.6–2× a path tracer's
//! where every light subpath costs 5–7× (measured in docs/design/bdpt.md).
//!
//! Conventions shared with the path tracer (`render::path`):
//! * `-m` bounds s + t − 2 (0: emitters seen directly, 1: direct light);
//!   `-o 0` keeps only paths of exactly `-m` bounces;
//! * the same BSDFs and lights, emission one-sided, glass scaling radiance
//!   by (η_i/η_t)² on camera subpaths (and importance unscaled on light
//!   subpaths: `vertex`);
//! * draws addressed by dimension id (`sampler::dim`), so the image does not
//!   depend on threads or on how the samples are split.
//!
//! Differences from pbrt-v4: the power heuristic (`mis`); Veach's adjoint
//! shading-normal correction on light subpaths (pbrt-v4 omits it, which its
//! users found makes BDPT and path tracing disagree); Russian roulette on
//! both subpaths and splitting at glass seen by the camera (`subpath`);
//! next-event points drawn by solid angle (`connect`); exact splats.
//! Lights at infinity (directional, hemisphere, environment map) start
//! light subpaths on the disk of the scene's
//! bounding sphere facing their direction, as in pbrt-v4; the environment
//! map's directions are drawn by its own importance sampling alone (the
//! path tracer's products with the cosine and with glossy lobes are not
//! used here). Not supported, and refused by the command line with a line
//! naming them: adaptive sampling (`-a`: a pixel's
//! stopping rule cannot see the light its neighbours' samples splat into
//! it) and tile splits (a tile's light subpaths light other tiles).
//!
//! CS184 has no bidirectional integrator.

mod connect;
mod mis;
mod subpath;
mod vertex;

use super::splat::Splat;
use super::{Integrator, Region};
use crate::accel::{Hit, Traversal};
use crate::camera::importance::Sensor;
use crate::camera::Camera;
use crate::error::Result;
use crate::light::emission::{LightPower, World};
use crate::light::Lights;
use crate::ray::Ray;
use crate::sampler::{dim, Sampler};
use crate::scene::Scene;
use glam::Vec3;
use smallvec::SmallVec;
use connect::Connection;
use vertex::{Kind, Vertex};

/// A subpath's vertices.
type Path = SmallVec<[Vertex; 8]>;

/// A pixel sample's camera subpaths: one, or the branches of one that split
/// at glass (`subpath::Branch`).
type Paths = SmallVec<[Path; 1]>;

/// Which strategies a render sums.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Technique {
    /// Every strategy, weighted by multiple importance sampling.
    Bidirectional,
    /// Light tracing alone: the strategies (s ≥ 1, t = 1), unweighted.
    LightTracing,
    /// One strategy (s, t) of the bidirectional path tracer, weighted as in
    /// the full sum or not: pbrt-v4's strategy images, for tests and
    /// debugging (`--bdpt-strategy S,T`).
    Strategy { s: usize, t: usize, weighted: bool },
}

/// Which light subpaths go on past their first bounce.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LightPaths {
    /// Every one: all of BDPT's strategies.
    #[default]
    All,
    /// Only those whose first bounce is specular (mirror, glass): the
    /// strategies with s ≥ 2 then make only paths L S …, the caustics, and
    /// the others are left to the camera side (s ≤ 1), as in a path tracer.
    Specular,
}

pub struct Bdpt<'a> {
    scene: &'a Scene,
    lights: &'a Lights,
    camera: Sensor,
    max_depth: u32,
    accumulate: bool,
    technique: Technique,
    power: LightPower,
    /// The frame's size in pixels, where splats land.
    width: u32,
    height: u32,
    /// Pixels rendered ÷ pixels of the frame: light tracing's sample count
    /// per pixel relative to the camera's (see `mis`).
    light_tracing_share: f64,
    /// The lights at infinity that an escaping camera ray sees (hemisphere,
    /// environment map): strategy s = 0 for each.
    sky: Vec<usize>,
    light_paths: LightPaths,
    /// Whether a light no ray can find (point, directional, a CGL area
    /// light without geometry) lights the scene through a mirror or glass
    /// first: its caustics, physical light that a path tracer (ours, or a
    /// reference's) cannot sample, since a path needs a ray to find the
    /// light from a non-specular vertex. On by default; `validate` turns
    /// it off to compare BDPT with the path tracer on the paths both make.
    unseen_light_caustics: bool,
    /// Whether light subpaths can go on past their light point: false
    /// with `LightPaths::Specular` in a scene without mirrors or glass.
    specular_objects: bool,
}

/// `Bdpt::light_share` with specular light paths. Measured against our path
/// tracer at equal time (docs/design/bdpt.md): CBgems 1.11 at 1, 0.78 at
/// 0.5, 0.81 at 0.25; CBspheres `-m 8` 0.61, 0.56, 0.60 (its floor caustic
/// 0.103, 0.106, 0.126).
pub const SPECULAR_LIGHT_SHARE: f32 = 0.5;

impl<'a> Bdpt<'a> {
    /// The integrator for a render of `region` of a `width`×`height` frame.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        scene: &'a Scene,
        lights: &'a Lights,
        camera: &'a Camera,
        width: u32,
        height: u32,
        region: Region,
        max_depth: u32,
        accumulate: bool,
        technique: Technique,
    ) -> Result<Bdpt<'a>> {
        let power = LightPower::new(&lights.lights, World::of(scene));
        let light_tracing_share = (region.w as f64 * region.h as f64) / (width as f64 * height as f64);
        let sky = (0..lights.lights.len()).filter(|&k| lights.lights[k].is_at_infinity() && lights.lights[k].is_visible()).collect();
        Ok(Bdpt { scene, lights, camera: Sensor::of(camera), max_depth, accumulate, technique, power, width, height, light_tracing_share, sky, light_paths: LightPaths::All, unseen_light_caustics: true, specular_objects: true })
    }

    /// The same integrator with `light_paths` for its light subpaths.
    pub fn with_light_paths(self, light_paths: LightPaths) -> Bdpt<'a> {
        let specular_objects = light_paths == LightPaths::All || has_delta_objects(self.scene);
        Bdpt { light_paths, specular_objects, ..self }
    }

    /// The same integrator with or without the caustics of lights no ray
    /// finds (see `unseen_light_caustics`).
    pub fn with_unseen_light_caustics(self, on: bool) -> Bdpt<'a> {
        Bdpt { unseen_light_caustics: on, ..self }
    }

    /// The probability that a pixel sample traces a light subpath (1, or
    /// `SPECULAR_LIGHT_SHARE` with `LightPaths::Specular`): the strategies
    /// s ≥ 2 then have this share of the camera's sample count, in their
    /// contributions (÷ it) and in the MIS weights (`mis`).
    fn light_share(&self) -> f32 {
        match self.light_paths {
            LightPaths::All => 1.0,
            LightPaths::Specular => SPECULAR_LIGHT_SHARE,
        }
    }

    /// Whether strategy (s, t) is summed.
    fn uses(&self, s: usize, t: usize) -> bool {
        let depth = s as i64 + t as i64 - 2;
        if depth < 0 || depth > self.max_depth as i64 || (!self.accumulate && depth != self.max_depth as i64) {
            return false;
        }
        match self.technique {
            Technique::Bidirectional => !(s == 1 && t == 1),
            // And the lights at infinity seen directly (s = 0, t = 2, for
            // escaped camera rays only: see `radiance_splat`).
            Technique::LightTracing => (t == 1 && s >= 1) || (s == 0 && t == 2),
            Technique::Strategy { s: ss, t: tt, .. } => (s, t) == (ss, tt) && !(s == 1 && t == 1),
        }
    }

    fn weighted(&self) -> bool {
        match self.technique {
            Technique::Bidirectional => true,
            Technique::LightTracing => false,
            Technique::Strategy { weighted, .. } => weighted,
        }
    }
}

impl Integrator for Bdpt<'_> {
    fn splats(&self) -> bool {
        true
    }

    fn radiance_from(&self, accel: &dyn Traversal, ray: &Ray, hit: Option<Hit>, sampler: &mut Sampler, rays: &mut u64) -> Vec3 {
        // Without a film for splats, only the camera strategies count.
        self.radiance_splat(accel, ray, hit, sampler, rays, &mut Vec::new())
    }

    fn radiance_splat(&self, accel: &dyn Traversal, ray: &Ray, hit: Option<Hit>, sampler: &mut Sampler, rays: &mut u64, splats: &mut Vec<Splat>) -> Vec3 {
        let m = self.max_depth as usize;
        let camera_vertices = match self.technique {
            // The camera ray's own end, for the lights at infinity it sees.
            Technique::LightTracing => 1 + !self.sky.is_empty() as usize,
            _ => m + 2,
        };
        // On the stack for the usual depths (`-m` up to 6).
        let mut cameras: Paths = Paths::new();
        let mut light: Path = Path::new();
        self.camera_subpaths(accel, ray, hit, sampler, &mut cameras, camera_vertices, rays);
        // Without mirrors or glass, specular light paths make nothing.
        let share = self.light_share();
        if self.specular_objects && (share >= 1.0 || sampler.get_1d(dim::light_vertex(0, dim::EMIT_SHARE)) < share) {
            self.light_subpath(accel, sampler, &mut light, m + 1, rays);
        }
        let light_nee_ratio = if light.len() >= 2 && self.weighted() { self.nee_ratio(&light[0], &light[1]) } else { 1.0 };
        let mut found: SmallVec<[Found; 32]> = SmallVec::new();
        for (branch, camera) in cameras.iter().enumerate() {
            // Light tracing (t = 1) shares only the lens point: once per sample.
            for t in 1 + usize::from(branch > 0)..=camera.len() {
                // Next-event estimation (s = 1) draws its own light point.
                for s in 0..=light.len().max(usize::from(!self.power.is_empty())) {
                    if !self.uses(s, t) {
                        continue;
                    }
                    if s == 0 && camera[t - 1].kind == Kind::Escaped {
                        // One strategy per light at infinity the escape sees.
                        let mut ends: Path = camera[..t].iter().copied().collect();
                        for &k in &self.sky {
                            ends[t - 1].kind = Kind::Distant(k);
                            // No shadow ray: weighted here, against these ends.
                            found.extend(self.connect(&light, &ends, s, t, sampler).map(|c| {
                                let w = self.weight(&light, &ends, &c, s, t, light_nee_ratio);
                                Found { c: Connection { value: c.value * w, ..c }, s, t, branch, weighted: true }
                            }));
                        }
                        continue;
                    }
                    if s == 0 && self.technique == Technique::LightTracing {
                        // Emitters the camera ray hits are light tracing's (s = 1, t = 1).
                        continue;
                    }
                    found.extend(self.connect(&light, camera, s, t, sampler).map(|c| Found { c, s, t, branch, weighted: false }));
                }
            }
        }
        self.gather(accel, &mut found, &light, &cameras, light_nee_ratio, rays, splats)
    }
}

/// Whether some object of `scene` scatters by delta lobes alone (mirror,
/// glass): without one, specular light paths make no path at all.
fn has_delta_objects(scene: &Scene) -> bool {
    (0..scene.shapes.len()).any(|g| {
        let m = scene.material_of(g as u32);
        m.emission == Vec3::ZERO && crate::bsdf::Bsdf::of(&m.surface, true).is_some_and(|b| b.is_delta())
    })
}

/// A strategy's contribution, before its shadow ray is traced.
struct Found {
    c: Connection,
    s: usize,
    t: usize,
    /// Which of the sample's camera subpaths it uses.
    branch: usize,
    /// `c.value` already has its MIS weight.
    weighted: bool,
}

impl Bdpt<'_> {
    /// Strategy (s, t)'s MIS weight (1 for the unweighted techniques).
    fn weight(&self, light: &[Vertex], camera: &[Vertex], c: &Connection, s: usize, t: usize, light_nee_ratio: f64) -> f32 {
        if self.weighted() {
            self.mis_weight(light, camera, c.sampled.as_ref(), s, t, if s == 1 { c.nee_ratio } else { light_nee_ratio })
        } else {
            1.0
        }
    }

    /// The sample's radiance from its connections: their shadow rays traced
    /// as one batch, then the MIS weights of the unoccluded ones (the
    /// weights cost more than the rays); light-tracing contributions go to
    /// `splats`. (Russian roulette on small connections did not pay:
    /// docs/design/bdpt.md.)
    #[allow(clippy::too_many_arguments)]
    fn gather(&self, accel: &dyn Traversal, found: &mut [Found], light: &[Vertex], cameras: &[Path], light_nee_ratio: f64, rays: &mut u64, splats: &mut Vec<Splat>) -> Vec3 {
        let mut shadows: SmallVec<[Ray; 32]> = SmallVec::new();
        let mut traced: SmallVec<[usize; 32]> = SmallVec::new();
        for (i, f) in found.iter().enumerate() {
            if let Some(shadow) = f.c.shadow {
                shadows.push(shadow);
                traced.push(i);
            }
        }
        let mut occluded: SmallVec<[bool; 32]> = smallvec::smallvec![false; shadows.len()];
        *rays += shadows.len() as u64;
        accel.occluded_batch(&shadows, &mut occluded);
        for (&i, &o) in traced.iter().zip(&occluded) {
            if o {
                found[i].c.value = Vec3::ZERO;
            }
        }
        let mut l = Vec3::ZERO;
        for f in found.iter().filter(|f| f.c.value != Vec3::ZERO) {
            let mut value = if f.weighted { f.c.value } else { f.c.value * self.weight(light, &cameras[f.branch], &f.c, f.s, f.t, light_nee_ratio) };
            if f.s >= 2 {
                value /= self.light_share();
            }
            match f.c.film {
                Some((x, y)) => splats.push(Splat {
                    x: ((x * self.width as f32) as u32).min(self.width - 1),
                    y: ((y * self.height as f32) as u32).min(self.height - 1),
                    l: value,
                }),
                None => l += value,
            }
        }
        l
    }
}
