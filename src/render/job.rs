//! A render, prepared: the scene and what is made from it for the
//! integrator (its lights, the path tracer's guide), the camera, and the
//! integrator's spec. The flow of a render is arguments → `Job` → backend →
//! integrator (built by `IntegratorSpec::build`) → exact sums → images.

use super::integrator::IntegratorSpec;
use super::path::specular_guide::SpecularGuide;
use super::{render, RenderOutput, RenderSettings};
use crate::accel::Traversal;
use crate::camera::Camera;
use crate::error::Result;
use crate::light::{EnvMap, Lights};
use crate::scene::Scene;
use std::sync::Arc;

/// How the lights are sampled (our defaults; the others for A/B
/// comparisons with CS184's and the references' ways).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LightSampling {
    /// Rectangles and spheres by area (CS184's way) instead of by solid angle.
    pub by_area: bool,
    /// The hemisphere light uniformly with MIS instead of by the lune.
    pub uniform_sky: bool,
    /// The environment map by the map × a cosine bound at reflecting
    /// vertices (else by the map alone).
    pub env_cosine: bool,
    /// And inside the lobe's cone at glossy vertices.
    pub env_lobes: bool,
    /// Each light sample picks one light by its estimated contribution
    /// (else every light is sampled at every vertex).
    pub pick_one: bool,
}

impl Default for LightSampling {
    fn default() -> Self {
        LightSampling { by_area: false, uniform_sky: false, env_cosine: true, env_lobes: true, pick_one: true }
    }
}

pub struct Job {
    pub scene: Scene,
    pub camera: Camera,
    pub lights: Lights,
    /// The path tracer's guide toward mirror, glass and metal objects.
    pub guide: Option<SpecularGuide>,
    pub spec: IntegratorSpec,
    /// What preparing the render found worth saying, a line each (an area
    /// light merged into its visible proxy, a scene without light, the
    /// guide's choice of objects).
    pub notes: Vec<String>,
}

impl Job {
    /// Prepare `spec` for `scene`: an integrator that transports light gets
    /// the scene's lights (and `env`), sampled as `sampling` says, after
    /// its materials are checked; the path tracer its guide.
    pub fn new(scene: Scene, camera: Camera, env: Option<Arc<EnvMap>>, sampling: LightSampling, spec: IntegratorSpec) -> Result<Job> {
        let mut notes = Vec::new();
        let lights = if spec.transports_light() {
            scene.check_materials()?;
            let l = Lights::with_environment(&scene, env)?
                .with_sampling(sampling.by_area, sampling.uniform_sky)
                .with_env_sampling(sampling.env_cosine, sampling.env_lobes)
                .with_light_pick(&scene, sampling.pick_one);
            if l.lights.is_empty() {
                // One line: the notes (a zero-radiance light dropped) go into it.
                let why = if l.notes.is_empty() { String::new() } else { format!(" ({})", l.notes.join("; ")) };
                notes.push(format!("warning: the scene has no light{why}; the image will be black (an environment map, -e FILE.exr, would light it)"));
            } else {
                notes.extend(l.notes.iter().cloned());
            }
            l
        } else {
            Lights::default()
        };
        let guide = match spec {
            IntegratorSpec::Path(o) => {
                let (guide, note) = SpecularGuide::of_scene(&scene, o.specular_guide);
                notes.extend(note);
                guide
            }
            _ => None,
        };
        Ok(Job { scene, camera, lights, guide, spec, notes })
    }

    /// Render with `accel` (built over `self.scene`'s shapes).
    pub fn render(&self, accel: &dyn Traversal, settings: &RenderSettings) -> Result<RenderOutput> {
        let integrator = self.spec.build(&self.scene, &self.lights, self.guide.as_ref(), &self.camera, settings.width, settings.height, settings.region())?;
        Ok(render(&self.camera, accel, integrator.as_ref(), settings))
    }
}
