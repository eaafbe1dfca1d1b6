//! The path tracer over a batch of camera rays (one sample round of a tile),
//! bounce by bounce: every path's direct-light samples and continuation ray
//! are drawn first, then all shadow rays are traced as one batch and all
//! other rays as another, then every path adds what its rays found.
//!
//! `PathTracer::radiance_from` (one path at a time) is built from the same
//! pieces (`direct_terms`, `replay`, `continuation`), tracing each ray as it
//! is drawn. Each path draws from its own random stream in the same order
//! either way (visibility never changes what is drawn next), and the
//! deferred sums are replayed in the same order, so every path's radiance
//! is bit-identical: batching changes which rays travel together, never the
//! image.

use super::path::{Continuation, PathTracer, Vertex};
use crate::accel::Hit;
use crate::light::specular_guide::GuideAt;
use crate::light::{emitted, lune, pick, EnvAt, Light, LightSample, Target};
use crate::ray::Ray;
use crate::bsdf::{Bsdf, BsdfSample};
use crate::sampler::{dim, Sampler};
use crate::sampling::{cosine_hemisphere, cosine_hemisphere_pdf, uniform_hemisphere, UNIFORM_HEMISPHERE_PDF};
use crate::scene::Interaction;
use glam::Vec3;
use std::f32::consts::PI;

/// Russian roulette is a weight window: a path whose throughput (its
/// largest channel) is at least this goes on for sure; a darker one goes on
/// with probability throughput / floor and its throughput is raised to the
/// floor. So no surviving weight grows past the floor's scale, dark paths
/// are the ones cut, and bright ones are never cut. pbrt-v4 (and this
/// renderer before) used a floor of 1 — continue with probability
/// max(throughput) from the first indirect bounce — which in a Cornell box
/// (albedo ~0.6) cut half the paths at every bounce: measured at 256x192,
/// 4 seeds, relMSE × time, the floor of 1/4 is 1.5x (CBspheres_lambertian
/// `-m 5`) to 1.7x (`-m 10`) more efficient than a floor of 1, and equal to
/// no roulette at `-m 5` (floors 1/8 and 1/4 measured equal within noise).
/// Mitsuba 3 starts roulette at depth 5; Cycles, like pbrt, from the start.
const RR_WEIGHT_FLOOR: f32 = 0.25;

/// One term of a vertex's direct-light estimate, in the order the
/// path-at-a-time code adds them.
pub(super) enum Term {
    /// A light sample's contribution, counted if shadow ray `ray` is unoccluded.
    Shadow { ray: usize, value: Vec3 },
    /// A `-H` hemisphere sample: `f * le * cos / pdf` with `le` what ray
    /// `ray` (in the closest-hit batch) finds along `wi`.
    Hemisphere { ray: usize, f: Vec3, wi: Vec3, cos: f32 },
    /// End of one light's (or the hemisphere's) samples: `total += sum / n`.
    Group { n: u32 },
}

/// What every light sample at one vertex shares.
struct LightsAt<'v, 'g> {
    v: &'v Vertex,
    bsdf: Bsdf,
    alone: bool,
    env_at: EnvAt,
    /// The path's last vertex.
    last: bool,
    /// The guide's cones here: the continuation's pdf is their mixture.
    guide: Option<&'v GuideAt<'g>>,
}

/// One path between bounces.
struct Path {
    l: Vec3,
    beta: Vec3,
    /// See `Continuation::radiance_scale`.
    radiance_scale: f32,
    v: Option<Vertex>,
    bounce: u32,
    /// Direct-light terms of the current vertex (when this bounce counts):
    /// a range of the bounce's shared term buffer.
    terms: std::ops::Range<usize>,
    counted: bool,
    /// The continuation and its ray's index in the closest-hit batch, or
    /// `None` when the path ends here.
    next: Option<(usize, Continuation)>,
}

