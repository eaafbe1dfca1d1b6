//! pathtracer: a physically based path tracer for the CS184 scenes, with
//! interchangeable ray-traversal backends (native BVH, Embree, brute force).

pub mod accel;
pub mod bench;
pub mod bsdf;
pub mod camera;
pub mod cli;
pub mod error;
pub mod export;
pub mod fuzz;
pub mod geometry;
pub mod image_io;
pub mod light;
pub mod merge;
pub mod metrics;
pub mod partial;
pub mod ray;
pub mod render;
pub mod rng;
pub mod sampler;
pub mod sampling;
pub mod scene;

pub use error::{Error, Result};
