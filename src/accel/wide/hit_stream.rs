//! Incoherent closest-hit batches as *streams*: the batch's rays grouped by
//! the sign pattern of their directions (octant), in batch order, into
//! streams of up to 64, each stream traced together with a mask of the rays
//! that entered each stacked node — the closest-hit twin of the occlusion
//! streams (`stream`). A node some of a stream's rays entered is fetched
//! once for all of them and each of those rays tests its 8 boxes (one AVX2
//! test per ray, the single-ray test's operations) with its own current
//! closest distance; a leaf is tested by each ray that entered it. Where a
//! batch's rays start near one another (a tile's bounce rays), they share
//! most of their node fetches; where they do not (rays from anywhere in the
//! scene), the stream costs more than single rays: which batches stream is
//! `stream_choice`'s.
//!
//! Answers equal single-ray traversal's: each ray tests every triangle
//! whose leaf box it enters within its current closest distance, with the
//! watertight test and the same tie-break (`closer`), so its closest hit is
//! the same whatever order the leaves come in.

use super::stream::{octant_planes, octant_streams, ready, StreamRays, STREAM};
use super::triangle::Shear;
use super::stack::WalkStack;
use super::{ChildOrder, WideBvh, EMPTY, LEAF_BIT};
use crate::accel::prims::closer;
use crate::accel::Hit;
use crate::geometry::RayTransform;
use crate::ray::Ray;
use std::mem::MaybeUninit;

/// What a stream did: nodes fetched, and ray-node tests made at them.
#[derive(Default)]
pub(super) struct StreamWork {
    pub(super) nodes: u64,
    pub(super) tests: u64,
}

