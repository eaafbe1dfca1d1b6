//! Light transport: CS184's structure (zero bounce, one bounce, at least one
//! bounce) made physically correct, written as a loop.
//!
//! Emission is counted where a camera ray lands, and otherwise as direct
//! light at each vertex, estimated one of two ways:
//!
//! * default: light sampling combined with the BSDF sample that continues the
//!   path, by multiple importance sampling (Veach's power heuristic, counting
//!   `-l` samples per light). Light sampling alone has unbounded variance
//!   where surfaces meet at an emitter (the 1/r^2 of points sampled next to
//!   the receiver); the BSDF sample covers that region. Each emitter hit is
//!   counted once, with its MIS weight: no double counting.
//! * `-H`: CS184's uniform hemisphere estimate, on its own rays; the
//!   continuation ray then adds nothing where it lands.
//!
//! Delta lights (point, directional) and proxy-less rectangle lights cannot be
//! hit by a ray, so `-H` still samples them explicitly; everything a ray can
//! hit (emissive surfaces, the hemisphere light) is found by the hemisphere
//! samples. Both modes therefore estimate the same integral.
//!
//! Delta BSDFs (mirror, glass, refraction) cannot use light sampling: their
//! vertices skip it, and the emitter (or environment) their sampled ray
//! finds is counted with weight 1, in either mode. With `-m 1` a mirror
//! therefore shows the light it reflects (CS184 renders it black there).
//!
//! The pieces, one a file: `direct` (a vertex's direct light, drawn as
//! terms and replayed), `continuation` (the BSDF sample that continues the
//! path, guided at diffuse vertices, and Russian roulette),
//! `specular_guide` (the guide's cones toward mirror, glass and metal
//! objects: built once per scene, `PathTracer::guide`),
//! `wavefront` (the same loop over a batch of paths, bounce by bounce);
//! this file holds
//! the vertex, the MIS weights of BSDF samples and the path-at-a-time loop.

mod continuation;
mod direct;
pub mod specular_guide;
mod wavefront;

use super::Integrator;
use crate::accel::{Hit, Traversal};
use crate::bsdf::Bsdf;
use specular_guide::SpecularGuide;
use crate::light::{EnvAt, Lights};
use crate::ray::Ray;
use crate::sampler::Sampler;
use crate::sampling::Frame;
use crate::scene::{Interaction, Scene};
use glam::Vec3;

pub struct PathTracer<'a> {
    pub scene: &'a Scene,
    pub lights: &'a Lights,
    /// `--specular-guide`: aims a share of diffuse vertices' continuation
    /// rays at the scene's mirror, glass and metal objects
    /// (`SpecularGuide::of_scene`); `None`: the cosine lobe alone.
    pub guide: Option<&'a SpecularGuide>,
    /// `-m`: 0 emission only, 1 direct, k paths of up to k bounces.
    pub max_depth: u32,
    /// `-o`: true sums bounces 0..=m, false keeps only bounce m.
    pub accumulate: bool,
    /// `-H`: uniform hemisphere sampling for direct light.
    pub hemisphere: bool,
    /// `-l`: samples per non-delta light (per hemisphere-sample group with -H).
    pub light_samples: u32,
    pub russian_roulette: bool,
}

/// The surface seen from the side the ray came from: normals flipped towards `wo`.
pub(super) struct Vertex {
    pub it: Interaction,
    /// Geometric and shading normals on the side of `wo`.
    pub ng: Vec3,
    pub ns: Vec3,
    /// The shading frame (z = `ns`) and `wo` in it.
    pub frame: Frame,
    pub wo: Vec3,
    /// What the surface does with light; `None` where it does not scatter.
    pub bsdf: Option<Bsdf>,
    /// How the environment light is sampled here (`PathTracer::env_at`),
    /// by the light samples and in the BSDF sample's MIS weight alike.
    pub env_at: EnvAt,
}

