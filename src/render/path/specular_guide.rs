//! Directions towards specular and glossy objects, mixed into a diffuse
//! vertex's BSDF sampling, so that caustics (light reaching a diffuse
//! surface through a mirror, glass or a glossy metal) are found by more
//! than the few cosine samples that happen to hit those objects.
//!
//! Model: the *targets* are the scene's objects whose material reflects or
//! transmits non-diffusely (mirror, glass, CS184 refraction, microfacet)
//! with a brightest channel of at least `MIN_ALBEDO`, each bounded by a
//! sphere (a sphere by itself, a mesh by the sphere around its bounding
//! box). At a diffuse vertex the continuation direction comes from the
//! one-sample mixture
//!
//!   p(ω) = (1 − q) · cos θ / π + q · (1/n) Σ_k 1[ω ∈ cone_k] / Ω_k
//!
//! over the n targets whose cone of directions is not wholly below the
//! surface (`GuideAt`), with cone_k uniform in solid angle (`SphereCone`).
//! The throughput weight is f cos / p and the MIS pdf of the ray is p, so
//! the estimator is unbiased for any q < 1: the cosine part keeps every
//! direction of the hemisphere sampled.
//!
//! Why it pays: in the Cornell boxes a sphere fills ~0.1 sr of a wall's
//! view, so cosine sampling sends ~3 % of the rays at it, and the light
//! reflected or refracted through it arrives as rare, bright samples; in
//! CBspheres these caustic paths (diffuse → specular chain → light) carry
//! 82 % of the variance (measured by dropping them: 256×192, 256 spp,
//! relMSE 1.6e-3 → 2.8e-4). Measured (8 seeds × 64 spp, 256×192, 1
//! thread, relMSE × time against q = 0, q = 0.2): CBspheres,
//! CBspheres_refract and the microfacet Al/Ag spheres 1.44× each, the
//! copper bunny 1.23–1.27×, CBgems' three glass gems 1.04–1.05×; q =
//! 0.15–0.25 alike, 0.35 less. It does not remove the rest: within a cone
//! only a few per cent of the directions lead on to the light, a mesh's
//! bounding cone also holds directions that pass beside it, and the
//! ceiling lit by the glass sphere's bright spot on the floor is found by
//! the floor's rays, where the sphere fills a wide cone.
//!
//! CS184, Mitsuba's `path` and Cycles' path tracer sample a diffuse bounce
//! by its cosine alone. This is not path guiding in general (no learned
//! distribution): it only knows where the non-diffuse objects are.
//! Scenes with more than `MAX_TARGETS` targets get no guide (the pdf sums
//! over them at every diffuse vertex), with a note.

use crate::light::sphere_cone::{ConeBound, SphereCone};
use crate::scene::{material, Scene, Shape};
use glam::Vec3;

/// More targets than this and the per-vertex sum costs more than it saves.
pub const MAX_TARGETS: usize = 16;

/// Default share `q` of a diffuse vertex's continuation rays aimed at the
/// targets (`--specular-guide`).
pub const DEFAULT_FRACTION: f32 = 0.2;

/// Objects reflecting or transmitting less than this (their brightest
/// channel, at normal incidence) are not aimed at: their caustics are dim,
/// and the rays aimed at them are taken from the cosine lobe, whose other
/// directions then weigh 1/(1 − q) more. Measured (8 seeds × 64 spp,
/// 256×192, relMSE × time against q = 0): CBcoil's mirror coil of
/// reflectance 0.3 lost (0.82×), the copper bunny (F0 up to 0.95) gained
/// 1.27×, CBgems' glass gems 1.04×.
pub const MIN_ALBEDO: f32 = 0.5;

/// The brightest channel of what a material reflects or transmits
/// non-diffusely (at normal incidence); 0 for diffuse and emitters.
fn specular_albedo(b: &material::Surface) -> f32 {
    match *b {
        material::Surface::Diffuse { .. } | material::Surface::Emission { .. } => 0.0,
        material::Surface::Mirror { reflectance } => reflectance.max_element(),
        material::Surface::Glass { reflectance, transmittance, .. } => reflectance.max(transmittance).max_element(),
        material::Surface::Refraction { transmittance, .. } => transmittance.max_element(),
        material::Surface::Microfacet { eta, k, .. } => crate::bsdf::fresnel::conductor(1.0, eta, k).max_element(),
    }
}

