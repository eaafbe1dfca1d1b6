//! Emitters, one model for every integrator.
//!
//! * Emissive surfaces (triangle meshes and spheres with an `<emission>`
//!   material) are lights: light sampling picks points on them, and a ray that
//!   hits one sees its radiance. Emission is **one-sided**, on the side the
//!   geometric normal points to (the triangle winding; outward for spheres).
//! * A CGL `<area>` light that has a visible emissive proxy (coplanar,
//!   overlapping, same radiance, as in every CS184 Cornell box) is merged into
//!   it: the proxy is the one emitter.
//! * Lights without a proxy stay as they are: point lights (the file's colour
//!   is the intensity, falling off as 1/r^2), directional lights (colour =
//!   irradiance), the hemisphere ("ambient") light (radiance from every
//!   direction with y > 0, seen by rays that escape), and proxy-less
//!   rectangular area lights (not geometry, so only light sampling sees them).
//! * The environment light (`-e FILE.exr`, see `environment`): radiance from
//!   every direction, seen by escaping rays, importance sampled: by the map
//!   × a bound of the receiver's cosine (`env_product`), inside the lobe at
//!   glossy vertices (`env_lobe`), by the map alone where light passes
//!   through (`EnvAt`).
//! * Lights of zero radiance (the `_unlit` scenes' sky) are dropped.
//! * Sampling (CS184 samples every emitter by area): rectangles — area
//!   lights and two-triangle rectangular meshes — by solid angle
//!   (`spherical_rect`), spheres seen from outside by their cone
//!   (`sphere_cone`), the hemisphere light at diffuse vertices by the lune
//!   (`lune`); other meshes pick a triangle by area, then sample it by its
//!   solid angle where that pays (`spherical_triangle`), else by area.
//!   `pdf_hit` applies the same choice.

pub mod emission;
pub mod env_lobe;
pub mod env_product;
pub mod environment;
pub mod lune;
pub mod pick;
pub mod sphere_cone;
pub mod spherical_rect;
pub mod spherical_triangle;

use spherical_rect::RectEmitter;
use spherical_triangle::SphericalTriangle;

pub use environment::EnvMap;

use crate::error::Result;
use crate::sampling::{magnitude, offset_ray_origin, uniform_hemisphere, uniform_sphere, uniform_triangle, UNIFORM_HEMISPHERE_PDF};
use crate::scene::{Interaction, LightKind, Scene, Shape};
use glam::{Vec3, Vec4Swizzles};
use std::sync::Arc;
use std::f32::consts::PI;

/// How the environment light is sampled at a vertex (the BSDF sample's
/// MIS weight uses the same): by the map alone, by the map × a bound of
/// the cosine of a receiver with this shading normal (`env_product`), or
/// inside a glossy lobe's cone (`env_lobe`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EnvAt {
    Map,
    Cosine(Vec3),
    Lobe(env_lobe::Lobe),
}

#[derive(Clone, Debug)]
pub enum Light {
    Point { position: Vec3, intensity: Vec3 },
    Directional { to_light: Vec3, irradiance: Vec3 },
    /// CS184's "ambient": uniform radiance over the upper (+y) hemisphere of
    /// directions; `lune`: sampled by the lune at diffuse vertices.
    Hemisphere { radiance: Vec3, lune: bool },
    /// A one-sided rectangle `corner + s*ex + t*ey`, `s, t ∈ [0, 1]`, emitting
    /// towards `normal`; sampled by solid angle (`solid_angle`: the
    /// rectangle as `RectEmitter`, when its edges are orthogonal and that
    /// sampling is on) where it subtends enough, else by area.
    Rect { corner: Vec3, ex: Vec3, ey: Vec3, normal: Vec3, radiance: Vec3, solid_angle: Option<RectEmitter> },
    /// The triangles of an emissive mesh: when they form one rectangle
    /// (`rect`), sampled by solid angle where it subtends enough; else a
    /// triangle picked by area, then sampled by its solid angle where that
    /// pays (`spherical`, see `spherical_triangle`), else by area.
    Mesh { geom_id: u32, cdf: Vec<f32>, area: f32, radiance: Vec3, rect: Option<RectEmitter>, spherical: bool },
    /// An emissive sphere; sampled by its cone from outside (`cone`), else by area.
    Sphere { center: Vec3, radius: f32, radiance: Vec3, cone: bool },
    /// A latitude-longitude environment map (`-e`).
    Environment(Arc<EnvMap>),
}