impl PathTracer<'_> {
    /// `vertex`, made in place in `slot`: returned by value into a path's
    /// `Option<Vertex>`, the 176-byte vertex was copied twice (two `memcpy`
    /// calls per bounce, 3 % of a CBgems render).
    pub(super) fn vertex_in(&self, it: Interaction, wo: Vec3, slot: &mut Option<Vertex>) {
        // `wo` on the side the geometric normal points to: outside.
        let front = it.ng.dot(wo) >= 0.0;
        let flip = if front { 1.0 } else { -1.0 };
        let ng = it.ng * flip;
        let mut ns = it.ns * flip;
        if ns.dot(ng) <= 0.0 {
            ns = ng; // an interpolated normal turned past the face: use the face's
        }
        let frame = Frame::new(ns);
        let bsdf = Bsdf::of(&self.scene.material_of(it.geom_id).surface, front);
        let v = slot.insert(Vertex { it, ng, ns, frame, wo: frame.to_local(wo), bsdf, env_at: EnvAt::Map });
        if let Some(b) = &v.bsdf {
            v.env_at = self.env_at(b, v);
        }
    }

    /// MIS weight of the BSDF sample `c` that reached the emitter surface
    /// at `hit`, seen from `v`. Delta samples have weight 1: light sampling
    /// cannot find what they find.
    pub(super) fn bsdf_weight_hit(&self, v: &Vertex, hit: &Interaction, c: &Continuation) -> f32 {
        if c.delta {
            return 1.0;
        }
        match self.lights.of_geometry[hit.geom_id as usize] {
            Some(k) => {
                let light = &self.lights.lights[k];
                if c.alone && light.covers(v.it.p) {
                    return 0.0; // estimated by its light samples alone
                }
                let mut pl = light.pdf_hit(self.scene, v.it.p, hit.p, hit.ng, hit.prim_id);
                if let Some(picker) = self.lights.pick.as_ref().filter(|_| !self.hemisphere) {
                    // Light samples pick this light with this probability here.
                    pl *= picker.probabilities(&self.lights.lights, v.it.p, v.ns)[k];
                }
                power_heuristic(c.pdf, self.light_samples as f32 * pl)
            }
            None => 1.0,
        }
    }

    /// Whether lights are sampled *alone* at a vertex with this BSDF:
    /// diffuse, and not CS184's `-H` estimator. There, a light whose samples
    /// cover its whole solid angle uniformly — the hemisphere light by the
    /// lune (`light::lune`), a rectangle by solid angle, a sphere by its
    /// cone (`Light::covers`) — is estimated by its light samples with weight
    /// 1, and the vertex's BSDF sample adds nothing where it finds it: the
    /// light sample's value varies only with the receiver's cosine and
    /// visibility, where MIS would mix in a cosine-sampled estimate that finds
    /// the light by chance. At the path's last vertex the BSDF sample is then
    /// not traced at all when every light a ray can find is covered (at `-m 1`
    /// a third of the rays). Measured on CBspheres_lambertian at 256x192:
    /// see docs/design/light-transport.md.
    pub(super) fn alone(&self, bsdf: &Bsdf) -> bool {
        !self.hemisphere && matches!(bsdf, Bsdf::Diffuse(_))
    }

    /// How the environment light is sampled at `v`: with `env_product` on
    /// and a BSDF that does not transmit, inside the lobe where the BSDF is
    /// glossy enough (`env_lobe`), else by the map × the bound of the
    /// shading normal's cosine; otherwise by the map alone.
    fn env_at(&self, bsdf: &Bsdf, v: &Vertex) -> EnvAt {
        let Some(env) = self.lights.environment() else { return EnvAt::Map };
        if !self.lights.env_product || self.hemisphere || bsdf.transmits() {
            return EnvAt::Map;
        }
        if let (Bsdf::Microfacet(m), Some(lobes), true) = (bsdf, &env.lobe, self.lights.env_lobes) {
            let mirror = v.frame.to_world(Vec3::new(-v.wo.x, -v.wo.y, v.wo.z));
            if let Some(l) = lobes.lobe(mirror, m.alpha) {
                return EnvAt::Lobe(l);
            }
        }
        EnvAt::Cosine(v.ns)
    }

    /// What a BSDF sample that escaped along `c.wi` sees: each escaping
    /// light's radiance (hemisphere, environment) weighted against that
    /// light's own samples, since each light is sampled on its own.
    pub(super) fn escaped_weighted(&self, c: &Continuation) -> Vec3 {
        self.lights
            .lights
            .iter()
            .map(|l| {
                let le = l.escaped(c.wi);
                if c.alone && matches!(l, crate::light::Light::Hemisphere(crate::light::HemisphereLight { lune: true, .. })) {
                    Vec3::ZERO
                } else if le == Vec3::ZERO || c.delta {
                    le
                } else {
                    le * power_heuristic(c.pdf, self.light_samples as f32 * l.pdf_escape(c.wi, c.env_at))
                }
            })
            .sum()
    }
}

impl Integrator for PathTracer<'_> {
    fn radiance_batch(&self, accel: &dyn Traversal, rays: &[Ray], hits: &[Option<Hit>], samplers: &mut [&mut Sampler], out: &mut [Vec3], ray_count: &mut u64) {
        self.wavefront(accel, rays, hits, samplers, out, ray_count, wavefront::Tracing::Batched)
    }

    /// One path: the bounce loop (`wavefront`) over a batch of one, each
    /// ray traced alone.
    fn radiance_from(&self, accel: &dyn Traversal, camera_ray: &Ray, hit: Option<Hit>, sampler: &mut Sampler, rays: &mut u64) -> Vec3 {
        let mut out = [Vec3::ZERO];
        self.wavefront(accel, std::slice::from_ref(camera_ray), &[hit], &mut [sampler], &mut out, rays, wavefront::Tracing::OneByOne);
        out[0]
    }
}

/// The ray that continues a path past a vertex.
#[derive(Clone, Copy, Debug)]
pub(super) struct Continuation {
    /// World direction.
    pub wi: Vec3,
    /// Its solid-angle pdf (for a delta lobe, the lobe's probability).
    pub pdf: f32,
    /// The path throughput past the vertex (Russian roulette included).
    pub beta: Vec3,
    /// Sampled from a delta lobe.
    pub delta: bool,
    /// The vertex samples lights alone where their samples cover them
    /// (`PathTracer::alone`), so this ray's view of those must add nothing.
    pub alone: bool,
    /// The product of the path's radiance scalings (η²) so far, which
    /// Russian roulette divides out of `beta`.
    pub radiance_scale: f32,
    /// How the vertex sampled the environment (`Vertex::env_at`): this
    /// ray's escape is weighted against that pdf.
    pub env_at: EnvAt,
}

/// Veach's power heuristic (beta = 2) for a sample of pdf `a` against `b`,
/// both already multiplied by their strategies' sample counts.
pub(super) fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 && (a2 + b2).is_finite() {
        a2 / (a2 + b2)
    } else if a.is_infinite() {
        1.0
    } else {
        0.0
    }
}