/// The bounding sphere of one specular or glossy object.
#[derive(Clone, Copy, Debug)]
struct Target {
    center: Vec3,
    radius: f32,
}

#[derive(Clone, Debug)]
pub struct SpecularGuide {
    targets: Vec<Target>,
    /// The mixture's share `q` of guided directions, in (0, 1).
    pub fraction: f32,
}

impl SpecularGuide {
    /// The guide for `scene`'s bright non-diffuse, non-emissive objects, or
    /// `None` when there are none, more than `MAX_TARGETS` (then with a
    /// note to print), or `fraction` is not in (0, 1) (0 turns guiding off).
    pub fn of_scene(scene: &Scene, fraction: f32) -> (Option<SpecularGuide>, Option<String>) {
        if !(fraction > 0.0 && fraction < 1.0) {
            return (None, None);
        }
        let mut targets = Vec::new();
        for (g, shape) in scene.shapes.iter().enumerate() {
            let m = scene.material_of(g as u32);
            if m.emission != Vec3::ZERO || specular_albedo(&m.surface) < MIN_ALBEDO {
                continue;
            }
            let t = match shape {
                Shape::Sphere { center, radius } => Target { center: *center, radius: *radius },
                Shape::Mesh(mesh) => {
                    if mesh.positions.is_empty() {
                        continue;
                    }
                    let center = shape.bounds().center();
                    // Rounded up so that every vertex is inside.
                    let r = mesh.positions.iter().map(|p| (*p - center).length()).fold(0.0f32, f32::max);
                    Target { center, radius: r * (1.0 + 1e-5) + f32::EPSILON * center.abs().max_element() }
                }
            };
            if t.radius > 0.0 && t.radius.is_finite() {
                targets.push(t);
            }
        }
        match targets.len() {
            0 => (None, None),
            n if n > MAX_TARGETS => (None, Some(format!("{n} mirror, glass or metal objects: more than {MAX_TARGETS}, so diffuse bounces are not aimed at them (--specular-guide)"))),
            _ => (Some(SpecularGuide { targets, fraction }), None),
        }
    }

    /// The targets as seen from `p` on a surface with normal `n`: those
    /// `p` is clearly outside of (`SphereCone::new`) and whose cone reaches
    /// above the tangent plane.
    pub fn at(&self, p: Vec3, n: Vec3) -> GuideAt<'_> {
        let mut at = None;
        self.at_in(p, n, &mut at);
        at.expect("at_in fills the slot")
    }

    /// `at`, made in `slot` (reused from one vertex to the next): a
    /// `GuideAt` holds 16 cones, 304 bytes, and returning it by value cost
    /// a copy per diffuse vertex, 3.8 % of a CBgems render in `memcpy`.
    pub fn at_in<'g, 'b>(&'g self, p: Vec3, n: Vec3, slot: &'b mut Option<GuideAt<'g>>) -> &'b GuideAt<'g> {
        let at = slot.get_or_insert_with(|| GuideAt { guide: self, p, cones: [ConeBound::default(); MAX_TARGETS], which: [0; MAX_TARGETS], len: 0 });
        at.guide = self;
        at.p = p;
        at.len = 0;
        for (k, t) in self.targets.iter().enumerate() {
            if (t.center - p).dot(n) <= -t.radius {
                continue;
            }
            if let Some(cone) = SphereCone::new(p, t.center, t.radius) {
                at.cones[at.len] = cone.bound();
                at.which[at.len] = k as u8;
                at.len += 1;
            }
        }
        at
    }
}

/// The guide's cones from one vertex: the first `len` entries, each a
/// target's axis and aperture (`ConeBound`) and its index. Only the cone a
/// sample picks is made whole (`SphereCone`, with its frame), so a vertex
/// that only weighs light samples or draws from the cosine copies and
/// builds a fraction of it (whole cones here cost 5 % of a copper-bunny
/// render in copies alone).
pub struct GuideAt<'g> {
    guide: &'g SpecularGuide,
    p: Vec3,
    cones: [ConeBound; MAX_TARGETS],
    which: [u8; MAX_TARGETS],
    len: usize,
}

