//! The built-in default scene: CS184's Cornell box with two diffuse spheres,
//! compiled into the binary so `pathtracer` with no arguments renders it.

use super::{collada, Scene};
use crate::error::Result;

pub const NAME: &str = "CBspheres_lambertian";
pub const TEXT: &str = include_str!("../../scenes/cs184/sky/CBspheres_lambertian.dae");

pub fn load() -> Result<Scene> {
    collada::parse(TEXT, NAME, "<built-in CBspheres_lambertian>")
}
