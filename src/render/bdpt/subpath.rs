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
//! * A camera subpath splits at glass it sees through mirrors and glass
//!   alone, following both lobes (`Branch`), up to `MAX_CAMERA_SUBPATHS`
//!   subpaths per pixel sample.
//! * A camera subpath that leaves the scene ends with an `Escaped` vertex
//!   when some light at infinity can be seen (strategy s = 0); a light
//!   subpath that leaves the scene just ends.

use super::vertex::{Kind, Mode, Vertex};
use super::{Bdpt, LightPaths};
use crate::accel::{Hit, Traversal};
use crate::bsdf::BsdfSample;
use smallvec::SmallVec;
use crate::ray::Ray;
use crate::sampler::{dim, Sampler};
use crate::scene::Interaction;
use glam::Vec3;

/// See the module comment.
const RR_WEIGHT_FLOOR: f32 = 0.25;

/// At most this many camera subpaths per pixel sample (see `Branch`).
pub const MAX_CAMERA_SUBPATHS: usize = 4;

/// Splitting at glass the camera sees through mirrors and glass alone (as
/// Cycles' former branched path tracer followed every closure at the
/// first hit): where a camera subpath reaches glass and every vertex
/// before it is specular, the subpath follows both lobes, reflection and
/// transmission, each with its throughput times the probability `sample`
/// would have picked it, instead of one lobe picked with that probability.
/// A pure specular path E S… L (a light seen reflected in a gem, or
/// through it) then has no variance from the lobe choices, where a picked
/// lobe shows a reflected light at weight 1 in ~4 % of the samples:
/// measured on CBgems, those paths (strategy s = 0 on the gems) were a
/// third of BDPT's variance (docs/design/bdpt.md).
///
/// Why the weights need nothing: on a specular prefix of a camera subpath
/// no strategy can connect (a connection needs non-specular ends), so every
/// strategy that makes the path makes those vertices from the camera, with
/// the same lobe probabilities; they cancel from every ratio `mis` takes
/// (and specular vertices' densities are left out of them anyway).
///
/// A branch draws the same numbers as the subpath it split from (the same
/// dimension ids at the same depth), and Russian roulette judges it by the
/// throughput the unsplit path would have had.
pub(super) type Branch = (super::Path, Walk);

/// The branches a camera subpath has split off and not yet walked, and how
/// many more it may make (`MAX_CAMERA_SUBPATHS` in all).
pub(super) struct Branches {
    pending: SmallVec<[Branch; 2]>,
    left: usize,
}

impl Branches {
    /// For a subpath that does not split (light subpaths).
    fn none() -> Branches {
        Branches { pending: SmallVec::new(), left: 0 }
    }
}