/// Where a shadow ray must reach.
#[derive(Clone, Copy, Debug)]
pub enum Target {
    /// A point: the ray stops just short of it.
    Point(Vec3),
    /// Infinitely far in direction `wi`.
    Infinite,
}

#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the shading point to the light.
    pub wi: Vec3,
    /// Radiance (area and environment lights), or intensity/r^2 or
    /// irradiance (delta lights) arriving along `wi`.
    pub value: Vec3,
    /// Solid-angle pdf of `wi`; 1 for delta lights.
    pub pdf: f32,
    pub target: Target,
    /// Drawn uniformly over the whole solid angle the light subtends from
    /// the shading point (`Light::covers`).
    pub covers: bool,
    /// The primitive the sample lies on (a mesh's triangle; 0 otherwise), as
    /// `pdf_hit` takes it.
    pub prim: u32,
}

impl Light {
    pub fn is_delta(&self) -> bool {
        matches!(self, Light::Point { .. } | Light::Directional { .. })
    }

    /// Whether rays can hit this emitter (so hemisphere sampling finds it).
    pub fn is_visible(&self) -> bool {
        matches!(self, Light::Mesh { .. } | Light::Sphere { .. } | Light::Hemisphere { .. } | Light::Environment(_))
    }

    pub fn describe(&self) -> String {
        match self {
            Light::Point { position, intensity } => format!("point at {position} intensity {intensity}"),
            Light::Directional { to_light, irradiance } => format!("directional towards {to_light} irradiance {irradiance}"),
            Light::Hemisphere { radiance, .. } => format!("hemisphere (+y) radiance {radiance}"),
            Light::Rect { corner, ex, ey, radiance, .. } => format!("rectangle at {corner} {}x{} radiance {radiance}", ex.length(), ey.length()),
            Light::Mesh { geom_id, area, radiance, rect, .. } => format!(
                "emissive mesh {geom_id} area {area} radiance {radiance}{}",
                if rect.is_some() { " (a rectangle: sampled by solid angle)" } else { "" }
            ),
            Light::Sphere { center, radius, radiance, .. } => format!("emissive sphere at {center} r {radius} radiance {radiance}"),
            Light::Environment(e) => format!("environment map {} ({}x{})", e.path, e.width, e.height),
        }
    }

    /// Solid-angle pdf with which `sample` from `p` picks the point `x` (normal
    /// `n`, on primitive `prim`) of this emitter's surface; 0 for lights that
    /// are not surfaces.
    pub fn pdf_hit(&self, scene: &Scene, p: Vec3, x: Vec3, n: Vec3, prim: u32) -> f32 {
        // The same choice `sample` makes from `p`.
        if let Light::Mesh { rect: Some(r), .. } = self {
            if let Some(sr) = r.from(p) {
                return 1.0 / sr.omega;
            }
        }
        if let Light::Mesh { geom_id, cdf, area, rect: None, spherical: true, .. } = self {
            let Shape::Mesh(m) = &scene.shapes[*geom_id as usize] else { return 0.0 };
            let [a, b, c] = m.triangles[prim as usize].map(|k| m.positions[k as usize]);
            if let Some(st) = SphericalTriangle::new(p, a, b, c) {
                return (triangle_share(cdf, prim as usize, *area) / st.omega) as f32;
            }
        }
        if let Light::Sphere { center, radius, cone: true, .. } = self {
            if let Some(cone) = sphere_cone::SphereCone::new(p, *center, *radius) {
                return cone.pdf();
            }
        }
        let pdf_area = match self {
            Light::Mesh { area, .. } => 1.0 / area,
            Light::Sphere { radius, .. } => 1.0 / (4.0 * PI * radius * radius),
            _ => return 0.0,
        };
        let d = x - p;
        let dist2 = d.length_squared();
        let cos = n.dot(d).abs() / dist2.sqrt();
        if cos > 0.0 {
            pdf_area * dist2 / cos
        } else {
            0.0
        }
    }

