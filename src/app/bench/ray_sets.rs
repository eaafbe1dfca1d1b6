//! The rays a bench scene is timed on: camera, shadow, random and diffuse
//! sets, built once per scene and shared by every table that times it.

use super::timing::RaySet;
use crate::accel::workloads::{diffuse_rays, random_rays, shadow_rays, tile_order};
use crate::accel::Traversal;
use crate::ray::Ray;
use crate::render;
use crate::scene::Scene;

/// One scene's ray sets, each repeated up to `--rays`.
pub(super) struct RaySets {
    camera: Vec<Ray>,
    shadow: Vec<Ray>,
    random: Vec<Ray>,
    diffuse: Vec<Ray>,
}

impl RaySets {
    /// Camera rays in scanlines of a `w x h` frame; shadow rays from their
    /// hits (`first` finds them); random rays; diffuse rays from the hits
    /// taken in the renderer's tiles. Repeated up to `n`: only the camera
    /// rays that hit make shadow rays (7 % of them on arch), and a pass of
    /// 60k rays (under a millisecond) timed mostly the thread pool's start
    /// at 2 threads (arch:500k shadow rays 91 Mrays/s at 1 and 2 threads
    /// alike, Embree 70 and 69).
    pub(super) fn new(scene: &Scene, first: &dyn Traversal, camera_all: &[Ray], w: u32, h: u32, n: usize) -> RaySets {
        let repeat = |v: Vec<Ray>| if v.is_empty() { v } else { v.iter().cycle().take(n).copied().collect() };
        let camera: Vec<Ray> = repeat(camera_all.to_vec());
        let shadow = repeat(shadow_rays(scene, first, &camera));
        let diffuse = repeat(diffuse_rays(scene, first, &tile_order(camera_all, w, h, render::TILE), 7));
        RaySets { camera, shadow, random: random_rays(scene, n, 1), diffuse }
    }

    pub(super) fn get(&self, set: RaySet) -> &[Ray] {
        match set {
            RaySet::Camera => &self.camera,
            RaySet::Shadow => &self.shadow,
            RaySet::Random => &self.random,
            RaySet::Diffuse => &self.diffuse,
        }
    }
}
