//! The triangles that occluded the last packets of a shadow batch, tried
//! on the next packet before any traversal.
//!
//! Neighbouring shadow rays are mostly stopped by the same triangle: a roof
//! or a floor between the points and the light, a wall. Testing the last
//! one or two such triangles against a packet's 16 rays (8 per instruction,
//! `RaysSoA::hits_triangle`) costs a fraction of a traversal from the root.
//! A packet whose rays they all occlude is done; otherwise the rays they
//! occlude leave the packet and the rest are traced as before (`sweep`
//! traces the smaller swept box of the rest; the other traversals trace
//! every ray again). The cache is tried only while it pays: after
//! `WARM_UP` rays, while it occludes at least one tested ray in
//! `WIN_RATE`, else on one packet in `RETRY`.
//!
//! Answers are the traversal's either way: a ray that hits a scene triangle
//! within its range is occluded, and the test is the traversal's own
//! (watertight, bit for bit the single-ray one), so which triangles are
//! cached decides the time, never an answer — and the images stay the same
//! at any thread count.
//!
//! Measured (`probe`, 1 thread, shadow rays of the bench, Mrays/s, best of
//! 5 passes, two or three alternating runs): arch:500k 56-59 -> 86-94
//! (Embree 64-69), where 81 % of the tested rays were occluded by a cached
//! triangle; cow 34.9-35.5 -> 34.4-36.1; CBbunny 39.5-40.8 -> 37.5-38.1,
//! maxplanck 11.8-12.2 -> 11.3-11.6 (no cached triangle ever occluded a
//! maxplanck packet: the loss is the bookkeeping). Only packets whose rays
//! all went by swept boxes are traced with fewer rays; whole packets only
//! skipped at first, arch gained half as much (83-88) and cow lost 5 %.

use super::packet::{RaysSoA, NO_OCCLUDER, PACKET};
use super::{WideBvh, LANES};

#[derive(Default)]
pub(super) struct OccluderCache {
    /// `group · LANES + lane`, most recent first; `len` of them valid.
    tris: [u32; OCCLUDERS],
    len: usize,
    /// Rays tested against the cache, those it occluded, and the packets
    /// let through untested since the last test.
    tried: u32,
    found: u32,
    skipped: u32,
}

/// Triangles an `OccluderCache` holds.
const OCCLUDERS: usize = 2;
/// After `WARM_UP` tested rays, the cache is tested only while it has
/// occluded at least one tested ray in `WIN_RATE`, and else once every
/// `RETRY` packets.
const WARM_UP: u32 = 256;
const WIN_RATE: u32 = 8;
const RETRY: u32 = 32;

impl OccluderCache {
    /// Remember `code` (`group · LANES + lane`, or `NO_OCCLUDER`).
    #[inline(always)]
    pub(super) fn record(&mut self, code: u32) {
        if code == NO_OCCLUDER || self.tris[..self.len].first() == Some(&code) {
            return;
        }
        self.tris.copy_within(0..OCCLUDERS - 1, 1);
        self.tris[0] = code;
        self.len = (self.len + 1).min(OCCLUDERS);
    }

    /// Which of the first `n` rays of `soa` (bits) the cached triangles
    /// occlude; 0 when the cache is not tried (empty, an invalid ray, rays
    /// of several axis permutations, or not paying lately).
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[inline(always)]
    pub(super) unsafe fn occluded<const W: usize>(&mut self, bvh: &WideBvh<W>, soa: &RaysSoA, n: usize) -> u32 {
        let all = (1u32 << n) - 1;
        if self.len == 0 || soa.valid & all != all {
            return 0;
        }
        if self.tried >= WARM_UP && self.found * WIN_RATE < self.tried && self.skipped < RETRY {
            self.skipped += 1;
            return 0;
        }
        let Some(k) = soa.shared_axes() else { return 0 };
        self.skipped = 0;
        self.tried += n as u32;
        let mut left = all;
        for &code in &self.tris[..self.len] {
            let g = &bvh.tree.groups[code as usize / LANES];
            for half in 0..PACKET / 8 {
                if (left >> (8 * half)) & 0xff != 0 {
                    left &= !(soa.hits_triangle(g, code as usize % LANES, half, k, &soa.tmax) << (8 * half));
                }
            }
            if left == 0 {
                break;
            }
        }
        self.found += (all & !left).count_ones();
        #[cfg(test)]
        COUNTS[(left == 0) as usize].fetch_add((left != all) as u64, std::sync::atomic::Ordering::Relaxed);
        all & !left
    }
}