    /// Whether `sample` from `p` draws directions uniformly over the whole
    /// solid angle this emitter subtends (a rectangle by solid angle, a
    /// sphere by its cone) — the same choice `sample` makes. For a diffuse
    /// receiver such samples are already the BSDF's shape but for the
    /// cosine, so light sampling alone estimates that light (see
    /// `PathTracer::alone`).
    pub fn covers(&self, p: Vec3) -> bool {
        match self {
            Light::Mesh { rect: Some(r), .. } => r.from(p).is_some(),
            Light::Sphere { center, radius, cone: true, .. } => sphere_cone::SphereCone::new(p, *center, *radius).is_some(),
            _ => false,
        }
    }

    /// Radiance this light sends along `-dir` to a ray escaping along `dir`
    /// (0 for lights that are not at infinity).
    pub fn escaped(&self, dir: Vec3) -> Vec3 {
        match self {
            Light::Hemisphere { radiance, .. } if dir.y > 0.0 => *radiance,
            Light::Environment(e) => e.eval(dir),
            _ => Vec3::ZERO,
        }
    }

    /// Solid-angle pdf of `sample` for an escaping direction (hemisphere
    /// light, environment map), with the same `env_at` as `sample`.
    pub fn pdf_escape(&self, dir: Vec3, env_at: EnvAt) -> f32 {
        match self {
            Light::Hemisphere { .. } if dir.y > 0.0 => UNIFORM_HEMISPHERE_PDF,
            Light::Environment(e) => match (env_at, &e.product, &e.lobe) {
                (EnvAt::Lobe(l), Some(pr), Some(lobes)) => lobes.pdf(pr, e, &l, dir),
                (EnvAt::Cosine(n), Some(pr), _) => pr.pdf(e, n, dir),
                (EnvAt::Map, _, _) => e.pdf(dir),
                _ => 0.0,
            },
            _ => 0.0,
        }
    }

    /// Whether `sample` uses its `u_sel` (to pick a triangle of a mesh).
    pub fn uses_selection(&self) -> bool {
        matches!(self, Light::Mesh { .. })
    }