impl Bdpt<'_> {
    /// The camera subpaths of camera ray `ray` (whose closest hit is
    /// `hit`): at most `max` vertices each, the lens point first. One
    /// subpath, or more where the camera sees glass: see `Branch`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn camera_subpaths(&self, accel: &dyn Traversal, ray: &Ray, hit: Option<Hit>, sampler: &mut Sampler, paths: &mut super::Paths, max: usize, rays: &mut u64) {
        paths.clear();
        let dir = ray.dir.normalize();
        let axis = self.camera.view_axis();
        paths.push(super::Path::new());
        let path = &mut paths[0];
        path.push(Vertex::at_point(Kind::Camera, ray.origin, axis, ray.origin.abs().max_element(), u32::MAX, 0, Vec3::ONE, 1.0));
        if max < 2 {
            return;
        }
        let pdf_dir = self.camera.pdf_dir(ray.origin, dir);
        let first = Ray { dir, tmin: ray.tmin * ray.dir.length(), tmax: ray.tmax * ray.dir.length(), ..*ray };
        let mut branches = Branches { pending: SmallVec::new(), left: MAX_CAMERA_SUBPATHS - 1 };
        self.walk(accel, Walk::start(first, Vec3::ONE, pdf_dir, true), Some(hit), Mode::Radiance, sampler, path, max, rays, &mut branches);
        // Each branch goes on from its copy of the prefix it split from.
        while let Some((mut path, w)) = branches.pending.pop() {
            self.walk(accel, w, None, Mode::Radiance, sampler, &mut path, max, rays, &mut branches);
            paths.push(path);
        }
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
        let no_caustics = !self.unseen_light_caustics && !light.is_visible();
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
            let w = Walk { no_specular_first: no_caustics, ..Walk::start(ray, beta, e.pdf_pos, false) };
            self.walk(accel, w, None, Mode::Importance, sampler, path, max, rays, &mut Branches::none());
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
        let ray = if e.n == Vec3::ZERO {
            // A point light has no surface to step off: its first ray
            // leaves the point itself, past what lies within the step a
            // surface's rays take (`offset_ray_origin`). Next-event
            // estimation ends its shadow rays that far short of the light
            // too (`PointLight::sample`), so both see the same occluders: a
            // point light in the plane of a surface (CBempty's, on its
            // lamp) is not shadowed by that surface, whatever the rounding.
            let step = crate::sampling::OFFSET_ULPS * crate::sampling::ulp(e.magnitude);
            Ray::with_range(e.p, e.dir, step, f32::INFINITY)
        } else {
            y0.it.spawn_ray(e.dir)
        };
        let w = Walk { no_specular_first: no_caustics, ..Walk::start(ray, beta, e.pdf_dir, false) };
        self.walk(accel, w, None, Mode::Importance, sampler, path, max, rays, &mut Branches::none());
    }

    /// Extend `path` from its last vertex along `w.ray` (unit direction,
    /// drawn with solid-angle density `w.pdf_dir`, or from a light at
    /// infinity with its disk's area density; `first`: its hit, already
    /// traced) with throughput `w.beta`, until `max` vertices, an escape, an
    /// absorption or Russian roulette. Glass on a camera subpath's specular
    /// prefix splits it while `branches` has room (see `Branch`).
    #[allow(clippy::too_many_arguments)]
    fn walk(&self, accel: &dyn Traversal, mut w: Walk, mut first: Option<Option<Hit>>, mode: Mode, sampler: &mut Sampler, path: &mut super::Path, max: usize, rays: &mut u64, branches: &mut Branches) {
        loop {
            let ray = w.ray;
            let hit = match first.take() {
                Some(h) => h,
                None => {
                    *rays += 1;
                    accel.intersect(&ray)
                }
            };
            let Some(hit) = hit else {
                if mode == Mode::Radiance && !self.sky.is_empty() {
                    path.push(Vertex::escaped(ray.dir, w.beta, w.pdf_dir));
                }
                return;
            };
            let it = Interaction::with_barycentrics(self.scene, &ray, &hit, accel.exact_barycentrics());
            let prev = path.last().expect("a subpath starts with its end point");
            let mut v = Vertex::surface(self.scene, it, -ray.dir, w.beta);
            if mode == Mode::Importance && path.len() == 1 && self.light_paths == LightPaths::Specular && !v.bsdf.is_some_and(|b| b.is_delta()) {
                // Not a caustic path: the light subpath keeps only its light
                // point (next-event estimation, s = 1, draws its own).
                return;
            }
            if w.no_specular_first && path.len() == 1 && v.bsdf.is_some_and(|b| b.is_delta()) {
                // Only strategies s >= 2 make a path whose light no ray
                // finds next to a specular vertex: dropping it takes it
                // out of the image, and no other path's weight changes.
                return;
            }
            v.pdf_fwd = v.density_from(w.pdf_dir, prev);
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
            w.specular_prefix &= bsdf.is_delta();
            // Both lobes, when this vertex splits: the other one goes on as a
            // branch, from a copy of the path made once this vertex is final.
            let mut other = None;
            // (Asked only where a split is allowed: both lobes cost two Fresnel
            // terms and a refraction.)
            let lobes = if w.specular_prefix && branches.left > 0 { bsdf.delta_lobes(wo) } else { None };
            let bs = match lobes {
                Some([Some(reflect), Some(transmit)]) => {
                    branches.left -= 1;
                    let mut branch = w;
                    other = Some((branch.split(transmit), branch));
                    Some(w.split(reflect))
                }
                Some([Some(one), None] | [None, Some(one)]) => Some(w.split(one)),
                _ => {
                    let (lobe, u) = bsdf.draws();
                    let lobe = if lobe { sampler.get_1d(draw(dim::BSDF_LOBE)) } else { 0.0 };
                    let u = if u { sampler.get_2d(draw(dim::BSDF)) } else { (0.0, 0.0) };
                    bsdf.sample_with(wo, lobe, u)
                }
            };
            let Some(bs) = bs else { return };
            let (fwd, rev) = if bs.delta { (0.0, 0.0) } else { (bs.pdf, bsdf.pdf(bs.wi, wo)) };
            if bs.delta {
                // A specular chain starts here: its density is per projected
                // solid angle at the vertex that made it (see `vertex`).
                path[i].delta = true;
                path[i].pdf_fwd = path[i].density_from(w.pdf_dir, &path[i - 1]);
            }
            path[i - 1].pdf_rev = path[i - 1].density_from(rev, &path[i]);
            if let Some((other, branch)) = other {
                if let Some(next) = self.scatter(branch, other, &v, mode, i, fwd, draw(dim::RUSSIAN_ROULETTE), sampler) {
                    branches.pending.push((path.clone(), next));
                }
            }
            match self.scatter(w, bs, &v, mode, i, fwd, draw(dim::RUSSIAN_ROULETTE), sampler) {
                Some(next) => w = next,
                None => return,
            }
        }
    }

    /// The walk past vertex `v` (the `i`-th of its subpath) along `bs`, with
    /// the adjoint's factors on light subpaths and Russian roulette from the
    /// third vertex on (drawn at `roulette`); `None` when the walk ends there.
    #[allow(clippy::too_many_arguments)]
    fn scatter(&self, w: Walk, bs: BsdfSample, v: &Vertex, mode: Mode, i: usize, fwd: f32, roulette: u64, sampler: &mut Sampler) -> Option<Walk> {
        let wi = v.frame.to_world(bs.wi).normalize();
        let mut w = Walk { pdf_dir: fwd, ray: v.it.spawn_ray(wi), ..w };
        let mut weight = bs.weight;
        match mode {
            Mode::Radiance => w.radiance_scale *= bs.radiance_scale,
            // Importance is not scaled at a crossing; the adjoint's
            // shading-normal correction.
            Mode::Importance => weight *= v.shading_correction(wi) / bs.radiance_scale,
        }
        w.beta *= weight;
        if i >= 2 {
            // The level the path would have without splitting: a branch is
            // cut as often as the path it stands for.
            let level = match mode {
                Mode::Radiance => w.beta.max_element() / (w.radiance_scale * w.split),
                Mode::Importance => w.beta.max_element() / w.beta_start,
            };
            if level < RR_WEIGHT_FLOOR {
                let q = level / RR_WEIGHT_FLOOR;
                if !(sampler.get_1d(roulette) < q) {
                    return None;
                }
                w.beta /= q;
            }
        }
        (w.beta.max_element() > 0.0 && w.beta.is_finite()).then_some(w)
    }
}

