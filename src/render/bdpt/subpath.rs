//! Camera and light subpaths: random walks that record each vertex's
//! throughput and both densities (`vertex`).
//!
//! * The camera subpath starts with the lens point and the camera ray the
//!   image loop traced; its walk samples BSDFs in `Mode::Radiance`, as the
//!   path tracer does (same draws: `dim::BSDF_LOBE`, `dim::BSDF`,
//!   `dim::RUSSIAN_ROULETTE` at vertex `bounce`).
//! * The light subpath starts on a light picked by power
//!   (`emission::LightPower`), with a point and a cosine-weighted direction
//!   (`Light::sample_emission`); its walk scatters with the adjoint BSDF
//!   (`Mode::Importance`) and draws from its own dimension ids
//!   (`dim::light_vertex`).
//! * Russian roulette on both, from the third vertex on: the path tracer's
//!   weight window (continue for sure at a throughput of at least 1/4 of
//!   the start's, else with probability throughput / floor, the survivor's
//!   throughput divided by it). The camera side divides out the η² its
//!   radiance carries through glass, as the path tracer does. Survival is not
//!   in the densities (see `mis`). pbrt-v4's BDPT has no roulette.
//! * A light at infinity starts its subpath on the disk of the scene's
//!   bounding sphere that faces the drawn direction (`emission`), its first
//!   vertex a direction (`Kind::Distant`).
//! * A camera subpath that leaves the scene ends with an `Escaped` vertex
//!   when some light at infinity can be seen (strategy s = 0); a light
//!   subpath that leaves the scene just ends.

use super::vertex::{Kind, Mode, Vertex};
use super::{Bdpt, LightPaths};
use crate::accel::{Hit, Traversal};
use crate::ray::Ray;
use crate::sampler::{dim, Sampler};
use crate::scene::Interaction;
use glam::Vec3;

/// See the module comment.
const RR_WEIGHT_FLOOR: f32 = 0.25;