    /// Sample light arriving at `p`. `u` are two uniforms, `u_sel` a third
    /// (triangle selection). An environment map is sampled as `env_at`
    /// says (`EnvAt`: the map alone, × a receiver's cosine bound, or inside
    /// a glossy lobe). `None`
    /// when the sample carries no light (the back of a one-sided emitter, a
    /// degenerate configuration).
    pub fn sample(&self, scene: &Scene, p: Vec3, u: (f32, f32), u_sel: f32, env_at: EnvAt) -> Option<LightSample> {
        match self {
            Light::Point { position, intensity } => {
                let d = *position - p;
                let r2 = d.length_squared();
                // The shadow ray stops short of the light: by OFFSET_ULPS ulps of its
                // position, as for area lights, and by at least 2^-13 of the
                // distance. A point light sitting on a surface (CBempty's lies in
                // the plane of its emissive quad) is then not shadowed by that
                // surface, whatever the rounding of a grazing shadow ray; Mitsuba
                // and Cycles stop short by a similar relative margin.
                (r2 > 0.0).then(|| {
                    let dist = r2.sqrt();
                    let wi = d / dist;
                    let near = offset_ray_origin(*position, -wi, position.abs().max_element());
                    let target = if (*position - near).length() < dist / 8192.0 { *position - wi * (dist / 8192.0) } else { near };
                    LightSample { wi, value: *intensity / r2, pdf: 1.0, target: Target::Point(target), covers: false, prim: 0 }
                })
            }
            Light::Directional { to_light, irradiance } => Some(LightSample { wi: *to_light, value: *irradiance, pdf: 1.0, target: Target::Infinite, covers: false, prim: 0 }),
            Light::Hemisphere { radiance, .. } => {
                // Uniform over the upper hemisphere: local z maps to world +y.
                let l = uniform_hemisphere(u.0, u.1);
                let wi = Vec3::new(l.x, l.z, -l.y);
                Some(LightSample { wi, value: *radiance, pdf: UNIFORM_HEMISPHERE_PDF, target: Target::Infinite, covers: false, prim: 0 })
            }
            Light::Rect { corner, ex, ey, normal, radiance, solid_angle } => {
                if let Some(sr) = solid_angle.and_then(|r| r.from(p)) {
                    return solid_angle_sample(p, sr.sample(u), *normal, magnitude(&[*corner, *corner + *ex + *ey]), *radiance, 1.0 / sr.omega);
                }
                let area = ex.cross(*ey).length();
                let q = *corner + *ex * u.0 + *ey * u.1;
                area_sample(p, q, *normal, magnitude(&[*corner, *corner + *ex + *ey, *corner + *ex, *corner + *ey]), *radiance, 1.0 / area)
            }
            Light::Mesh { geom_id, cdf, area, radiance, rect, spherical } => {
                if let Some((r, sr)) = rect.and_then(|r| r.from(p).map(|sr| (r, sr))) {
                    return solid_angle_sample(p, sr.sample(u), r.normal, magnitude(&[r.corner, r.corner + r.ex + r.ey]), *radiance, 1.0 / sr.omega);
                }
                let Shape::Mesh(m) = &scene.shapes[*geom_id as usize] else { return None };
                let i = cdf.partition_point(|&c| c <= u_sel * area).min(cdf.len() - 1);
                let [a, b, c] = m.triangles[i].map(|k| m.positions[k as usize]);
                let n = crate::geometry::face_normal(a, b, c);
                let s = match SphericalTriangle::new(p, a, b, c).filter(|_| *spherical && rect.is_none()) {
                    // One triangle's share of the mesh, uniform in its solid angle.
                    Some(st) => solid_angle_sample(p, st.sample(u), n, magnitude(&[a, b, c]), *radiance, (triangle_share(cdf, i, *area) / st.omega) as f32)
                        .map(|s| LightSample { covers: false, ..s }),
                    None => {
                        let (bu, bv) = uniform_triangle(u.0, u.1);
                        let q = crate::geometry::triangle::point_at(a, b, c, bu, bv);
                        area_sample(p, q, n, magnitude(&[a, b, c]), *radiance, 1.0 / area)
                    }
                };
                s.map(|s| LightSample { prim: i as u32, ..s })
            }
            Light::Sphere { center, radius, radiance, cone } => {
                let mag = center.abs().max_element() + radius;
                if let Some(cone) = sphere_cone::SphereCone::new(p, *center, *radius).filter(|_| *cone) {
                    let (_, q) = cone.sample(u);
                    let n = (q - *center).normalize_or_zero();
                    return solid_angle_sample(p, q, n, mag, *radiance, cone.pdf());
                }
                let n = uniform_sphere(u.0, u.1);
                let q = *center + n * *radius;
                area_sample(p, q, n, mag, *radiance, 1.0 / (4.0 * PI * radius * radius))
            }
            Light::Environment(e) => {
                let (wi, value, pdf) = match env_at {
                    EnvAt::Lobe(l) => e.lobe.as_ref()?.sample(e.product.as_ref()?, e, &l, u)?,
                    EnvAt::Cosine(n) => e.product.as_ref()?.sample(e, n, u)?,
                    EnvAt::Map => e.sample(u)?,
                };
                Some(LightSample { wi, value, pdf, target: Target::Infinite, covers: false, prim: 0 })
            }
        }
    }
}