/// Packets the cache occluded in part (0) and entirely (1).
#[cfg(test)]
pub(super) static COUNTS: [std::sync::atomic::AtomicU64; 2] = [const { std::sync::atomic::AtomicU64::new(0) }; 2];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::brute::BruteForce;
    use crate::accel::wide::tests::avx_or_skip;
    use crate::accel::Traversal;
    use crate::scene::TriangleMesh;
    use crate::ray::Ray;
    use crate::scene::Shape;
    use glam::Vec3;
    use std::sync::atomic::Ordering::Relaxed;

    /// A floor of 40x40 small quads at y = 0 and a roof (two triangles)
    /// over its half x < 0 at y = 1: shadow rays from the floor to a point
    /// above the roof are occluded by one of two triangles under it, and
    /// not beside it.
    fn roofed_floor() -> Vec<Shape> {
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        let n = 40;
        for i in 0..n {
            for j in 0..n {
                let (x, z) = (-2.0 + 4.0 * i as f32 / n as f32, -2.0 + 4.0 * j as f32 / n as f32);
                let s = 4.0 / n as f32;
                let b = positions.len() as u32;
                positions.extend([Vec3::new(x, 0.0, z), Vec3::new(x + s, 0.0, z), Vec3::new(x + s, 0.0, z + s), Vec3::new(x, 0.0, z + s)]);
                triangles.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
            }
        }
        let floor = TriangleMesh { positions, triangles, normals: Vec::new() };
        let roof = TriangleMesh {
            positions: vec![Vec3::new(-3.0, 1.0, -3.0), Vec3::new(0.0, 1.0, -3.0), Vec3::new(0.0, 1.0, 3.0), Vec3::new(-3.0, 1.0, 3.0)],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            normals: Vec::new(),
        };
        vec![Shape::Mesh(floor), Shape::Mesh(roof)]
    }

    /// Packets of 16 shadow rays from rows of floor points (just above the
    /// floor) to `light`, scanning the floor row by row as a camera's
    /// first hits would; the rays stop `short` of the light.
    fn floor_rays(light: Vec3, short: f32) -> Vec<Ray> {
        let mut rays = Vec::new();
        for row in 0..64 {
            for col in 0..64 {
                let p = Vec3::new(-1.95 + 3.9 * col as f32 / 64.0, 1e-3, -1.95 + 3.9 * row as f32 / 64.0);
                rays.push(Ray::with_range(p, light - p, 1e-4, 1.0 - short));
            }
        }
        rays
    }

    /// Shadow rays under a roof, beside it, straddling its edge, and — in
    /// the same batch, after the cache has filled with the roof — rays that
    /// stop below the roof (the cached triangle hit beyond their range):
    /// every answer is brute force's, and packets were occluded by the
    /// cache both entirely and in part.
    #[test]
    fn cached_occluders_give_the_traversal_answers() {
        if !avx_or_skip("the occluder cache") {
            return;
        }
        let shapes = roofed_floor();
        let brute = BruteForce::new(&shapes);
        let bvh = WideBvh::<8>::build(&shapes);
        let light = Vec3::new(-0.5, 3.0, 0.2);
        let mut rays = floor_rays(light, 1e-4);
        // Every other row of packets ends at y = 0.6, under the roof.
        let low = floor_rays(light, 1.0 - 0.6 / 3.0);
        for (k, r) in rays.iter_mut().enumerate() {
            if (k / 64) % 4 == 1 {
                *r = low[k];
            }
        }
        let before: Vec<u64> = COUNTS.iter().map(|c| c.load(Relaxed)).collect();
        let mut out = vec![false; rays.len()];
        bvh.occluded_coherent(&rays, &mut out);
        let bad: Vec<usize> = (0..rays.len()).filter(|&i| brute.occluded(&rays[i]) != out[i]).collect();
        assert!(bad.is_empty(), "{} occlusion mismatches against brute force, first rays {:?}", bad.len(), &bad[..bad.len().min(8)]);
        let occluded = out.iter().filter(|o| **o).count();
        assert!(occluded > rays.len() / 4 && occluded < rays.len() * 3 / 4, "{occluded} of {} occluded: the test needs both", rays.len());
        let took: Vec<u64> = COUNTS.iter().zip(&before).map(|(c, b)| c.load(Relaxed) - b).collect();
        assert!(took[0] > 0 && took[1] > 0, "packets occluded by the cache in part / entirely: {took:?}");
    }

    /// The cache stops testing when it does not pay: a batch whose rays no
    /// cached triangle occludes tests `WARM_UP` rays, then one packet in
    /// `RETRY`.
    #[test]
    fn an_unpaying_cache_is_tried_rarely() {
        if !avx_or_skip("the occluder cache") {
            return;
        }
        let shapes = roofed_floor();
        let bvh = WideBvh::<8>::build(&shapes);
        // Rays from beside the roof, upwards: nothing occludes them.
        let rays: Vec<Ray> = (0..4096).map(|k| Ray::with_range(Vec3::new(0.5 + (k % 64) as f32 * 0.02, 0.01, -1.0 + (k / 64) as f32 * 0.03), Vec3::Y, 1e-4, 2.0)).collect();
        let mut cache = OccluderCache::default();
        cache.record(0);
        for p in rays.chunks(PACKET) {
            // SAFETY: AVX2 checked above.
            let soa = unsafe { RaysSoA::new(p) };
            // SAFETY: as above.
            assert_eq!(unsafe { cache.occluded(&bvh, &soa, p.len()) }, 0);
        }
        let packets = (rays.len() / PACKET) as u32;
        let want = WARM_UP + (packets - WARM_UP / PACKET as u32).div_ceil(RETRY + 1) * PACKET as u32;
        assert!(cache.tried <= want && cache.tried >= WARM_UP, "tested {} rays of {}; expected at most {want}", cache.tried, rays.len());
    }
}
