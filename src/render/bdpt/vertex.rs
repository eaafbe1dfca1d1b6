//! A vertex of a camera or light subpath, with the two densities the MIS
//! weights need (Veach's thesis ch. 10, pbrt-v4's `Vertex`):
//!
//! * `pdf_fwd`: the area density of this vertex, generated from its
//!   predecessor on its own subpath;
//! * `pdf_rev`: the area density of the same vertex generated from its
//!   successor, as if the path had been traced from the other end.
//!
//! Area densities convert solid-angle ones by |cos θ| at the vertex (its
//! geometric normal) / distance²; the camera and point lights have no
//! surface, so no cosine. Through a specular chain the measure changes: a
//! delta (specular) vertex holds the density of the direction that reached
//! it per **projected solid angle at the vertex it left** (÷ |cos θ| there),
//! not per area, and a vertex reached from a delta vertex holds 0 (read as
//! 1). A chain a → δ … δ → b made from either end then carries that end's
//! projected density times the chain's generalized geometry term, the same
//! term both ways (étendue is conserved), so the term cancels from the
//! ratios `mis` takes, which become exact (Veach's thesis §10.3.5; Mitsuba
//! 0.5's `Path::miWeight` converts the same densities). pbrt-v4 keeps both
//! densities of a delta vertex at 0 and so weighs a chain's two ends by
//! G(a, δ) ÷ G(δ, b) too much or too little: on CBspheres that gave the
//! camera paths through the glass ball 70 % of the weight of its caustic,
//! whose light-tracing strategy has 1/70 of their variance.
//!
//! A light at infinity makes a vertex that is a direction, not a point
//! (`Kind::Distant`, as pbrt-v4's infinite-light vertices): densities of
//! it stay per solid angle (no conversion), and the vertex after it on a
//! light subpath has the density of the disk its ray left (`World`)
//! times |cos θ| there, with no distance.
//!
//! Light subpaths scatter with the adjoint BSDF (`f` with `Mode::Importance`):
//! Veach's shading-normal correction |wo·ns||wi·ng| / (|wo·ng||wi·ns|)
//! (thesis §5.3; pbrt-v3 and Mitsuba 3 apply it, pbrt-v4 omits it), and no
//! (η_i/η_t)² on refraction (radiance is scaled at a crossing, importance
//! is not).

use crate::bsdf::Bsdf;
use crate::light::Lights;
use crate::light::emission::LightPower;
use crate::sampling::{offset_ray_origin, Frame};
use crate::scene::{Interaction, Scene};
use glam::Vec3;

/// Which end of the transport a subpath starts from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Mode {
    /// Camera subpaths: radiance flows toward the camera.
    Radiance,
    /// Light subpaths: importance flows toward the lights.
    Importance,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    /// A point on the lens (or the pinhole).
    Camera,
    /// A point on light `k` (`Lights::lights[k]`) where a light subpath or
    /// a next-event connection starts.
    Light(usize),
    /// A surface a subpath reached.
    Surface,
    /// Light `k`, at infinity: the direction toward it is `it.ns`.
    Distant(usize),
    /// A camera subpath that left the scene along `it.ns`; it becomes a
    /// `Distant` vertex of each light at infinity it can see (strategy s = 0).
    Escaped,
}

#[derive(Clone, Copy, Debug)]
pub(crate) struct Vertex {
    pub kind: Kind,
    /// The point, its geometric normal as wound (a light: its emitting side;
    /// the camera: the view axis; a point light: zero), its primitive.
    pub it: Interaction,
    /// The shading frame, its z turned to the side of `wo`.
    pub frame: Frame,
    /// Unit direction toward the predecessor on the subpath (world).
    pub wo: Vec3,
    pub bsdf: Option<Bsdf>,
    /// The subpath's throughput up to and including this vertex's arrival.
    pub beta: Vec3,
    pub pdf_fwd: f32,
    pub pdf_rev: f32,
    /// Scattered by a delta lobe (so nothing connects through it).
    pub delta: bool,
}