/// The probability that a mesh light picks triangle `i` (∝ its area; `cdf`
/// holds the running sums of the areas).
fn triangle_share(cdf: &[f32], i: usize, area: f32) -> f64 {
    let lo = if i == 0 { 0.0 } else { cdf[i - 1] };
    (cdf[i] - lo) as f64 / area as f64
}

/// A sample at `q` drawn uniformly in solid angle (pdf `pdf`), of a
/// one-sided emitter with normal `n` that `p` is in front of.
fn solid_angle_sample(p: Vec3, q: Vec3, n: Vec3, mag: f32, radiance: Vec3, pdf: f32) -> Option<LightSample> {
    let wi = (q - p).normalize_or_zero();
    if !(-n.dot(wi) > 0.0) || !(pdf > 0.0 && pdf.is_finite()) {
        return None;
    }
    Some(LightSample { wi, value: radiance, pdf, target: Target::Point(offset_ray_origin(q, n, mag)), covers: true, prim: 0 })
}

/// Convert an area-measure sample at `q` (normal `n`, one-sided) into a
/// solid-angle sample seen from `p`: pdf_w = pdf_A * dist^2 / |cos_l|.
fn area_sample(p: Vec3, q: Vec3, n: Vec3, mag: f32, radiance: Vec3, pdf_area: f32) -> Option<LightSample> {
    let d = q - p;
    let dist2 = d.length_squared();
    if !(dist2 > 0.0) {
        return None;
    }
    let wi = d / dist2.sqrt();
    let cos_l = -n.dot(wi);
    if !(cos_l > 0.0) {
        return None; // the back of a one-sided emitter
    }
    // The shadow ray stops just short of the emitter: its end is pushed off
    // the surface, towards the receiver, by the same ulp offset as origins.
    Some(LightSample { wi, value: radiance, pdf: pdf_area * dist2 / cos_l, target: Target::Point(offset_ray_origin(q, n, mag)), covers: false, prim: 0 })
}

/// Radiance leaving the surface at `it` towards `wo` (unit, pointing away).
pub fn emitted(scene: &Scene, it: &Interaction, wo: Vec3) -> Vec3 {
    if it.ng.dot(wo) > 0.0 {
        scene.material_of(it.geom_id).emission
    } else {
        Vec3::ZERO
    }
}

/// The set of lights of a scene, after merging area lights into their proxies.
#[derive(Clone, Debug, Default)]
pub struct Lights {
    pub lights: Vec<Light>,
    /// For each shape (geometry id), the index of the light it is, if emissive.
    pub of_geometry: Vec<Option<usize>>,
    /// One line per merge or notable decision, printed by the CLI.
    pub notes: Vec<String>,
    /// Sample the environment map × the receiver's cosine bound at
    /// vertices that do not transmit (`env_product`); else the map alone.
    pub env_product: bool,
    /// At glossy vertices, sample the environment inside the lobe's cone
    /// (`env_lobe`) instead (with `env_product` on).
    pub env_lobes: bool,
    /// Each light sample picks one of the lights (`pick`: several lights,
    /// all with an estimate); `None`: every light is sampled.
    pub pick: Option<pick::Picker>,
}

impl Lights {
    pub fn from_scene(scene: &Scene) -> Result<Lights> {
        Self::with_environment(scene, None)
    }

