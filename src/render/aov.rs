//! First-hit images that check *intersection* against other renderers,
//! independent of light transport: the distance to the first hit and a flat
//! colour per object. The validation harness renders the same images with
//! POV-Ray and Cycles (flat emissive colours, a distance shader) from our
//! exported scene; only silhouette pixels may differ.

use super::Integrator;
use crate::accel::{Hit, Traversal};
use crate::ray::Ray;
use crate::sampler::Sampler;
use glam::Vec3;

/// Distance from the camera to the first hit along the ray (not the planar
/// z depth), in every channel; 0 where the ray escapes.
pub struct Depth;

impl Integrator for Depth {
    fn radiance_from(&self, _accel: &dyn Traversal, ray: &Ray, hit: Option<Hit>, _sampler: &mut Sampler, _rays: &mut u64) -> Vec3 {
        match hit {
            Some(hit) => Vec3::splat(hit.t * ray.dir.length()),
            None => Vec3::ZERO,
        }
    }
}

/// The flat colour `id_colour(geometry id)` of the first object hit; black
/// where the ray escapes.
pub struct ObjectId;

impl Integrator for ObjectId {
    fn radiance_from(&self, _accel: &dyn Traversal, _ray: &Ray, hit: Option<Hit>, _sampler: &mut Sampler, _rays: &mut u64) -> Vec3 {
        match hit {
            Some(hit) => id_colour(hit.geom_id),
            None => Vec3::ZERO,
        }
    }
}

/// A colour per geometry id, exported with the scene so that reference
/// renderers paint each object the same. Channels lie on a grid of 1/8 steps
/// in [1/8, 1] (a mix of two colours at a silhouette is then rarely another
/// object's colour, and half-float outputs represent them exactly); ids
/// cycle after 512 objects, more than any shipped scene has.
pub fn id_colour(geom_id: u32) -> Vec3 {
    // A bijection of 0..512 that puts consecutive ids far apart.
    let k = (geom_id.wrapping_mul(173).wrapping_add(97)) % 512;
    let c = |d: u32| ((k >> (3 * d)) & 7) as f32 / 8.0 + 0.125;
    Vec3::new(c(0), c(1), c(2))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn id_colours_are_distinct_for_512_ids() {
        let mut seen = std::collections::HashSet::new();
        for id in 0..512 {
            let c = id_colour(id);
            assert!(c.min_element() >= 0.125 && c.max_element() <= 1.0);
            assert!(seen.insert([c.x.to_bits(), c.y.to_bits(), c.z.to_bits()]), "id {id} repeats a colour");
        }
    }
}