/// A walk between two vertices: the ray to trace and what it carries.
#[derive(Clone, Copy)]
pub(super) struct Walk {
    ray: Ray,
    beta: Vec3,
    /// The ray direction's density (see `Bdpt::walk`).
    pdf_dir: f32,
    /// The product of the (η_i/η_t)² factors in `beta` (camera subpaths),
    /// which Russian roulette divides out.
    radiance_scale: f32,
    /// The product of the probabilities of the lobes taken by splitting,
    /// in `beta` too (see `Branch`).
    split: f32,
    /// `max_element` of the starting throughput (light subpaths' roulette).
    beta_start: f32,
    /// Every vertex so far is specular (and this is a camera subpath).
    specular_prefix: bool,
    /// A light subpath that ends at a mirror or glass as its first bounce
    /// (from a light no ray finds, with `Bdpt::unseen_light_caustics` off).
    no_specular_first: bool,
}

impl Walk {
    fn start(ray: Ray, beta: Vec3, pdf_dir: f32, camera: bool) -> Walk {
        Walk { ray, beta, pdf_dir, radiance_scale: 1.0, split: 1.0, beta_start: beta.max_element(), specular_prefix: camera, no_specular_first: false }
    }

    /// `lobe`, followed for sure: its throughput carries its probability.
    fn split(&mut self, lobe: BsdfSample) -> BsdfSample {
        self.split *= lobe.pdf;
        BsdfSample { weight: lobe.weight * lobe.pdf, ..lobe }
    }
}