    /// The scene's lights plus an environment map (`-e`).
    pub fn with_environment(scene: &Scene, env: Option<Arc<EnvMap>>) -> Result<Lights> {
        let mut out = Lights { of_geometry: vec![None; scene.shapes.len()], env_product: true, env_lobes: true, ..Lights::default() };
        // Emissive shapes first.
        for (g, shape) in scene.shapes.iter().enumerate() {
            let radiance = scene.material_of(g as u32).emission;
            if radiance == Vec3::ZERO {
                continue;
            }
            match shape {
                Shape::Mesh(m) => {
                    let mut cdf = Vec::with_capacity(m.triangles.len());
                    let mut acc = 0.0f32;
                    for t in &m.triangles {
                        let [a, b, c] = t.map(|k| m.positions[k as usize]);
                        acc += crate::geometry::triangle::area(a, b, c);
                        cdf.push(acc);
                    }
                    if acc > 0.0 {
                        out.of_geometry[g] = Some(out.lights.len());
                        let tris: Vec<[Vec3; 3]> = m.triangles.iter().map(|t| t.map(|k| m.positions[k as usize])).collect();
                        let rect = RectEmitter::of_triangles(&tris);
                        out.lights.push(Light::Mesh { geom_id: g as u32, cdf, area: acc, radiance, rect, spherical: true });
                    }
                }
                Shape::Sphere { center, radius } => {
                    out.of_geometry[g] = Some(out.lights.len());
                    out.lights.push(Light::Sphere { center: *center, radius: *radius, radiance, cone: true });
                }
            }
        }
        for l in &scene.lights {
            if l.radiance == Vec3::ZERO {
                out.notes.push(format!("{} light '{}' has zero radiance: ignored", l.kind.as_str(), l.name));
                continue;
            }
            let xf = l.transform;
            let pos = (xf * glam::Vec4::new(0.0, 0.0, 0.0, 1.0)).xyz();
            match l.kind {
                LightKind::Point => out.lights.push(Light::Point { position: pos, intensity: l.radiance }),
                LightKind::Directional => {
                    // A Blender sun shines along its local -z; the light comes
                    // from +z. (CS184 transforms (0,0,-1) as a point instead,
                    // translation included; see docs/guide/cs184-users.md.)
                    let to_light = xf.transform_vector3(Vec3::Z).normalize_or_zero();
                    if to_light == Vec3::ZERO {
                        crate::bail!("{}: directional light '{}' has a degenerate transform", scene.source, l.name);
                    }
                    out.lights.push(Light::Directional { to_light, irradiance: l.radiance });
                }
                LightKind::Ambient => out.lights.push(Light::Hemisphere { radiance: l.radiance, lune: true }),
                LightKind::Spot => crate::bail!("{}: spot light '{}' is not supported (CS184 leaves spot lights unimplemented)", scene.source, l.name),
                LightKind::Area => {
                    // CS184: centre T(0,0,0), emitting along T(0,0,-1) - centre,
                    // spanned by T(-1,0,0) - centre and T(0,1,0) - centre.
                    let p = |v: Vec3| (xf * v.extend(1.0)).xyz();
                    let dir = (p(-Vec3::Z) - pos).normalize_or_zero();
                    let dx = p(-Vec3::X) - pos;
                    let dy = p(Vec3::Y) - pos;
                    if dir == Vec3::ZERO || dx.cross(dy).length() == 0.0 {
                        crate::bail!("{}: area light '{}' is degenerate", scene.source, l.name);
                    }
                    if let Some(msg) = find_proxy(scene, &out.lights, pos, dir, dx, dy, l.radiance, &l.name) {
                        out.notes.push(msg);
                        continue;
                    }
                    // Say so when an emissive surface is there too (CBcoil: a quad of
                    // radiance 10 under an area light of 5): both then light the scene.
                    if out.lights.iter().any(|k| matches!(k, Light::Mesh { .. })) {
                        out.notes.push(format!(
                            "area light '{}' (radiance {}) matches no emissive surface (same plane, place, size and radiance): it lights the scene as an invisible rectangle, beside the emissive surfaces",
                            l.name, l.radiance
                        ));
                    }
                    let corner = pos - 0.5 * dx - 0.5 * dy;
                    out.lights.push(Light::Rect { corner, ex: dx, ey: dy, normal: dir, radiance: l.radiance, solid_angle: RectEmitter::new(corner, dx, dy, dir) });
                }
            }
        }
        if let Some(e) = env {
            if e.is_black() {
                out.notes.push(format!("environment map {} is black everywhere", e.path));
            } else {
                out.lights.push(Light::Environment(e));
            }
        }
        Ok(out.with_light_pick(scene, true))
    }

