//! pathtracer: a physically based path tracer for the CS184 scenes, with
//! interchangeable ray-traversal backends (native BVH, Embree, brute force).
//!
//! # Architecture
//!
//! A render goes from a scene file to an image in five steps, each a module:
//!
//! 1. [`scene`] loads the file (CS184 COLLADA, OBJ, PLY) into a [`scene::Scene`]:
//!    shapes for the backends, objects with their materials, lights, the camera
//!    description. [`scene::Interaction`] later *describes a hit* from what a
//!    backend returns, with code every backend shares.
//! 2. [`accel::build`] builds the chosen backend ([`accel::BackendKind`]) over the
//!    shapes; every backend answers the same queries with the same semantics
//!    through the [`accel::Traversal`] trait (closest and any hit, single rays
//!    and batches).
//! 3. [`camera::Camera`] places CS184's camera; [`light::Lights`] turns the
//!    scene's emitters (and an environment map, [`light::EnvMap`]) into one
//!    light model with its samplers.
//! 4. [`render::render`] runs an integrator ([`render::Integrator`]: the path
//!    tracer [`render::path::PathTracer`], normal shading, depth, object ids)
//!    over tiles on rayon's pool; every random number is addressed by (pixel,
//!    sample, dimension) ([`sampler`]), and every pixel keeps exact fixed-point
//!    sums ([`render::sums`]), so the image is the same at any thread count and
//!    in any split of the work ([`partial`]).
//! 5. [`image_io`] writes the PNG (CS184's tone step), the rate image and OpenEXR.
//!
//! Those modules are the library: they know nothing of the command line, the
//! benchmark or the environment, and take every option as a value. [`app`]
//! is the application built on them: [`app::cli::parse`] and
//! [`app::run`] are the command line the binary runs, with every flag
//! checked; the benchmark, split renders' merge, the export for the
//! reference renderers and the fuzzer live beside it. The documentation in
//! `docs/` describes each piece (`docs/design/modules.md` is the module map).
//!
//! # Example: render the built-in scene into an image buffer
//!
//! ```
//! use pathtracer::accel::{self, BackendKind};
//! use pathtracer::camera::Camera;
//! use pathtracer::light::Lights;
//! use pathtracer::render::{self, path::{specular_guide::{self, SpecularGuide}, PathTracer}, RenderSettings};
//!
//! let scene = pathtracer::scene::builtin::load()?; // or scene::load_file(path)
//! let built = accel::build(BackendKind::Native, &scene.shapes, 0)?;
//! let lights = Lights::with_environment(&scene, None)?;
//! let (guide, _) = SpecularGuide::of_scene(&scene, specular_guide::DEFAULT_FRACTION);
//! let mut camera = Camera::from_scene(&scene);
//! camera.resize_keep_fov(64, 48); // the 800x600 view, scaled
//! let integrator = PathTracer {
//!     scene: &scene,
//!     lights: &lights,
//!     guide: guide.as_ref(), // --specular-guide
//!     max_depth: 5, // -m 5
//!     accumulate: true,
//!     hemisphere: false,
//!     light_samples: 1,
//!     russian_roulette: true,
//! };
//! let settings = RenderSettings::new(64, 48, 16, 0); // 16 samples per pixel, seed 0
//! let out = render::render(&camera, built.accel.as_ref(), &integrator, &settings);
//! assert_eq!((out.image.width, out.image.height), (64, 48));
//! let centre = out.image.get(32, 24);
//! assert!(centre.x > 0.0 && centre.is_finite(), "the Cornell box is lit: {centre}");
//! // Written as the command line writes it:
//! // pathtracer::image_io::write_png(std::path::Path::new("out.png"), &out.image)?;
//! # Ok::<(), pathtracer::Error>(())
//! ```

pub mod accel;
pub mod app;
pub mod bsdf;
pub mod camera;
pub mod color;
pub mod error;
pub mod geometry;
pub mod image_io;
pub mod light;
pub mod metrics;
pub mod partial;
pub mod ray;
pub mod render;
pub mod rng;
pub mod sampler;
pub mod sampling;
pub mod scene;

pub use error::{Error, Result};
