//! Direct light at a path vertex: light samples (by solid angle, cone, lune
//! or area, see `light`) weighed against the vertex's BSDF sample by the
//! power heuristic, or CS184's uniform hemisphere samples (`-H`), drawn
//! first and traced later, as terms replayed in a fixed order (`replay`),
//! so that the wavefront and the path-at-a-time loop sum the same bits.

use super::continuation::guided_pdf;
use super::{PathTracer, Vertex};
use crate::accel::{Hit, Traversal};
use crate::bsdf::Bsdf;
use crate::render::path::specular_guide::GuideAt;
use crate::light::{emitted, lune, pick, EnvAt, Light, LightSample, Target};
use crate::ray::Ray;
use crate::sampler::{dim, Sampler};
use crate::sampling::{uniform_hemisphere, UNIFORM_HEMISPHERE_PDF};
use crate::scene::Interaction;
use glam::Vec3;

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

impl<'a> PathTracer<'a> {
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
        let lune = at.alone && matches!(light, Light::Hemisphere(crate::light::HemisphereLight { lune: true, .. }));
        let s = match light {
            Light::Hemisphere(crate::light::HemisphereLight { radiance, .. }) if lune => {
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
            super::power_heuristic(n as f32 * pdf, p_bsdf)
        } else {
            1.0
        };
        terms.push(Term::Shadow { ray: shadow.len() - 1, value: f * s.value * cos / pdf * w });
        by_itself
    }

    /// The direct light of recorded `terms`, summed as `PathTracer::direct` sums.
    pub(super) fn replay(&self, accel: &dyn Traversal, terms: &[Term], occluded: &[bool], closest: &[Ray], found: &[Option<Hit>]) -> Vec3 {
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
                        Some(h) => emitted(self.scene, &Interaction::with_barycentrics(self.scene, &closest[ray], &h, accel.exact_barycentrics()), -wi),
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
}