impl<const W: usize> WideBvh<W> {
    /// `hits[i]` = the closest hit of `rays[i]`, in streams of up to
    /// `STREAM` rays of one octant each.
    ///
    /// # Safety
    /// The CPU must have AVX2 and the caller must be compiled with it; `W`
    /// must be 8.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn closest_streams(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        debug_assert!(W == 8);
        if self.tree.root & LEAF_BIT != 0 || self.tree.root == EMPTY {
            return self.closest_all::<true>(rays, hits);
        }
        hits.fill(None);
        octant_streams(rays, |which, oct| self.closest_stream(rays, which, oct, hits, &mut StreamWork::default()));
    }

    /// One stream: `which` (at most `STREAM` indices into `rays`, all valid,
    /// all of octant `oct`); its node fetches and ray-node tests are added
    /// to `work`.
    #[inline(always)]
    pub(super) unsafe fn closest_stream(&self, rays: &[Ray], which: &[u32], oct: usize, hits: &mut [Option<Hit>], work: &mut StreamWork) {
        let n = which.len();
        let mut s = StreamRays::new(rays, which);
        let mut best: [Option<Hit>; STREAM] = [None; STREAM];
        let planes = octant_planes(oct);
        let mut setup: u64 = 0;
        let mut rts: [MaybeUninit<RayTransform>; STREAM] = [const { MaybeUninit::uninit() }; STREAM];
        let mut shears: [MaybeUninit<Shear>; STREAM] = [const { MaybeUninit::uninit() }; STREAM];
        let mut stack = WalkStack::<u64>::new();
        let mut sp = 0;
        let (mut code, mut entered) = (self.tree.root, StreamRays::all(n));
        loop {
            let node = &self.tree.nodes[code as usize];
            work.nodes += 1;
            work.tests += entered.count_ones() as u64;
            let e = self.stream_enter(node, &planes, &s, entered);
            if e.children != 0 {
                let mark = sp;
                let mut b = e.children;
                while b != 0 {
                    let lane = b.trailing_zeros() as usize;
                    b &= b - 1;
                    let child = node.child[lane];
                    let r = e.rays(lane);
                    if r == 0 || child == EMPTY {
                        continue;
                    }
                    if child & LEAF_BIT == 0 {
                        stack.push(&mut sp, child, e.near[lane], r);
                        continue;
                    }
                    let leaf = self.leaf_of(child);
                    let mut m = r;
                    while m != 0 {
                        let k = m.trailing_zeros() as usize;
                        m &= m - 1;
                        ready(k, &mut setup, &mut rts, &mut shears, rays, s.index[k]);
                        let ray = &rays[s.index[k] as usize];
                        let (b, t) = (&mut best[k], &mut s.tmax[k]);
                        self.leaf(&leaf, ray, rts[k].assume_init_ref(), shears[k].assume_init_ref(), *t, &mut |h: Hit| {
                            if closer(h, b) {
                                *t = h.t;
                                *b = Some(h);
                            }
                            false
                        });
                        s.far[k] = s.tmax[k] * crate::accel::bvh::ROBUST_SCALE;
                    }
                }
                stack.order_since(mark, sp, ChildOrder::NearestFirst);
            }
            // The next stacked node that a ray entered no farther than its
            // current closest hit.
            let far = &s.far;
            let next = stack.pop_where(&mut sp, |d, r| {
                let mut live = 0u64;
                let mut m = r;
                while m != 0 {
                    let k = m.trailing_zeros() as usize;
                    m &= m - 1;
                    if d <= far[k] {
                        live |= 1 << k;
                    }
                }
                (live != 0).then_some(live)
            });
            match next {
                Some(e) => (code, entered) = e,
                None => {
                    for k in 0..n {
                        hits[s.index[k] as usize] = best[k];
                    }
                    return;
                }
            }
        }
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::super::tests::avx_or_skip;
    use super::*;
    use crate::accel::Traversal;
    use crate::accel::workloads::{camera_rays, diffuse_rays, tile_order};
    use super::super::policy::ClosestBatches;
    use crate::scene::generated::for_tests as load_bench_scene;
    use crate::camera::Camera;

    /// `closest_streams` as its callers run it (compiled with AVX2).
    pub(in crate::accel::wide) fn streams(bvh: &WideBvh<8>, rays: &[Ray], hits: &mut [Option<Hit>]) {
        // SAFETY: the tests call this only after `avx_or_skip`.
        unsafe { bvh.closest_streams(rays, hits) }
    }

    /// On bench scenes, a tile's diffuse rays (the batches that stream)
    /// and random rays find exactly the single-ray hits, through the
    /// batch call, whichever way the batch goes (incoherent ones one ray
    /// at a time or interleaved).
    #[test]
    fn streamed_diffuse_rays_find_the_single_ray_hits() {
        if !avx_or_skip("the closest-hit streams") {
            return;
        }
        for spec in ["subdiv:CBbunny:100k", "grass:30k", "arch:50k"] {
            let scene = load_bench_scene(spec);
            let mut bvh = WideBvh::<8>::build(&scene.shapes);
            let cam = camera_rays(&Camera::from_scene(&scene), 256, 192);
            let diffuse = diffuse_rays(&scene, &bvh, &tile_order(&cam, 256, 192, 32), 3);
            let random = crate::accel::workloads::random_rays(&scene, 4096, 2);
            for (what, rays) in [("diffuse", &diffuse), ("random", &random)] {
                let want: Vec<Option<Hit>> = rays.iter().map(|r| bvh.intersect(r)).collect();
                let mut via_streams = vec![None; rays.len()];
                let mut via_batch = vec![None; rays.len()];
                for ((r, s), b) in rays.chunks(1024).zip(via_streams.chunks_mut(1024)).zip(via_batch.chunks_mut(1024)) {
                    streams(&bvh, r, s);
                    bvh.intersect_batch(r, b);
                }
                assert!(via_streams == want, "{spec} {what}: streamed hits differ from single rays");
                assert!(via_batch == want, "{spec} {what}: batch hits differ from single rays");
                // Incoherent batches interleaved instead of one ray at a time.
                let chosen = bvh.policy.closest;
                bvh.policy.closest = ClosestBatches::StreamsElseInterleaved;
                for (r, b) in rays.chunks(1024).zip(via_batch.chunks_mut(1024)) {
                    bvh.intersect_batch(r, b);
                }
                bvh.policy.closest = chosen;
                assert!(via_batch == want, "{spec} {what}: batch hits, streams else interleaved, differ from single rays");
            }
            assert!(bvh.streams_pay(&diffuse[..1024]), "{spec}: a tile's diffuse rays do not stream");
            assert!(!bvh.streams_pay(&random[..1024]), "{spec}: random rays stream");
        }
    }
}