impl Vertex {
    /// A vertex that is not a surface: the lens point `p`, or a light's
    /// point `p` with emitting normal `n` (zero for a point light).
    pub fn at_point(kind: Kind, p: Vec3, n: Vec3, magnitude: f32, geom_id: u32, prim_id: u32, beta: Vec3, pdf_fwd: f32) -> Vertex {
        let it = Interaction { p, ng: n, ns: n, t: 0.0, magnitude, edge_room: 0.0, incoming_side: 0.0, geom_id, prim_id };
        let frame = Frame::new(if n == Vec3::ZERO { Vec3::Z } else { n });
        Vertex { kind, it, frame, wo: Vec3::ZERO, bsdf: None, beta, pdf_fwd, pdf_rev: 0.0, delta: false }
    }

    /// The surface at `it`, reached along `-wo`: normals turned to `wo`'s
    /// side as the path tracer turns them (an interpolated normal past the
    /// face falls back to the face's).
    pub fn surface(scene: &Scene, it: Interaction, wo: Vec3, beta: Vec3) -> Vertex {
        let front = it.ng.dot(wo) >= 0.0;
        let flip = if front { 1.0 } else { -1.0 };
        let ng = it.ng * flip;
        let mut ns = it.ns * flip;
        if ns.dot(ng) <= 0.0 {
            ns = ng;
        }
        let bsdf = Bsdf::of(&scene.material_of(it.geom_id).surface, front);
        Vertex { kind: Kind::Surface, it, frame: Frame::new(ns), wo, bsdf, beta, pdf_fwd: 0.0, pdf_rev: 0.0, delta: false }
    }

    /// The vertex of light `k` at infinity in direction `to_light` (unit);
    /// `p`: where its ray left the `World` disk, when it started one.
    pub fn distant(k: usize, p: Vec3, to_light: Vec3, beta: Vec3, pdf_fwd: f32) -> Vertex {
        let it = Interaction { p, ng: Vec3::ZERO, ns: to_light, t: 0.0, magnitude: p.abs().max_element(), edge_room: 0.0, incoming_side: 0.0, geom_id: u32::MAX, prim_id: 0 };
        Vertex { kind: Kind::Distant(k), it, frame: Frame::new(to_light), wo: Vec3::ZERO, bsdf: None, beta, pdf_fwd, pdf_rev: 0.0, delta: false }
    }

    /// A camera subpath's escape along unit `dir`, reached with throughput
    /// `beta` and solid-angle density `pdf_fwd`.
    pub fn escaped(dir: Vec3, beta: Vec3, pdf_fwd: f32) -> Vertex {
        Vertex { kind: Kind::Escaped, ..Vertex::distant(usize::MAX, Vec3::ZERO, dir, beta, pdf_fwd) }
    }

    pub fn p(&self) -> Vec3 {
        self.it.p
    }

    /// Whether this vertex is a direction (a light at infinity, an escape).
    pub fn is_at_infinity(&self) -> bool {
        matches!(self.kind, Kind::Distant(_) | Kind::Escaped)
    }

    /// Unit direction from this vertex toward `other`.
    pub fn dir_to(&self, other: &Vertex) -> Vec3 {
        if other.is_at_infinity() {
            other.it.ns
        } else if self.is_at_infinity() {
            -self.it.ns
        } else {
            (other.p() - self.p()).normalize_or_zero()
        }
    }

    /// Whether densities arriving here are per area of a surface (with a
    /// cosine): surfaces and area lights, not the camera or point lights.
    fn has_normal(&self) -> bool {
        match self.kind {
            Kind::Surface => true,
            Kind::Light(_) => self.it.ng != Vec3::ZERO,
            Kind::Camera | Kind::Distant(_) | Kind::Escaped => false,
        }
    }

