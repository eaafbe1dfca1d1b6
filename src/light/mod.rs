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
//!   × a bound of the receiver's cosine (`environment::product`), inside the lobe at
//!   glossy vertices (`environment::lobe`), by the map alone where light passes
//!   through (`EnvAt`).
//! * Lights of zero radiance (the `_unlit` scenes' sky) are dropped.
//! * Sampling (CS184 samples every emitter by area): rectangles — area
//!   lights and two-triangle rectangular meshes — by solid angle
//!   (`spherical_rect`), spheres seen from outside by their cone
//!   (`sphere_cone`), the hemisphere light at diffuse vertices by the lune
//!   (`lune`); other meshes pick a triangle by area, then sample it by its
//!   solid angle where that pays (`spherical_triangle`), else by area.
//!   `pdf_hit` applies the same choice.
//!
//! Layout: each emitter kind is a file — `point`, `directional`,
//! `hemisphere`, `rect` (area rectangle), `mesh` (emissive triangles),
//! `sphere`, `environment/` (the map) — owning its sampling, densities and
//! power by implementing `Emitter` (`emitter`); `Light` hands every
//! question to its kind. The spherical-geometry routines they share sit
//! below them (`spherical_rect`, `spherical_triangle`, `sphere_cone`,
//! `lune`); `emission` starts rays from the lights, `pick` chooses one
//! light per sample; `Lights` builds the set from a scene.

pub mod directional;
pub mod emission;
pub mod emitter;
pub mod environment;
pub mod hemisphere;
pub mod lune;
pub mod mesh;
pub mod pick;
pub mod point;
pub mod rect;
pub mod sphere;
pub mod sphere_cone;
pub mod spherical_rect;
pub mod spherical_triangle;

use spherical_rect::RectEmitter;

pub use directional::DirectionalLight;
pub use emitter::Emitter;
pub use environment::EnvMap;
pub use hemisphere::HemisphereLight;
pub use mesh::MeshLight;
pub use point::PointLight;
pub use rect::RectLight;
pub use sphere::SphereLight;

use crate::error::Result;
use crate::scene::{Interaction, LightKind, Scene, Shape};
use glam::{Vec3, Vec4Swizzles};
use std::sync::Arc;

/// How the environment light is sampled at a vertex (the BSDF sample's
/// MIS weight uses the same): by the map alone, by the map × a bound of
/// the cosine of a receiver with this shading normal (`env_product`), or
/// inside a glossy lobe's cone (`env_lobe`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EnvAt {
    Map,
    Cosine(Vec3),
    Lobe(environment::lobe::Lobe),
}

/// An emitter, one variant per kind; each kind is a file implementing
/// `Emitter`, and `Light` hands every question to it (`each_kind!`). A new
/// kind is its file, a variant here and a line of `each_kind!`, and its
/// construction in `Lights::with_environment`.
#[derive(Clone, Debug)]
pub enum Light {
    Point(PointLight),
    Directional(DirectionalLight),
    /// CS184's "ambient".
    Hemisphere(HemisphereLight),
    /// A CGL area light with no visible proxy.
    Rect(RectLight),
    /// An emissive triangle mesh.
    Mesh(MeshLight),
    /// An emissive sphere.
    Sphere(SphereLight),
    /// A latitude-longitude environment map (`-e`).
    Environment(Arc<EnvMap>),
}