impl Bdpt<'_> {
    /// The camera subpath of camera ray `ray` (whose closest hit is `hit`):
    /// at most `max` vertices, the lens point first.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn camera_subpath(&self, accel: &dyn Traversal, ray: &Ray, hit: Option<Hit>, sampler: &mut Sampler, path: &mut super::Path, max: usize, rays: &mut u64) {
        path.clear();
        let dir = ray.dir.normalize();
        let axis = self.camera.view_axis();
        path.push(Vertex::at_point(Kind::Camera, ray.origin, axis, ray.origin.abs().max_element(), u32::MAX, 0, Vec3::ONE, 1.0));
        if max < 2 {
            return;
        }
        let pdf_dir = self.camera.pdf_dir(ray.origin, dir);
        let first = Ray { dir, tmin: ray.tmin * ray.dir.length(), tmax: ray.tmax * ray.dir.length(), ..*ray };
        self.walk(accel, first, Some(hit), Vec3::ONE, pdf_dir, Mode::Radiance, sampler, path, max, rays);
    }

    /// The light subpath of this pixel sample: at most `max` vertices, the
    /// light's point first (none when no light emits).
    pub(super) fn light_subpath(&self, accel: &dyn Traversal, sampler: &mut Sampler, path: &mut super::Path, max: usize, rays: &mut u64) {
        path.clear();
        if max == 0 {
            return;
        }
        let draw2 = |slot| sampler.get_2d(dim::light_vertex(0, slot));
        let Some((k, pmf)) = self.power.pick(sampler.get_1d(dim::light_vertex(0, dim::EMIT_PICK))) else { return };
        let light = &self.lights.lights[k];
        let world = self.power.world();
        let Some(e) = light.sample_emission(self.scene, world, sampler.get_1d(dim::light_vertex(0, dim::EMIT_SELECT)), draw2(dim::EMIT_POINT), draw2(dim::EMIT_DIRECTION)) else { return };
        if light.is_at_infinity() {
            // The direction is the light's "position": its density starts
            // the chain; the next vertex gets the disk's (see `vertex`).
            let origin_pdf = pmf * e.pdf_dir;
            path.push(Vertex::distant(k, e.p, -e.dir, e.le / origin_pdf, origin_pdf));
            let beta = e.le / (origin_pdf * e.pdf_pos);
            if max < 2 || !beta.is_finite() || beta == Vec3::ZERO {
                return;
            }
            let ray = Ray::new(e.p, e.dir);
            self.walk(accel, ray, None, beta, e.pdf_pos, Mode::Importance, sampler, path, max, rays);
            return;
        }
        let origin_pdf = pmf * e.pdf_pos;
        let y0 = Vertex::at_point(Kind::Light(k), e.p, e.n, e.magnitude, light.geometry(), e.prim, e.le / origin_pdf, origin_pdf);
        path.push(y0);
        if max < 2 {
            return;
        }
        let cos = if e.n == Vec3::ZERO { 1.0 } else { e.n.dot(e.dir).abs() };
        let beta = e.le * cos / (origin_pdf * e.pdf_dir);
        if !beta.is_finite() || beta == Vec3::ZERO {
            return;
        }
        let ray = y0.it.spawn_ray(e.dir);
        self.walk(accel, ray, None, beta, e.pdf_dir, Mode::Importance, sampler, path, max, rays);
    }

    /// Extend `path` from its last vertex along `ray` (unit direction, drawn
    /// with solid-angle density `pdf_dir`, or from a light at infinity with
    /// its disk's area density; `first`: its hit, already traced) with
    /// throughput `beta`, until `max` vertices, an escape, an absorption or
    /// Russian roulette.
    #[allow(clippy::too_many_arguments)]
    fn walk(&self, accel: &dyn Traversal, mut ray: Ray, mut first: Option<Option<Hit>>, mut beta: Vec3, mut pdf_dir: f32, mode: Mode, sampler: &mut Sampler, path: &mut super::Path, max: usize, rays: &mut u64) {
        let beta_start = beta.max_element();
        let mut radiance_scale = 1.0f32;
        loop {
            let hit = match first.take() {
                Some(h) => h,
                None => {
                    *rays += 1;
                    accel.intersect(&ray)
                }
            };
            let Some(hit) = hit else {
                if mode == Mode::Radiance && !self.sky.is_empty() {
                    path.push(Vertex::escaped(ray.dir, beta, pdf_dir));
                }
                return;
            };
            let it = Interaction::with_barycentrics(self.scene, &ray, &hit, accel.exact_barycentrics());
            let prev = path.last().expect("a subpath starts with its end point");
            let mut v = Vertex::surface(self.scene, it, -ray.dir, beta);
            if mode == Mode::Importance && path.len() == 1 && self.light_paths == LightPaths::Specular && !v.bsdf.is_some_and(|b| b.is_delta()) {
                // Not a caustic path: the light subpath keeps only its light
                // point (next-event estimation, s = 1, draws its own).
                return;
            }
            v.pdf_fwd = v.density_from(pdf_dir, prev);
            path.push(v);
            let i = path.len() - 1;
            if path.len() >= max {
                return;
            }
            let Some(bsdf) = v.bsdf else { return };
            let draw = |slot: u32| match mode {
                Mode::Radiance => dim::at_bounce(i as u32, slot, 0),
                Mode::Importance => dim::light_vertex(i as u32, slot),
            };
            let wo = v.frame.to_local(v.wo);
            let (lobe, u) = bsdf.draws();
            let lobe = if lobe { sampler.get_1d(draw(dim::BSDF_LOBE)) } else { 0.0 };
            let u = if u { sampler.get_2d(draw(dim::BSDF)) } else { (0.0, 0.0) };
            let Some(bs) = bsdf.sample_with(wo, lobe, u) else { return };
            let wi = v.frame.to_world(bs.wi).normalize();
            let mut weight = bs.weight;
            match mode {
                Mode::Radiance => radiance_scale *= bs.radiance_scale,
                // Importance is not scaled at a crossing; the adjoint's
                // shading-normal correction.
                Mode::Importance => weight *= v.shading_correction(wi) / bs.radiance_scale,
            }
            beta *= weight;
            let (fwd, rev) = if bs.delta { (0.0, 0.0) } else { (bs.pdf, bsdf.pdf(bs.wi, wo)) };
            if bs.delta {
                // A specular chain starts here: its density is per projected
                // solid angle at the vertex that made it (see `vertex`).
                path[i].delta = true;
                path[i].pdf_fwd = path[i].density_from(pdf_dir, &path[i - 1]);
            }
            path[i - 1].pdf_rev = path[i - 1].density_from(rev, &path[i]);
            if i >= 2 {
                let level = match mode {
                    Mode::Radiance => beta.max_element() / radiance_scale,
                    Mode::Importance => beta.max_element() / beta_start,
                };
                if level < RR_WEIGHT_FLOOR {
                    let q = level / RR_WEIGHT_FLOOR;
                    if !(sampler.get_1d(draw(dim::RUSSIAN_ROULETTE)) < q) {
                        return;
                    }
                    beta /= q;
                }
            }
            if !(beta.max_element() > 0.0) || !beta.is_finite() {
                return;
            }
            pdf_dir = fwd;
            ray = v.it.spawn_ray(wi);
        }
    }
}