impl GuideAt<'_> {
    /// The cones in view.
    fn cones(&self) -> impl Iterator<Item = &ConeBound> {
        self.cones[..self.len].iter()
    }

    /// The mixture's guided share here: 0 when no target is in view.
    pub fn fraction(&self) -> f32 {
        if self.len == 0 {
            0.0
        } else {
            self.guide.fraction
        }
    }

    /// A direction uniform in the cone of the target `u_pick` ∈ [0, 1)
    /// picks (all equally likely), from the 2D draw `u`, and that cone's
    /// index for `pdf`.
    pub fn sample(&self, u_pick: f32, u: (f32, f32)) -> Option<(Vec3, usize)> {
        if self.len == 0 {
            return None;
        }
        let k = ((u_pick * self.len as f32) as usize).min(self.len - 1);
        // The same cone `at` found: `SphereCone::new` of the same inputs.
        let t = self.guide.targets[self.which[k] as usize];
        SphereCone::new(self.p, t.center, t.radius).map(|cone| (cone.sample(u).0, k))
    }

    /// The guided part's pdf of direction `w` (unit): (1/n) Σ over the
    /// cones containing it of 1/Ω. `from`: the cone `w` was sampled in,
    /// counted as containing it even where rounding put `w` a hair outside
    /// its rim (those rim samples would otherwise be weighted as if only
    /// the cosine could have drawn them).
    pub fn pdf(&self, w: Vec3, from: Option<usize>) -> f32 {
        // A sample the cosine drew inside a cone but judged outside would
        // count that part of the cone twice (once per strategy), hence the
        // exact test (`SphereCone::contains`).
        let sum: f32 = self.cones().enumerate().filter(|&(k, c)| from == Some(k) || c.contains(w)).map(|(_, c)| c.pdf()).sum();
        sum / self.len.max(1) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;
    use crate::sampling::{cosine_hemisphere, uniform_sphere};
    use std::f32::consts::PI;

    /// Up (+z) at the origin: one sphere overhead, one straddling the
    /// horizon, one wholly below it (not a target from here).
    fn guide(q: f32) -> SpecularGuide {
        let targets = vec![
            Target { center: Vec3::new(0.5, 0.2, 2.0), radius: 0.4 },
            Target { center: Vec3::new(2.0, 0.0, 0.1), radius: 0.5 },
            Target { center: Vec3::new(0.0, 0.0, -3.0), radius: 1.0 },
        ];
        SpecularGuide { targets, fraction: q }
    }

    /// Draws the mixture as the path tracer does; `(ω, p(ω))` with ω
    /// possibly below the surface (the path tracer ends those paths).
    fn draw(at: &GuideAt, rng: &mut Rng) -> Option<(Vec3, f32)> {
        let q = at.fraction();
        let pick = rng.uniform();
        let u = rng.uniform2();
        let (w, from) = if pick < q {
            let (w, k) = at.sample(pick / q, u)?;
            (w, Some(k))
        } else {
            (cosine_hemisphere(u.0, u.1), None)
        };
        let cos_pdf = if w.z > 0.0 { w.z / PI } else { 0.0 };
        Some((w, (1.0 - q) * cos_pdf + q * at.pdf(w, from)))
    }

    /// Mean and standard error.
    fn mean_se(x: &[f64]) -> (f64, f64) {
        let n = x.len() as f64;
        let m = x.iter().sum::<f64>() / n;
        let v = x.iter().map(|a| (a - m) * (a - m)).sum::<f64>() / (n - 1.0);
        (m, (v / n).sqrt())
    }

    #[test]
    fn targets_below_the_surface_or_around_the_point_are_skipped() {
        let g = guide(0.25);
        let at = g.at(Vec3::ZERO, Vec3::Z);
        assert_eq!(at.len, 2, "the sphere below the horizon is no target");
        // Inside the first sphere, above the other two: none.
        let inside = g.at(Vec3::new(0.5, 0.2, 2.1), Vec3::Z);
        assert_eq!((inside.len, inside.fraction()), (0, 0.0));
        // Facing down: the sphere below and the one across the horizon.
        assert_eq!(g.at(Vec3::ZERO, -Vec3::Z).len, 2);
    }

    #[test]
    fn the_mixture_pdf_is_the_density_it_samples() {
        // E[g/p] over mixture draws equals ∫ g dω for: the cosine over the
        // upper hemisphere (π), the upper hemisphere (2π), and each cone's
        // part above the horizon (the first: 2π(1 − cos θmax) exactly; the
        // second, cut by the horizon: by uniform sphere sampling). A wrong
        // pdf anywhere the mixture samples shifts one of them.
        for q in [0.2f32, 0.6] {
            let g = guide(q);
            let at = g.at(Vec3::ZERO, Vec3::Z);
            let cones: Vec<ConeBound> = at.cones().copied().collect();
            let inside = |w: Vec3, k: usize| cones[k].contains(w) && w.z > 0.0;
            let mut rng = Rng::new(17, q.to_bits() as u64);
            let n = 400_000;
            let mut est: [Vec<f64>; 4] = Default::default();
            for _ in 0..n {
                let (cos, hemi, c0, c1) = match draw(&at, &mut rng) {
                    Some((w, p)) if w.z > 0.0 => {
                        assert!(p > 0.0 && p.is_finite(), "p({w}) = {p}");
                        let p = p as f64;
                        (w.z as f64 / p, 1.0 / p, if inside(w, 0) { 1.0 / p } else { 0.0 }, if inside(w, 1) { 1.0 / p } else { 0.0 })
                    }
                    _ => (0.0, 0.0, 0.0, 0.0),
                };
                for (e, v) in est.iter_mut().zip([cos, hemi, c0, c1]) {
                    e.push(v);
                }
            }
            // The second cone's upper part by uniform directions.
            let mut uni = Vec::with_capacity(n);
            for _ in 0..n {
                let (a, b) = rng.uniform2();
                let w = uniform_sphere(a, b);
                uni.push(if inside(w, 1) { 4.0 * std::f64::consts::PI } else { 0.0 });
            }
            let (c1_exact, c1_se) = mean_se(&uni);
            let exact = [std::f64::consts::PI, 2.0 * std::f64::consts::PI, 1.0 / cones[0].pdf() as f64, c1_exact];
            for (k, (e, x)) in est.iter().zip(exact).enumerate() {
                let (m, se) = mean_se(e);
                let se = if k == 3 { (se * se + c1_se * c1_se).sqrt() } else { se };
                assert!((m - x).abs() < 5.0 * se + 1e-9 * x, "q {q}, integral {k}: {m} ± {se} against {x}");
            }
        }
    }

    #[test]
    fn directions_just_inside_a_far_cone_are_in_it() {
        // A sphere seen under 1e-3 rad: directions at 0.999 and 1.001 of
        // its angular radius, all around the axis.
        let (dist, r) = (40.0f32, 0.04f32);
        let g = SpecularGuide { targets: vec![Target { center: Vec3::new(0.0, 0.0, dist), radius: r }], fraction: 0.5 };
        let at = g.at(Vec3::ZERO, Vec3::Z);
        let theta = (r / dist).asin();
        for i in 0..64 {
            let phi = i as f32 * 0.1;
            let dir = |t: f32| Vec3::new(t.sin() * phi.cos(), t.sin() * phi.sin(), t.cos());
            assert!(at.pdf(dir(0.999 * theta), None) > 0.0, "inside at φ {phi}");
            assert_eq!(at.pdf(dir(1.001 * theta), None), 0.0, "outside at φ {phi}");
        }
    }

    #[test]
    fn rim_samples_count_their_own_cone() {
        // Draws at the rim of a tiny cone (u → 1): whatever rounding does
        // to the direction, its own cone's density is in its pdf.
        let g = SpecularGuide { targets: vec![Target { center: Vec3::new(0.3, -0.2, 40.0), radius: 0.05 }], fraction: 0.5 };
        let at = g.at(Vec3::ZERO, Vec3::Z);
        let omega = 1.0 / at.cones().next().unwrap().pdf();
        for i in 0..1000 {
            let (w, k) = at.sample(0.3, (1.0 - i as f32 * 1e-7, i as f32 / 1000.0)).unwrap();
            assert!((at.pdf(w, Some(k)) * omega - 1.0).abs() < 1e-4);
        }
    }
}