    /// Whether a connection can end here: the camera, a light, a surface
    /// with a non-delta BSDF.
    pub fn connectible(&self) -> bool {
        match self.kind {
            Kind::Camera | Kind::Light(_) | Kind::Distant(_) => true,
            Kind::Surface => self.bsdf.is_some_and(|b| !b.is_delta()),
            Kind::Escaped => false,
        }
    }

    /// This vertex's density when made from `from` along a direction of
    /// solid-angle density `pdf` there (a light at infinity: `pdf` is its
    /// disk's area density): per area here (|cos θ| at this vertex ÷
    /// distance², no distance after a light at infinity), or, when this
    /// vertex is a delta (the start of a specular chain), per projected
    /// solid angle at `from` (see the module comment). Kept per solid angle
    /// at a vertex at infinity.
    pub fn density_from(&self, pdf: f32, from: &Vertex) -> f32 {
        if self.is_at_infinity() {
            return pdf;
        }
        if let Kind::Distant(_) = from.kind {
            return if self.delta { pdf } else { pdf * self.cos_ng(from.dir_to(self)) };
        }
        if self.delta {
            let cos = from.cos_ng(from.dir_to(self));
            return if cos > 0.0 { pdf / cos } else { 0.0 };
        }
        let d = self.p() - from.p();
        let d2 = d.length_squared();
        if !(d2 > 0.0) {
            return 0.0;
        }
        let cos = if self.has_normal() { self.it.ng.dot(d).abs() / d2.sqrt() } else { 1.0 };
        pdf * cos / d2
    }

    /// |cos| between the shading normal (a light's normal; 1 for a point
    /// light) and unit direction `w`.
    pub fn cos(&self, w: Vec3) -> f32 {
        match self.kind {
            Kind::Surface => self.frame.n.dot(w).abs(),
            Kind::Distant(_) | Kind::Escaped => 1.0,
            _ if self.it.ng == Vec3::ZERO => 1.0,
            _ => self.it.ng.dot(w).abs(),
        }
    }

    /// The BSDF from `wo` toward point `q` (without the cosine), adjoint in
    /// `Mode::Importance`. At a light vertex: 1 on the emitting side (the
    /// emitters are Lambertian, so the direction changes nothing else).
    pub fn f(&self, q: Vec3, mode: Mode) -> Vec3 {
        self.f_dir((q - self.p()).normalize_or_zero(), mode)
    }

    /// `f` toward unit direction `wi`.
    pub fn f_dir(&self, wi: Vec3, mode: Mode) -> Vec3 {
        match self.kind {
            Kind::Surface => {
                let Some(b) = &self.bsdf else { return Vec3::ZERO };
                let f = b.eval(self.frame.to_local(self.wo), self.frame.to_local(wi));
                match mode {
                    Mode::Radiance => f,
                    Mode::Importance => f * self.shading_correction(wi),
                }
            }
            Kind::Light(_) => {
                if self.it.ng == Vec3::ZERO || self.it.ng.dot(wi) > 0.0 {
                    Vec3::ONE
                } else {
                    Vec3::ZERO
                }
            }
            Kind::Distant(_) => Vec3::ONE,
            Kind::Camera | Kind::Escaped => Vec3::ZERO,
        }
    }

    /// |cos θ| between this surface's geometric normal and unit `w`: the
    /// disk density of a ray from a light at infinity, per area here.
    pub fn cos_ng(&self, w: Vec3) -> f32 {
        if self.has_normal() {
            self.it.ng.dot(w).abs()
        } else {
            1.0
        }
    }

    /// Veach's adjoint correction for shading normals, |wo·ns||wi·ng| /
    /// (|wo·ng||wi·ns|): without it a light subpath over interpolated
    /// normals does not converge to what the camera sees.
    pub fn shading_correction(&self, wi: Vec3) -> f32 {
        let (ns, ng) = (self.frame.n, self.it.ng);
        let den = self.wo.dot(ng).abs() * wi.dot(ns).abs();
        if den > 0.0 {
            self.wo.dot(ns).abs() * wi.dot(ng).abs() / den
        } else {
            0.0
        }
    }