impl<'a> PathTracer<'a> {
    /// `out[i]` = the radiance along camera ray `rays[i]`, whose closest hit
    /// is `hits[i]`, drawing from `samplers[i]`.
    pub(super) fn wavefront(&self, rays: &[Ray], hits: &[Option<Hit>], samplers: &mut [&mut Sampler], out: &mut [Vec3], ray_count: &mut u64) {
        let m = self.max_depth;
        let counts = |bounce: u32| self.accumulate || bounce == m;
        // Each path is pushed empty and its first vertex made in place
        // (`vertex_in`): a path built by value and collected was copied.
        let mut paths: Vec<Path> = Vec::with_capacity(rays.len());
        for (ray, hit) in rays.iter().zip(hits) {
            let wo = -ray.dir.normalize();
            paths.push(Path { l: Vec3::ZERO, beta: Vec3::ONE, radiance_scale: 1.0, v: None, bounce: 1, terms: 0..0, counted: false, next: None });
            let p = paths.last_mut().expect("just pushed");
            match hit.map(|h| Interaction::with_barycentrics(self.scene, ray, &h, self.accel.exact_barycentrics())) {
                None => {
                    if counts(0) {
                        p.l = self.lights.escaped(-wo);
                    }
                }
                Some(it) => {
                    if counts(0) {
                        p.l = emitted(self.scene, &it, wo);
                    }
                    if m > 0 {
                        self.vertex_in(it, wo, &mut p.v);
                    }
                }
            }
        }
        // Sized for a bounce's worst case up front (every path drawing every
        // light sample, and with -H its hemisphere samples): grown on demand,
        // these were 4000 reallocations per CBempty render, 1 % of its work.
        let per_light = self.lights.lights.len() * self.light_samples as usize;
        let hemi = if self.hemisphere { per_light.max(self.light_samples as usize) } else { 0 };
        let n = rays.len();
        let (mut shadow, mut closest): (Vec<Ray>, Vec<Ray>) = (Vec::with_capacity(n * per_light), Vec::with_capacity(n * (1 + hemi)));
        let (mut occluded, mut found): (Vec<bool>, Vec<Option<Hit>>) = (Vec::with_capacity(n * per_light), Vec::with_capacity(n * (1 + hemi)));
        let mut terms: Vec<Term> = Vec::with_capacity(n * (per_light + self.lights.lights.len() + hemi + 1));
        let mut guide_slot = None;
        loop {
            shadow.clear();
            closest.clear();
            terms.clear();
            let mut live = false;
            // Draw: direct-light samples, then the continuation, per path.
            for (i, p) in paths.iter_mut().enumerate() {
                let Some(v) = &p.v else { continue };
                live = true;
                let sampler = &mut *samplers[i];
                sampler.set_bounce(p.bounce);
                let first = terms.len();
                p.counted = counts(p.bounce);
                // Found once for the light samples' MIS weights and the
                // continuation that draws from it.
                let guide = self.guide_at(v, p.bounce, &mut guide_slot);
                let seeks_light = p.counted && self.direct_terms(v, p.bounce, guide, sampler, &mut terms, &mut shadow, &mut closest);
                p.terms = first..terms.len();
                p.next = self.continuation(v, p.bounce, guide, seeks_light, p.beta, p.radiance_scale, sampler).map(|c| {
                    closest.push(v.it.spawn_ray(c.wi));
                    (closest.len() - 1, c)
                });
            }
            if !live {
                break;
            }
            // Trace: shadow rays as one batch, everything else as another.
            *ray_count += (shadow.len() + closest.len()) as u64;
            occluded.clear();
            occluded.resize(shadow.len(), false);
            self.accel.occluded_coherent(&shadow, &mut occluded);
            found.clear();
            found.resize(closest.len(), None);
            self.accel.intersect_batch(&closest, &mut found);
            // Add what the rays found, in the path-at-a-time order.
            for p in paths.iter_mut() {
                // The vertex stays in place until its successor replaces it
                // (moving it out and back was 5 % of a CBspheres render in
                // memcpy).
                let Some(v) = &p.v else { continue };
                if p.counted {
                    p.l += p.beta * self.replay(&terms[p.terms.clone()], &occluded, &closest, &found);
                }
                let next = p.next.and_then(|(k, c)| {
                    let gather = p.counted && (!self.hemisphere || c.delta);
                    let Some(next) = found[k].map(|h| Interaction::with_barycentrics(self.scene, &closest[k], &h, self.accel.exact_barycentrics())) else {
                        if gather {
                            p.l += c.beta * self.escaped_weighted(&c);
                        }
                        return None;
                    };
                    if gather {
                        let le = emitted(self.scene, &next, -c.wi);
                        if le != Vec3::ZERO {
                            p.l += c.beta * le * self.bsdf_weight_hit(v, &next, &c);
                        }
                    }
                    (p.bounce < m).then_some((next, c))
                });
                match next {
                    Some((next, c)) => {
                        self.vertex_in(next, -c.wi, &mut p.v);
                        p.beta = c.beta;
                        p.radiance_scale = c.radiance_scale;
                        p.bounce += 1;
                    }
                    None => p.v = None,
                }
            }
        }
        for (o, p) in out.iter_mut().zip(&paths) {
            *o = p.l;
        }
    }

