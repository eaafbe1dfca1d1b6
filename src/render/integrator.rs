//! Which integrator renders, with its options, as one value
//! (`IntegratorSpec`), and the one factory that builds it for a scene. A
//! new integrator option is a field of its options here and a line of the
//! factory; the command line only maps its flags to this value, and a split
//! render's partial records it (`header_fields`), so `merge` asks the same
//! value what the parts made (`splats`).

use super::bdpt::{Bdpt, LightPaths, Technique};
use super::path::{specular_guide::SpecularGuide, PathTracer};
use super::{aov, normals::NormalShading, Integrator, Region};
use crate::camera::Camera;
use crate::error::Result;
use crate::light::Lights;
use crate::scene::Scene;

/// What every light-transport integrator shares: the maximum ray depth
/// (CS184's `-m`), and whether bounces 0..m accumulate or only bounce m
/// counts (`-o 1` / `-o 0`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounces {
    pub max_depth: u32,
    pub accumulate: bool,
}

/// The path tracer's options.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathOptions {
    pub bounces: Bounces,
    /// Samples per light at every vertex (`-l`).
    pub light_samples: u32,
    /// Direct light by uniform hemisphere sampling (`-H`).
    pub hemisphere: bool,
    pub russian_roulette: bool,
    /// Share of diffuse bounce rays aimed at mirror, glass and metal
    /// objects (`render::path::specular_guide`; 0 for none).
    pub specular_guide: f32,
}

/// Bidirectional path tracing's options.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BdptOptions {
    pub bounces: Bounces,
    /// Every strategy weighted, or one strategy's image.
    pub technique: Technique,
    /// Which light subpaths go on past their first bounce.
    pub light_paths: LightPaths,
    /// Whether lights no ray finds (point, directional, CGL area lights
    /// without geometry) light the scene through mirrors and glass: their
    /// caustics, which the path tracer cannot sample (see
    /// `bdpt::Bdpt::with_unseen_light_caustics`).
    pub unseen_light_caustics: bool,
}

/// An integrator and its options, checked once.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum IntegratorSpec {
    /// Light transport from the camera (direct light at `-m 1`, global
    /// illumination above).
    Path(PathOptions),
    /// Camera and light subpaths joined by every strategy.
    Bdpt(BdptOptions),
    /// Paths from the lights, each vertex joined to the lens.
    LightTracing(Bounces),
    /// CS184's normal shading.
    Normals,
    /// Distance to the first hit.
    Depth,
    /// A flat colour per object.
    ObjectId,
}

/// The name of each integrator, as `--integrator` and a partial's header
/// spell it.
const NAMES: [&str; 6] = ["path", "bdpt", "light", "normals", "depth", "object-id"];