    /// The area density with which this vertex, having been reached from
    /// `prev` (ignored by the camera and lights), generates `next`.
    pub fn pdf(&self, lights: &Lights, power: &LightPower, camera: &crate::camera::importance::Sensor, prev: Option<&Vertex>, next: &Vertex) -> f32 {
        let w = self.dir_to(next);
        let pdf_dir = match self.kind {
            Kind::Camera => camera.pdf_dir(self.p(), w),
            Kind::Light(k) => lights.lights[k].emission_pdf_dir(self.it.ng, w),
            Kind::Distant(_) => power.world().disk_pdf(),
            Kind::Surface => {
                let (Some(b), Some(prev)) = (&self.bsdf, prev) else { return 0.0 };
                let wo = self.dir_to(prev);
                b.pdf(self.frame.to_local(wo), self.frame.to_local(w))
            }
            Kind::Escaped => return 0.0,
        };
        next.density_from(pdf_dir, self)
    }

    /// The light this vertex lies on: a light vertex's, or the emitter a
    /// surface vertex hit.
    pub fn light(&self, lights: &Lights) -> Option<usize> {
        match self.kind {
            Kind::Light(k) | Kind::Distant(k) => Some(k),
            Kind::Surface => lights.of_geometry.get(self.it.geom_id as usize).copied().flatten(),
            Kind::Camera | Kind::Escaped => None,
        }
    }

    /// The area density of this emitter point as the start of a light
    /// subpath: the light's pick probability × its position density (for a
    /// light at infinity, × the density of its direction).
    pub fn pdf_light_origin(&self, lights: &Lights, power: &LightPower) -> f32 {
        match (self.kind, self.light(lights)) {
            (Kind::Distant(k), _) => power.pmf(k) * lights.lights[k].infinite_pdf_dir(self.it.ns),
            (_, Some(k)) => power.pmf(k) * lights.lights[k].emission_pdf_pos(power.world()),
            (_, None) => 0.0,
        }
    }

    /// The area density of `next` as the second vertex of a light subpath
    /// leaving this emitter point.
    pub fn pdf_light(&self, lights: &Lights, power: &LightPower, next: &Vertex) -> f32 {
        let Some(k) = self.light(lights) else { return 0.0 };
        let pdf = match self.kind {
            Kind::Distant(_) => power.world().disk_pdf(),
            _ => lights.lights[k].emission_pdf_dir(self.it.ng, self.dir_to(next)),
        };
        next.density_from(pdf, self)
    }