    /// The CS184 sampling of every light instead of ours, for A/B
    /// measurements (`--light-sampling area`, `--sky-sampling uniform`):
    /// rectangles and spheres by area (`area`), the hemisphere light
    /// uniformly with MIS at every vertex (`uniform_sky`).
    pub fn with_sampling(mut self, area: bool, uniform_sky: bool) -> Lights {
        for l in &mut self.lights {
            match l {
                Light::Mesh { rect, spherical, .. } if area => (*rect, *spherical) = (None, false),
                Light::Rect { solid_angle, .. } if area => *solid_angle = None,
                Light::Sphere { cone, .. } if area => *cone = false,
                Light::Hemisphere { lune, .. } if uniform_sky => *lune = false,
                _ => {}
            }
        }
        self
    }

    /// `with_sampling`'s switches for the environment map (`--env-sampling`):
    /// `product` = the map × cosine bound (`env_product`), else the map
    /// alone; `lobes` = inside the lobe at glossy vertices (`env_lobe`).
    pub fn with_env_sampling(mut self, product: bool, lobes: bool) -> Lights {
        self.env_product = product;
        self.env_lobes = lobes;
        self
    }

    /// Pick one light per light sample (`pick`) where the scene allows it
    /// (`--light-pick one`), or sample every light (`all`).
    pub fn with_light_pick(mut self, scene: &Scene, one: bool) -> Lights {
        self.pick = if one { pick::Picker::new(scene, &self.lights) } else { None };
        self
    }

    /// The environment map, if the scene has one.
    pub fn environment(&self) -> Option<&EnvMap> {
        self.lights.iter().find_map(|l| match l {
            Light::Environment(e) => Some(&**e),
            _ => None,
        })
    }

    /// Radiance of the lights a ray escaping along `dir` sees.
    pub fn escaped(&self, dir: Vec3) -> Vec3 {
        self.lights.iter().map(|l| l.escaped(dir)).sum()
    }
}

/// An emissive mesh light that stands for the CGL area light at `pos`: all its
/// vertices in the light's plane, its centroid inside the rectangle, emitting
/// to the same side with the same radiance.
#[allow(clippy::too_many_arguments)]
fn find_proxy(scene: &Scene, lights: &[Light], pos: Vec3, dir: Vec3, dx: Vec3, dy: Vec3, radiance: Vec3, name: &str) -> Option<String> {
    let size = dx.length().max(dy.length());
    for l in lights {
        let Light::Mesh { geom_id, area, radiance: r, .. } = l else { continue };
        if (*r - radiance).abs().max_element() > 1e-4 * radiance.abs().max_element().max(1e-6) {
            continue;
        }
        let Shape::Mesh(m) = &scene.shapes[*geom_id as usize] else { continue };
        let used: Vec<Vec3> = m.triangles.iter().flatten().map(|&k| m.positions[k as usize]).collect();
        let coplanar = used.iter().all(|q| (*q - pos).dot(dir).abs() <= 1e-3 * size);
        let centroid = used.iter().copied().sum::<Vec3>() / used.len() as f32;
        let c = centroid - pos;
        let inside = c.dot(dx).abs() <= 0.5 * dx.length_squared() * (1.0 + 1e-3) && c.dot(dy).abs() <= 0.5 * dy.length_squared() * (1.0 + 1e-3);
        // Same side: the proxy's triangles face along the light's direction.
        let facing = m.triangles.iter().all(|t| {
            let [a, b, c] = t.map(|k| m.positions[k as usize]);
            (b - a).cross(c - a).dot(dir) > 0.0
        });
        if coplanar && inside && facing {
            let obj = &scene.objects[*geom_id as usize].name;
            return Some(format!(
                "merged area light '{name}' ({:.3}x{:.3}, radiance {radiance}) into its visible emissive mesh '{obj}' (coplanar, overlapping, same radiance; area {area:.3})",
                dx.length(),
                dy.length()
            ));
        }
    }
    None
}
