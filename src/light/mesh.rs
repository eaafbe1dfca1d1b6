//! An emissive triangle mesh (a shape whose material emits): when its
//! triangles form one rectangle (CS184's Cornell-box light quad), sampled
//! by solid angle where it subtends enough (`spherical_rect`); else a
//! triangle picked by area, then sampled by its solid angle where that pays
//! (`spherical_triangle`), else by area (CS184 samples every emitter by
//! area). Emission is one-sided, along the triangles' winding.

use super::emission::{Emission, World};
use super::emitter::{area_sample, area_to_solid_angle, cosine_emission, solid_angle_sample, solid_angle_to_area, Emitter};
use super::spherical_rect::RectEmitter;
use super::spherical_triangle::SphericalTriangle;
use super::{EnvAt, LightSample};
use crate::color::illuminance;
use crate::sampling::{magnitude, uniform_triangle};
use crate::scene::{Scene, Shape, TriangleMesh};
use glam::Vec3;
use std::f32::consts::PI;

#[derive(Clone, Debug)]
pub struct MeshLight {
    /// The mesh's geometry id (`Scene::shapes`).
    pub geom_id: u32,
    /// Running sums of the triangles' areas.
    pub cdf: Vec<f32>,
    pub area: f32,
    pub radiance: Vec3,
    /// The mesh as one rectangle, when it is one and sampling by solid
    /// angle is on.
    pub rect: Option<RectEmitter>,
    /// Triangles sampled by their solid angle where that pays.
    pub spherical: bool,
    /// The light pick's view of it: its area at its centroid, facing its
    /// mean normal where its normals agree.
    pub proxy: Option<MeshProxy>,
}

/// An emissive mesh as the light pick sees it.
#[derive(Clone, Copy, Debug)]
pub struct MeshProxy {
    pub center: Vec3,
    pub normal: Option<Vec3>,
    pub area: f32,
}

impl MeshLight {
    /// The light of mesh `geom_id` emitting `radiance`; `None` for a mesh
    /// of no area.
    pub fn new(geom_id: u32, m: &TriangleMesh, radiance: Vec3) -> Option<MeshLight> {
        let mut cdf = Vec::with_capacity(m.triangles.len());
        let mut acc = 0.0f32;
        for t in &m.triangles {
            let [a, b, c] = t.map(|k| m.positions[k as usize]);
            acc += crate::geometry::triangle::area(a, b, c);
            cdf.push(acc);
        }
        if !(acc > 0.0) {
            return None;
        }
        let tris: Vec<[Vec3; 3]> = m.triangles.iter().map(|t| t.map(|k| m.positions[k as usize])).collect();
        Some(MeshLight { geom_id, cdf, area: acc, radiance, rect: RectEmitter::of_triangles(&tris), spherical: true, proxy: proxy_of(m) })
    }

    fn mesh<'a>(&self, scene: &'a Scene) -> Option<&'a TriangleMesh> {
        match &scene.shapes[self.geom_id as usize] {
            Shape::Mesh(m) => Some(m),
            Shape::Sphere { .. } => None,
        }
    }

    /// The triangle `u_sel` picks, by area.
    fn pick(&self, u_sel: f32) -> usize {
        self.cdf.partition_point(|&c| c <= u_sel * self.area).min(self.cdf.len() - 1)
    }

    /// The probability of picking triangle `i` (∝ its area).
    fn triangle_share(&self, i: usize) -> f64 {
        let lo = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        (self.cdf[i] - lo) as f64 / self.area as f64
    }
}

/// The pick's proxy of `m`: its area at its centroid, with its mean
/// normal where its normals agree.
fn proxy_of(m: &TriangleMesh) -> Option<MeshProxy> {
    let (mut area, mut center, mut nsum) = (0.0f32, Vec3::ZERO, Vec3::ZERO);
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| m.positions[i as usize]);
        let cross = (b - a).cross(c - a);
        let ai = 0.5 * cross.length();
        area += ai;
        center += ai * (a + b + c) / 3.0;
        nsum += 0.5 * cross;
    }
    (area > 0.0).then(|| MeshProxy { center: center / area, normal: (nsum.length() > 0.9 * area).then(|| nsum.normalize()), area })
}

impl Emitter for MeshLight {
    fn describe(&self) -> String {
        format!("emissive mesh {} area {} radiance {}{}", self.geom_id, self.area, self.radiance, if self.rect.is_some() { " (a rectangle: sampled by solid angle)" } else { "" })
    }

    fn is_visible(&self) -> bool {
        true
    }

    fn is_hittable(&self) -> bool {
        true
    }