    /// A point just off this vertex's surface toward `toward`, as a shadow
    /// segment's end.
    pub fn offset_toward(&self, toward: Vec3) -> Vec3 {
        let n = self.it.ng;
        if n == Vec3::ZERO {
            return self.p();
        }
        let side = if (toward - self.p()).dot(n) >= 0.0 { n } else { -n };
        offset_ray_origin(self.p(), side, self.it.magnitude)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 0 read as 1, as `mis` reads densities.
    fn r0(x: f32) -> f64 {
        if x == 0.0 {
            1.0
        } else {
            x as f64
        }
    }

    fn point(kind: Kind, p: Vec3, n: Vec3) -> Vertex {
        Vertex::at_point(kind, p, n.normalize(), 1.0, 0, 0, Vec3::ONE, 0.0)
    }

    /// Through a planar mirror the true path densities of the two ways to
    /// make a → m → b (from a, or from b) have the closed form of the
    /// unfolded path: p_A(a)·p_a·|cos_b|/D² and p_A(b)·p_b·|cos_a|/D², D the
    /// unfolded length. The chain of densities `mis` multiplies must give
    /// their ratio exactly; per-area densities at the mirror (pbrt-v4's
    /// zeros) give it off by (|a − m| / |m − b|)² × cosines.
    #[test]
    fn density_ratios_through_a_mirror_are_the_true_path_density_ratios() {
        let a_pos = Vec3::new(0.0, 1.5, 0.2);
        let light = point(Kind::Light(0), a_pos, Vec3::new(0.3, -1.0, 0.0));
        let floor_pos = Vec3::new(0.2, 0.0, -0.3);
        let floor = point(Kind::Surface, floor_pos, Vec3::Y);
        // The mirror x = 1: b reflected to b', the mirror point on a → b'.
        let b_image = Vec3::new(2.0 - floor_pos.x, floor_pos.y, floor_pos.z);
        let m_pos = a_pos + (b_image - a_pos) * ((1.0 - a_pos.x) / (b_image.x - a_pos.x));
        let mut mirror = point(Kind::Surface, m_pos, Vec3::NEG_X);
        mirror.delta = true;
        let unfolded = (b_image - a_pos).length() as f64;
        let (pa_area, pa_dir, pb_area, pb_dir) = (0.7f32, 0.45f32, 2.3f32, 0.31f32);
        let cos_a = light.cos_ng(light.dir_to(&mirror)) as f64;
        let cos_b = floor.cos_ng(floor.dir_to(&mirror)) as f64;
        let from_a = pa_area as f64 * pa_dir as f64 * cos_b / (unfolded * unfolded);
        let from_b = pb_area as f64 * pb_dir as f64 * cos_a / (unfolded * unfolded);
        // `mis`'s chain from b back to a: rev/fwd at b, m, then a.
        let fwd_b = floor.density_from(0.0, &mirror);
        let (rev_m, fwd_m) = (mirror.density_from(pb_dir, &floor), mirror.density_from(pa_dir, &light));
        let rev_a = light.density_from(0.0, &mirror);
        let chain = r0(pb_area) / r0(fwd_b) * r0(rev_m) / r0(fwd_m) * r0(rev_a) / r0(pa_area);
        assert!((chain / (from_b / from_a) - 1.0).abs() < 1e-5, "chain {chain}, true ratio {}", from_b / from_a);
    }

    /// A light at infinity through the same mirror: from the light, a
    /// direction (p_dir) and a disk point (p_disk per area across the beam,
    /// |cos_b| per area at b); from b, a direction that the mirror sends to
    /// infinity unchanged in measure.
    #[test]
    fn density_ratios_from_a_light_at_infinity_through_a_mirror_are_exact() {
        let floor = point(Kind::Surface, Vec3::new(0.2, 0.0, -0.3), Vec3::Y);
        let mut mirror = point(Kind::Surface, Vec3::new(1.0, 0.8, 0.1), Vec3::NEG_X);
        mirror.delta = true;
        // The sun's direction after the mirror: toward the floor point.
        let down = (floor.p() - mirror.p()).normalize();
        let incoming = Vec3::new(-down.x, down.y, down.z);
        let sun = Vertex::distant(0, mirror.p() - incoming * 3.0, -incoming, Vec3::ONE, 0.0);
        let (p_dir, p_disk, pb_area, pb_dir) = (0.9f32, 0.05f32, 1.7f32, 0.4f32);
        let cos_b = floor.cos_ng(-down) as f64;
        let from_sun = p_dir as f64 * p_disk as f64 * cos_b;
        let from_b = pb_area as f64 * pb_dir as f64;
        let fwd_b = floor.density_from(0.0, &mirror);
        let (rev_m, fwd_m) = (mirror.density_from(pb_dir, &floor), mirror.density_from(p_disk, &sun));
        let rev_sun = sun.density_from(0.0, &mirror);
        let chain = r0(pb_area) / r0(fwd_b) * r0(rev_m) / r0(fwd_m) * r0(rev_sun) / r0(p_dir);
        assert!((chain / (from_b / from_sun) - 1.0).abs() < 1e-5, "chain {chain}, true ratio {}", from_b / from_sun);
    }
}