    /// The direct light at `v`, drawn but not yet traced: the terms in the
    /// order they are summed, shadow rays appended to `shadow`, `-H`
    /// hemisphere rays to `closest`. Light sampling weighs each sample
    /// against the BSDF sample by the power heuristic (delta lights, lights
    /// no ray can hit and lights sampled alone (`PathTracer::alone`) have
    /// weight 1: only light sampling counts them); `-H` adds CS184's uniform
    /// hemisphere samples for the lights a ray can hit. Returns whether the
    /// vertex's BSDF sample can still add light (some light a ray can hit is
    /// not sampled alone here, or the BSDF is a delta).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn direct_terms(&self, v: &Vertex, bounce: u32, guide: Option<&GuideAt<'a>>, sampler: &mut Sampler, terms: &mut Vec<Term>, shadow: &mut Vec<Ray>, closest: &mut Vec<Ray>) -> bool {
        // Delta BSDFs see lights only through their sampled ray.
        let Some(bsdf) = v.bsdf.filter(|b| !b.is_delta()) else { return true };
        let at = LightsAt {
            v,
            bsdf,
            alone: self.alone(&bsdf),
            env_at: v.env_at,
            last: bounce == self.max_depth,
            guide,
        };
        if let Some(picker) = self.lights.pick.as_ref().filter(|_| !self.hemisphere) {
            // One light per sample, picked by its estimate here (`light::pick`).
            let prob = picker.probabilities(&self.lights.lights, v.it.p, v.ns);
            let count = self.lights.lights.len();
            let n = self.light_samples;
            for j in 0..n {
                // The picked light draws from slots shared by all lights:
                // its own would see only the samples that pick it, a random
                // subset of their stratified sequence.
                let li = pick::pick(&prob, count, sampler.slot_1d(dim::LIGHT_PICK, j as u64));
                self.light_term(&at, li, j as u64, n, prob[li], sampler, terms, shadow);
            }
            terms.push(Term::Group { n });
            // Only the last vertex asks whether its BSDF sample can still
            // find light (`continuation`); there, every light it can hit is
            // weighed as in `bsdf_weight_hit`.
            return !at.last || self.lights.lights.iter().any(|l| l.is_visible() && !(at.alone && l.covers(v.it.p)));
        }
        let explicit = self.lights.lights.iter().enumerate().filter(|(_, l)| !self.hemisphere || !l.is_visible());
        let mut bsdf_finds_light = self.hemisphere;
        for (li, light) in explicit {
            let n = if light.is_delta() { 1 } else { self.light_samples };
            for j in 0..n {
                // Light li's sample j: its own slots, whatever other lights drew.
                let slot = li as u64 * self.light_samples as u64 + j as u64;
                let by_itself = self.light_term(&at, li, slot, n, 1.0, sampler, terms, shadow);
                bsdf_finds_light |= light.is_visible() && !by_itself;
            }
            terms.push(Term::Group { n });
        }
        if !self.hemisphere {
            return bsdf_finds_light;
        }
        let visible = self.lights.lights.iter().filter(|l| l.is_visible()).count() as u32;
        let n = visible.max(1) * self.light_samples;
        for j in 0..n {
            let (u1, u2) = sampler.slot_2d(dim::HEMISPHERE, j as u64);
            let local = uniform_hemisphere(u1, u2);
            let wi = v.frame.to_world(local);
            if wi.dot(v.ng) <= 0.0 {
                continue;
            }
            closest.push(v.it.spawn_ray(wi));
            terms.push(Term::Hemisphere { ray: closest.len() - 1, f: bsdf.eval(v.wo, local), wi, cos: wi.dot(v.ns) });
        }
        terms.push(Term::Group { n });
        bsdf_finds_light
    }

    /// A sample of light `li` (one of `n`, each taken with probability
    /// `p_pick`) at the vertex, drawn from the light slots numbered `k`:
    /// its term and shadow ray, when it carries light. Returns whether the
    /// light was sampled alone (`PathTracer::alone`): then the BSDF sample
    /// need not look for it.
    #[allow(clippy::too_many_arguments)]
    fn light_term(&self, at: &LightsAt<'_, 'a>, li: usize, k: u64, n: u32, p_pick: f32, sampler: &mut Sampler, terms: &mut Vec<Term>, shadow: &mut Vec<Ray>) -> bool {
        let (v, bsdf) = (at.v, at.bsdf);
        let light = &self.lights.lights[li];
        let mis = !self.hemisphere && light.is_visible();
        let u = sampler.slot_2d(dim::LIGHT, k);
        let u_sel = if light.uses_selection() { sampler.slot_1d(dim::LIGHT_CHOICE, k) } else { 0.0 };
        // The sky at a diffuse vertex: the lune sampler alone (its
        // weight is constant; BSDF rays escaping there add nothing).
        let lune = at.alone && matches!(light, Light::Hemisphere { lune: true, .. });
        let s = match light {
            Light::Hemisphere { radiance, .. } if lune => {
                lune::sample(v.ns, u).map(|(wi, pdf)| LightSample { wi, value: *radiance, pdf, target: Target::Infinite, covers: true, prim: 0 })
            }
            _ => light.sample(self.scene, v.it.p, u, u_sel, at.env_at),
        };
        let by_itself = at.alone && s.is_some_and(|s| s.covers);
        let Some(s) = s else { return by_itself };
        let cos = s.wi.dot(v.ns);
        if cos <= 0.0 || s.wi.dot(v.ng) <= 0.0 || s.pdf <= 0.0 {
            return by_itself;
        }
        let wi = v.frame.to_local(s.wi);
        let f = bsdf.eval(v.wo, wi);
        if f == Vec3::ZERO {
            return by_itself;
        }
        shadow.push(match s.target {
            Target::Point(q) => v.it.spawn_ray_to(q),
            Target::Infinite => v.it.spawn_ray(s.wi),
        });
        let pdf = p_pick * s.pdf;
        let w = if mis && !by_itself {
            // Against the pdf of the continuation this vertex will draw:
            // the guided mixture where it applies.
            let p_bsdf = match at.guide {
                Some(g) => guided_pdf(g, wi, s.wi, None),
                None => bsdf.pdf(v.wo, wi),
            };
            super::path::power_heuristic(n as f32 * pdf, p_bsdf)
        } else {
            1.0
        };
        terms.push(Term::Shadow { ray: shadow.len() - 1, value: f * s.value * cos / pdf * w });
        by_itself
    }

    /// The direct light of recorded `terms`, summed as `PathTracer::direct` sums.
    pub(super) fn replay(&self, terms: &[Term], occluded: &[bool], closest: &[Ray], found: &[Option<Hit>]) -> Vec3 {
        let (mut total, mut sum) = (Vec3::ZERO, Vec3::ZERO);
        for t in terms {
            match *t {
                Term::Shadow { ray, value } => {
                    if !occluded[ray] {
                        sum += value;
                    }
                }
                Term::Hemisphere { ray, f, wi, cos } => {
                    let le = match found[ray] {
                        Some(h) => emitted(self.scene, &Interaction::with_barycentrics(self.scene, &closest[ray], &h, self.accel.exact_barycentrics()), -wi),
                        None => self.lights.escaped(wi),
                    };
                    sum += f * le * cos / UNIFORM_HEMISPHERE_PDF;
                }
                Term::Group { n } => {
                    total += sum / n as f32;
                    sum = Vec3::ZERO;
                }
            }
        }
        total
    }

    /// What follows a vertex's direct light: `None` when the path ends,
    /// else the BSDF-sampled direction, its pdf and the throughput past it
    /// (after Russian roulette from the second indirect bounce on, see
    /// `RR_WEIGHT_FLOOR`).
    /// The last vertex samples its BSDF only to find emitters: with MIS
    /// (its share of the direct light) or behind a delta BSDF (the only way
    /// to see light there), and only when `seeks_light`: its bounce counts
    /// and `direct_terms` left it light to find. `guide`: the vertex's
    /// `guide_at`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn continuation(&self, v: &Vertex, bounce: u32, guide: Option<&GuideAt>, seeks_light: bool, beta: Vec3, radiance_scale: f32, sampler: &mut Sampler) -> Option<Continuation> {
        let last = bounce == self.max_depth;
        let bsdf = v.bsdf?;
        if last && (!seeks_light || (self.hemisphere && !bsdf.is_delta())) {
            return None;
        }
        // Only the draws this BSDF uses (each has its own slot anyway).
        let (lobe, dir) = bsdf.draws();
        let lobe = if lobe { sampler.slot_1d(dim::BSDF_LOBE, 0) } else { 0.0 };
        let u = if dir { sampler.slot_2d(dim::BSDF, 0) } else { (0.0, 0.0) };
        let (s, wi) = match self.guided(v, &bsdf, guide, sampler, u) {
            Some(guided) => guided?,
            None => {
                let s = bsdf.sample_with(v.wo, lobe, u)?;
                (s, v.frame.to_world(s.wi))
            }
        };
        // With shading normals a sampled direction can leave on the other
        // side of the face than its lobe says. A reflecting surface then
        // ends the path: the ray would start inside the object (a leak into
        // closed rooms). A dielectric has light on both sides anyway: the
        // ray goes where it points, spawned on that side, as Mitsuba and
        // Cycles do (ending such paths made CBgems 0.17 % darker than both
        // references, measured at 256x192).
        let side = wi.dot(v.ng);
        if side == 0.0 || (!bsdf.transmits() && (side > 0.0) != (s.wi.z > 0.0)) {
            return None;
        }
        let mut beta_next = beta * s.weight;
        let radiance_scale = radiance_scale * s.radiance_scale;
        if self.russian_roulette && bounce >= 2 && !last {
            // Judged on the throughput without the η² scaling of radiance
            // inside a dielectric (which leaving it undoes).
            let q = (beta_next.max_element() / (radiance_scale * RR_WEIGHT_FLOOR)).min(1.0);
            if q <= 0.0 || sampler.slot_1d(dim::RUSSIAN_ROULETTE, 0) >= q {
                return None;
            }
            beta_next /= q;
        }
        Some(Continuation { wi, pdf: s.pdf, beta: beta_next, delta: s.delta, radiance_scale, alone: self.alone(&bsdf), env_at: v.env_at })
    }

    /// The guide's cones from diffuse vertex `v` at `bounce`
    /// (`light::specular_guide`), where its continuation is drawn from the
    /// guided mixture: not at the path's last vertex, not with `-H`, and
    /// only with a target in view.
    /// Made in `slot`, which the caller keeps from vertex to vertex
    /// (`SpecularGuide::at_in`).
    pub(super) fn guide_at<'b>(&self, v: &Vertex, bounce: u32, slot: &'b mut Option<GuideAt<'a>>) -> Option<&'b GuideAt<'a>> {
        if !matches!(v.bsdf, Some(Bsdf::Diffuse(_))) || self.hemisphere || bounce == self.max_depth {
            return None;
        }
        let lights: &'a crate::light::Lights = self.lights;
        let at = lights.guide.as_ref()?.at_in(v.it.p, v.ns, slot);
        (at.fraction() > 0.0).then_some(at)
    }

    /// A diffuse vertex's continuation from the mixture of its cosine lobe
    /// and cones towards the scene's specular and glossy objects: `None`
    /// where the guide does not apply (no `guide`: see `guide_at`), else the sample
    /// (`Some(None)`: the direction is below the surface). The lobe's slot
    /// picks the strategy and the target (diffuse sampling does not use
    /// it), the direction's slot draws the direction either way.
    fn guided(&self, v: &Vertex, bsdf: &Bsdf, guide: Option<&GuideAt>, sampler: &mut Sampler, u: (f32, f32)) -> Option<Option<(BsdfSample, Vec3)>> {
        let Bsdf::Diffuse(d) = bsdf else { return None };
        let at = guide?;
        let q = at.fraction();
        let pick = sampler.slot_1d(dim::BSDF_LOBE, 0);
        let (wi, from) = if pick < q {
            let Some((wi, k)) = at.sample(pick / q, u) else { return Some(None) };
            (wi, Some(k))
        } else {
            (v.frame.to_world(cosine_hemisphere(u.0, u.1)), None)
        };
        let local = v.frame.to_local(wi);
        if !(local.z > 0.0) {
            return Some(None);
        }
        let pdf = guided_pdf(at, local, wi, from);
        if !(pdf > 0.0) || !pdf.is_finite() {
            return Some(None);
        }
        let weight = d.albedo * (local.z / PI / pdf);
        Some(Some((BsdfSample { wi: local, weight, pdf, delta: false, radiance_scale: 1.0 }, wi)))
    }
}

/// The guided mixture's pdf of a direction, `local` in the shading frame
/// and `world` (see `GuideAt::pdf` for `from`).
fn guided_pdf(at: &GuideAt, local: Vec3, world: Vec3, from: Option<usize>) -> f32 {
    let q = at.fraction();
    (1.0 - q) * cosine_hemisphere_pdf(local.z) + q * at.pdf(world, from)
}