    fn geometry(&self) -> u32 {
        self.geom_id
    }

    fn uses_selection(&self) -> bool {
        true
    }

    fn sample(&self, scene: &Scene, p: Vec3, u: (f32, f32), u_sel: f32, _env_at: EnvAt) -> Option<LightSample> {
        if let Some((r, sr)) = self.rect.and_then(|r| r.from(p).map(|sr| (r, sr))) {
            return solid_angle_sample(p, sr.sample(u), r.normal, magnitude(&[r.corner, r.corner + r.ex + r.ey]), self.radiance, 1.0 / sr.omega);
        }
        let m = self.mesh(scene)?;
        let i = self.pick(u_sel);
        let [a, b, c] = m.triangles[i].map(|k| m.positions[k as usize]);
        let n = crate::geometry::face_normal(a, b, c);
        let s = match SphericalTriangle::new(p, a, b, c).filter(|_| self.spherical && self.rect.is_none()) {
            // One triangle's share of the mesh, uniform in its solid angle.
            Some(st) => solid_angle_sample(p, st.sample(u), n, magnitude(&[a, b, c]), self.radiance, (self.triangle_share(i) / st.omega) as f32).map(|s| LightSample { covers: false, ..s }),
            None => {
                let (bu, bv) = uniform_triangle(u.0, u.1);
                let q = crate::geometry::triangle::point_at(a, b, c, bu, bv);
                area_sample(p, q, n, magnitude(&[a, b, c]), self.radiance, 1.0 / self.area)
            }
        };
        s.map(|s| LightSample { prim: i as u32, ..s })
    }

    /// The same choice `sample` makes from `p`.
    fn pdf_hit(&self, scene: &Scene, p: Vec3, x: Vec3, n: Vec3, prim: u32) -> f32 {
        if let Some(r) = &self.rect {
            if let Some(sr) = r.from(p) {
                return 1.0 / sr.omega;
            }
        }
        if self.rect.is_none() && self.spherical {
            let Some(m) = self.mesh(scene) else { return 0.0 };
            let [a, b, c] = m.triangles[prim as usize].map(|k| m.positions[k as usize]);
            if let Some(st) = SphericalTriangle::new(p, a, b, c) {
                return (self.triangle_share(prim as usize) / st.omega) as f32;
            }
        }
        area_to_solid_angle(1.0 / self.area, p, x, n)
    }

    fn covers(&self, p: Vec3) -> bool {
        self.rect.is_some_and(|r| r.from(p).is_some())
    }

    fn power(&self, _world: &World) -> f32 {
        PI * self.area * illuminance(self.radiance).max(0.0)
    }

    fn emission_pdf_pos(&self, _world: &World) -> f32 {
        1.0 / self.area
    }

    fn emission_pdf_dir(&self, n: Vec3, dir: Vec3) -> f32 {
        n.dot(dir).max(0.0) / PI
    }

    fn sample_pdf_area(&self, scene: &Scene, p: Vec3, q: Vec3, n: Vec3, prim: u32) -> f32 {
        solid_angle_to_area(self.pdf_hit(scene, p, q, n, prim), p, q, n)
    }

    fn normal_at(&self, scene: &Scene, _q: Vec3, prim: u32) -> Vec3 {
        match self.mesh(scene) {
            Some(m) => {
                let [a, b, c] = m.triangles[prim as usize].map(|k| m.positions[k as usize]);
                crate::geometry::face_normal(a, b, c)
            }
            None => Vec3::ZERO,
        }
    }

    fn emit(&self, scene: &Scene, world: &World, u_sel: f32, u_pos: (f32, f32), u_dir: (f32, f32)) -> Option<Emission> {
        let m = self.mesh(scene)?;
        let i = self.pick(u_sel);
        let [a, b, c] = m.triangles[i].map(|k| m.positions[k as usize]);
        let (bu, bv) = uniform_triangle(u_pos.0, u_pos.1);
        let p = crate::geometry::triangle::point_at(a, b, c, bu, bv);
        cosine_emission(p, crate::geometry::face_normal(a, b, c), self.radiance, magnitude(&[a, b, c]), i as u32, self.emission_pdf_pos(world), u_dir)
    }

    fn use_cs184_sampling(&mut self, by_area: bool, _uniform_sky: bool) {
        if by_area {
            (self.rect, self.spherical) = (None, false);
        }
    }

    fn pick_estimate(&self, p: Vec3, n: Vec3) -> Option<f32> {
        Some(self.proxy.map_or(0.0, |m| super::pick::patch(p, n, m.center, m.area, m.normal, self.radiance)))
    }
}