/// `$body` with `$l` bound to the light's kind, whichever it is.
macro_rules! each_kind {
    ($light:expr, $l:ident => $body:expr) => {
        match $light {
            Light::Point($l) => $body,
            Light::Directional($l) => $body,
            Light::Hemisphere($l) => $body,
            Light::Rect($l) => $body,
            Light::Mesh($l) => $body,
            Light::Sphere($l) => $body,
            Light::Environment($l) => $body,
        }
    };
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
    /// The kind's answers (`Emitter`), as a trait object.
    pub fn kind(&self) -> &dyn Emitter {
        each_kind!(self, l => l as &dyn Emitter)
    }

    pub fn is_delta(&self) -> bool {
        each_kind!(self, l => l.is_delta())
    }

    /// Whether rays can hit this emitter (so hemisphere sampling finds it).
    pub fn is_visible(&self) -> bool {
        each_kind!(self, l => l.is_visible())
    }

    pub fn describe(&self) -> String {
        each_kind!(self, l => l.describe())
    }

    /// Solid-angle pdf with which `sample` from `p` picks the point `x` (normal
    /// `n`, on primitive `prim`) of this emitter's surface; 0 for lights that
    /// are not surfaces.
    pub fn pdf_hit(&self, scene: &Scene, p: Vec3, x: Vec3, n: Vec3, prim: u32) -> f32 {
        each_kind!(self, l => l.pdf_hit(scene, p, x, n, prim))
    }

    /// Whether `sample` from `p` draws directions uniformly over the whole
    /// solid angle this emitter subtends (a rectangle by solid angle, a
    /// sphere by its cone) — the same choice `sample` makes. For a diffuse
    /// receiver such samples are already the BSDF's shape but for the
    /// cosine, so light sampling alone estimates that light (see
    /// `PathTracer::alone`).
    pub fn covers(&self, p: Vec3) -> bool {
        each_kind!(self, l => l.covers(p))
    }

    /// Radiance this light sends along `-dir` to a ray escaping along `dir`
    /// (0 for lights that are not at infinity).
    pub fn escaped(&self, dir: Vec3) -> Vec3 {
        each_kind!(self, l => l.escaped(dir))
    }

    /// Solid-angle pdf of `sample` for an escaping direction (hemisphere
    /// light, environment map), with the same `env_at` as `sample`.
    pub fn pdf_escape(&self, dir: Vec3, env_at: EnvAt) -> f32 {
        each_kind!(self, l => l.pdf_escape(dir, env_at))
    }

    /// Whether `sample` uses its `u_sel` (to pick a triangle of a mesh).
    pub fn uses_selection(&self) -> bool {
        each_kind!(self, l => l.uses_selection())
    }

    /// Sample light arriving at `p`. `u` are two uniforms, `u_sel` a third
    /// (triangle selection). An environment map is sampled as `env_at`
    /// says (`EnvAt`: the map alone, × a receiver's cosine bound, or inside
    /// a glossy lobe). `None` when the sample carries no light (the back of
    /// a one-sided emitter, a degenerate configuration).
    pub fn sample(&self, scene: &Scene, p: Vec3, u: (f32, f32), u_sel: f32, env_at: EnvAt) -> Option<LightSample> {
        each_kind!(self, l => l.sample(scene, p, u, u_sel, env_at))
    }

    /// The CS184 way of sampling it, for A/B measurements (`Emitter::use_cs184_sampling`).
    fn use_cs184_sampling(&mut self, by_area: bool, uniform_sky: bool) {
        each_kind!(self, l => l.use_cs184_sampling(by_area, uniform_sky))
    }
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
                    if let Some(light) = MeshLight::new(g as u32, m, radiance) {
                        out.of_geometry[g] = Some(out.lights.len());
                        out.lights.push(Light::Mesh(light));
                    }
                }
                Shape::Sphere { center, radius } => {
                    out.of_geometry[g] = Some(out.lights.len());
                    out.lights.push(Light::Sphere(SphereLight { center: *center, radius: *radius, radiance, cone: true }));
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
                LightKind::Point => out.lights.push(Light::Point(PointLight { position: pos, intensity: l.radiance })),
                LightKind::Directional => {
                    // A Blender sun shines along its local -z; the light comes
                    // from +z. (CS184 transforms (0,0,-1) as a point instead,
                    // translation included; see docs/guide/cs184-users.md.)
                    let to_light = xf.transform_vector3(Vec3::Z).normalize_or_zero();
                    if to_light == Vec3::ZERO {
                        crate::bail!("{}: directional light '{}' has a degenerate transform", scene.source, l.name);
                    }
                    out.lights.push(Light::Directional(DirectionalLight { to_light, irradiance: l.radiance }));
                }
                LightKind::Ambient => out.lights.push(Light::Hemisphere(HemisphereLight { radiance: l.radiance, lune: true })),
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
                    if out.lights.iter().any(|k| matches!(k, Light::Mesh(_))) {
                        out.notes.push(format!(
                            "area light '{}' (radiance {}) matches no emissive surface (same plane, place, size and radiance): it lights the scene as an invisible rectangle, beside the emissive surfaces",
                            l.name, l.radiance
                        ));
                    }
                    let corner = pos - 0.5 * dx - 0.5 * dy;
                    out.lights.push(Light::Rect(RectLight { corner, ex: dx, ey: dy, normal: dir, radiance: l.radiance, solid_angle: RectEmitter::new(corner, dx, dy, dir) }));
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
            l.use_cs184_sampling(area, uniform_sky);
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
        let _ = scene;
        self.pick = if one { pick::Picker::new(&self.lights) } else { None };
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
        let Light::Mesh(MeshLight { geom_id, area, radiance: r, .. }) = l else { continue };
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
