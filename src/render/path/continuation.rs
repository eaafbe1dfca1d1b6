//! What continues a path past a vertex: the BSDF sample (from the guided
//! mixture at diffuse vertices, `specular_guide`), checked against the
//! geometric side, and Russian roulette.

use super::{Continuation, PathTracer, Vertex};
use crate::bsdf::{Bsdf, BsdfSample};
use crate::render::path::specular_guide::GuideAt;
use crate::sampler::{dim, Sampler};
use crate::sampling::{cosine_hemisphere, cosine_hemisphere_pdf};
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

impl<'a> PathTracer<'a> {
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
    /// (`render::path::specular_guide`), where its continuation is drawn from the
    /// guided mixture: not at the path's last vertex, not with `-H`, and
    /// only with a target in view.
    /// Made in `slot`, which the caller keeps from vertex to vertex
    /// (`SpecularGuide::at_in`).
    pub(super) fn guide_at<'b>(&self, v: &Vertex, bounce: u32, slot: &'b mut Option<GuideAt<'a>>) -> Option<&'b GuideAt<'a>> {
        if !matches!(v.bsdf, Some(Bsdf::Diffuse(_))) || self.hemisphere || bounce == self.max_depth {
            return None;
        }
        let guide: &'a super::SpecularGuide = self.guide?;
        let at = guide.at_in(v.it.p, v.ns, slot);
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
pub(super) fn guided_pdf(at: &GuideAt, local: Vec3, world: Vec3, from: Option<usize>) -> f32 {
    let q = at.fraction();
    (1.0 - q) * cosine_hemisphere_pdf(local.z) + q * at.pdf(world, from)
}