impl IntegratorSpec {
    pub fn name(&self) -> &'static str {
        NAMES[match self {
            IntegratorSpec::Path(_) => 0,
            IntegratorSpec::Bdpt(_) => 1,
            IntegratorSpec::LightTracing(_) => 2,
            IntegratorSpec::Normals => 3,
            IntegratorSpec::Depth => 4,
            IntegratorSpec::ObjectId => 5,
        }]
    }

    /// Whether the integrator lands light on other pixels than the one
    /// sampled (a film of splats), as light tracing and BDPT do.
    pub fn splats(&self) -> bool {
        matches!(self, IntegratorSpec::Bdpt(_) | IntegratorSpec::LightTracing(_))
    }

    /// `splats` for an integrator known only by its name (a partial's
    /// header); `None` for a name no integrator has.
    pub fn splats_by_name(name: &str) -> Option<bool> {
        NAMES.iter().position(|n| *n == name).map(|i| i == 1 || i == 2)
    }

    /// Whether it transports light: it then needs the scene's lights and
    /// supported materials, and reads the light-sampling options.
    pub fn transports_light(&self) -> bool {
        matches!(self, IntegratorSpec::Path(_) | IntegratorSpec::Bdpt(_) | IntegratorSpec::LightTracing(_))
    }

    /// The bounces of a light-transport integrator.
    pub fn bounces(&self) -> Option<Bounces> {
        match self {
            IntegratorSpec::Path(o) => Some(o.bounces),
            IntegratorSpec::Bdpt(o) => Some(o.bounces),
            IntegratorSpec::LightTracing(b) => Some(*b),
            _ => None,
        }
    }

    /// The options that change the image, as a split render's partial
    /// records them: parts that differ in any of them are not merged. The
    /// path tracer's fields are written for every integrator (at their
    /// defaults where it has none), so that a partial's header is the same
    /// whichever way it was asked for; BDPT adds its own.
    pub fn header_fields(&self) -> Vec<(&'static str, String)> {
        let flag = |b: bool| if b { "1" } else { "0" }.to_string();
        let bounces = self.bounces().unwrap_or(Bounces { max_depth: 1, accumulate: true });
        let path = match self {
            IntegratorSpec::Path(o) => *o,
            _ => PathOptions { bounces, light_samples: 1, hemisphere: false, russian_roulette: true, specular_guide: 0.0 },
        };
        let mut out = vec![
            ("integrator", self.name().to_string()),
            ("max_depth", bounces.max_depth.to_string()),
            ("light_samples", path.light_samples.to_string()),
            ("accumulate", flag(bounces.accumulate)),
            ("hemisphere", flag(path.hemisphere)),
            ("russian_roulette", flag(path.russian_roulette)),
        ];
        if let IntegratorSpec::Bdpt(o) = self {
            let technique = match o.technique {
                Technique::Bidirectional => "all".to_string(),
                Technique::LightTracing => "light".to_string(),
                Technique::Strategy { s, t, weighted } => format!("{s},{t}{}", if weighted { ",weighted" } else { "" }),
            };
            out.push(("bdpt_strategy", technique));
            out.push(("bdpt_light_paths", if o.light_paths == LightPaths::Specular { "specular" } else { "all" }.to_string()));
        }
        out
    }

    /// The integrator for `scene` as `camera` sees it (the full frame is
    /// `width` x `height`, the render covers `region`): the one factory.
    #[allow(clippy::too_many_arguments)]
    pub fn build<'a>(&self, scene: &'a Scene, lights: &'a Lights, guide: Option<&'a SpecularGuide>, camera: &'a Camera, width: u32, height: u32, region: Region) -> Result<Box<dyn Integrator + 'a>> {
        Ok(match *self {
            IntegratorSpec::Normals => Box::new(NormalShading { scene }),
            IntegratorSpec::Depth => Box::new(aov::Depth),
            IntegratorSpec::ObjectId => Box::new(aov::ObjectId),
            IntegratorSpec::Path(o) => Box::new(PathTracer {
                scene,
                lights,
                guide,
                max_depth: o.bounces.max_depth,
                accumulate: o.bounces.accumulate,
                hemisphere: o.hemisphere,
                light_samples: o.light_samples,
                russian_roulette: o.russian_roulette,
            }),
            IntegratorSpec::Bdpt(o) => Box::new(Bdpt::new(scene, lights, camera, width, height, region, o.bounces.max_depth, o.bounces.accumulate, o.technique)?.with_light_paths(o.light_paths).with_unseen_light_caustics(o.unseen_light_caustics)),
            IntegratorSpec::LightTracing(b) => Box::new(Bdpt::new(scene, lights, camera, width, height, region, b.max_depth, b.accumulate, Technique::LightTracing)?),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splats_agree_by_value_and_by_name() {
        let b = Bounces { max_depth: 5, accumulate: true };
        let specs = [
            IntegratorSpec::Path(PathOptions { bounces: b, light_samples: 1, hemisphere: false, russian_roulette: true, specular_guide: 0.1 }),
            IntegratorSpec::Bdpt(BdptOptions { bounces: b, technique: Technique::Bidirectional, light_paths: LightPaths::Specular, unseen_light_caustics: true }),
            IntegratorSpec::LightTracing(b),
            IntegratorSpec::Normals,
            IntegratorSpec::Depth,
            IntegratorSpec::ObjectId,
        ];
        for s in specs {
            assert_eq!(IntegratorSpec::splats_by_name(s.name()), Some(s.splats()), "{}", s.name());
            assert_eq!(s.header_fields()[0], ("integrator", s.name().to_string()));
        }
        assert_eq!(IntegratorSpec::splats_by_name("pathtracer"), None);
        let bdpt = specs[1].header_fields();
        assert!(bdpt.contains(&("bdpt_light_paths", "specular".to_string())) && bdpt.contains(&("bdpt_strategy", "all".to_string())));
    }
}
