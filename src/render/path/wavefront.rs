//! The path tracer's one bounce loop, over a batch of camera rays (one
//! sample round of a tile): every path's direct-light samples and
//! continuation ray are drawn first, then the bounce's rays are traced —
//! all shadow rays as one batch and all other rays as another, or each
//! alone (`Tracing`) — then every path adds what its rays found.
//!
//! `PathTracer::radiance_from` (one path at a time) is this loop over a
//! batch of one, its rays traced alone: the two cannot drift apart. Each
//! path draws from its own random stream in the same order whatever else
//! is in the batch (visibility never changes what is drawn next), so every
//! path's radiance is bit-identical: batching changes which rays travel
//! together, never the image.

use super::direct::Term;
use super::{Continuation, PathTracer, Vertex};
use crate::accel::{Hit, Traversal};
use crate::light::emitted;
use crate::ray::Ray;
use crate::sampler::Sampler;
use crate::scene::MeshFetch;
use crate::scene::Interaction;
use glam::Vec3;

/// How a bounce's rays are traced.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Tracing {
    /// Shadow rays as one batch, the other rays as another. The first
    /// bounce's shadow rays leave the tile's camera hits, close together,
    /// and go as a coherent batch. Later bounces' shadow rays leave points
    /// scattered over the scene and go as an incoherent one. Called coherent,
    /// Embree 4 traced them in packets meant for rays that travel together,
    /// and its 5-bounce renders of CBbunny and the subdivided CBbunny took
    /// 3–12 % longer (docs/notes/2026-12-03-embree-coherent-packets.md).
    Batched,
    /// Each ray on its own.
    OneByOne,
}

impl Tracing {
    /// `occluded[i]` for `shadow[i]`, `found[i]` for `closest[i]`;
    /// `coherent_shadows`: the shadow rays start close together.
    fn trace(self, accel: &dyn Traversal, shadow: &[Ray], closest: &[Ray], occluded: &mut Vec<bool>, found: &mut Vec<Option<Hit>>, coherent_shadows: bool) {
        occluded.clear();
        occluded.resize(shadow.len(), false);
        found.clear();
        found.resize(closest.len(), None);
        match self {
            Tracing::Batched => {
                if coherent_shadows {
                    accel.occluded_coherent(shadow, occluded);
                } else {
                    accel.occluded_batch(shadow, occluded);
                }
                accel.intersect_batch(closest, found);
            }
            Tracing::OneByOne => {
                for (r, o) in shadow.iter().zip(occluded.iter_mut()) {
                    *o = accel.occluded(r);
                }
                for (r, f) in closest.iter().zip(found.iter_mut()) {
                    *f = accel.intersect(r);
                }
            }
        }
    }
}

/// How many closest-hit rays ahead of the path being gathered a hit's
/// vertex indices, then its vertices, are fetched (`Scene::prefetch_hit`):
/// enough paths' work to cover a miss each step, few enough that the lines
/// are still cached when described.
const FETCH_INDICES_AHEAD: usize = 8;
const FETCH_VERTICES_AHEAD: usize = 4;

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
    #[allow(clippy::too_many_arguments)]
    pub(super) fn wavefront(&self, accel: &dyn Traversal, rays: &[Ray], hits: &[Option<Hit>], samplers: &mut [&mut Sampler], out: &mut [Vec3], ray_count: &mut u64, tracing: Tracing) {
        let m = self.max_depth;
        let counts = |bounce: u32| self.accumulate || bounce == m;
        // Each path is pushed empty and its first vertex made in place
        // (`vertex_in`): a path built by value and collected was copied.
        let mut paths: Vec<Path> = Vec::with_capacity(rays.len());
        for (ray, hit) in rays.iter().zip(hits) {
            let wo = -ray.dir.normalize();
            paths.push(Path { l: Vec3::ZERO, beta: Vec3::ONE, radiance_scale: 1.0, v: None, bounce: 1, terms: 0..0, counted: false, next: None });
            let p = paths.last_mut().expect("just pushed");
            match hit.map(|h| Interaction::with_barycentrics(self.scene, ray, &h, accel.exact_barycentrics())) {
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
        let fetch_hits = self.scene.hits_miss_caches();
        // Every live path is at the same bounce in each round: the first
        // round's vertices are the tile's camera hits.
        let mut first_bounce = true;
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
            tracing.trace(accel, &shadow, &closest, &mut occluded, &mut found, first_bounce);
            first_bounce = false;
            // Add what the rays found, in the path-at-a-time order.
            for p in paths.iter_mut() {
                // The vertex stays in place until its successor replaces it
                // (moving it out and back was 5 % of a CBspheres render in
                // memcpy).
                let Some(v) = &p.v else { continue };
                if let Some((k, _)) = p.next.filter(|_| fetch_hits) {
                    for (ahead, step) in [(FETCH_INDICES_AHEAD, MeshFetch::Indices), (FETCH_VERTICES_AHEAD, MeshFetch::PositionsAndNormals)] {
                        if let Some(Some(h)) = found.get(k + ahead) {
                            self.scene.prefetch_hit(h, step);
                        }
                    }
                }
                if p.counted {
                    p.l += p.beta * self.replay(accel, &terms[p.terms.clone()], &occluded, &closest, &found);
                }
                let next = p.next.and_then(|(k, c)| {
                    let gather = p.counted && (!self.hemisphere || c.delta);
                    let Some(next) = found[k].map(|h| Interaction::with_barycentrics(self.scene, &closest[k], &h, accel.exact_barycentrics())) else {
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
}
