//! Shadow rays through large trees as *streams*: a batch's rays sorted by
//! the sign pattern of their directions (octant) into groups of up to 64,
//! each group traced together with a ray mask per stacked node — Embree's
//! incoherent stream for occlusion (`rtcOccluded1M` without the coherent
//! flag), which on trees too large for the caches beats both its own
//! packets and ours.
//!
//! Every node is tested by each still-unoccluded ray that entered it, one
//! ray against the node's 8 boxes per AVX2 instruction (`entry_exit`,
//! the single-ray test's operations), which gives each child the mask of
//! the rays entering it. Against a ray at a time, a node shared by several
//! rays is fetched once (and prefetched when pushed), and its rays' tests
//! are independent of one another, where a single ray's visits are a chain
//! of dependent loads. Against the 16-ray packets (`frustum`, `sweep`,
//! `masked`), no box bounds the rays loosely, and 64 rays share each fetch.
//! One octant per stream fixes the near and far planes for all its rays.
//!
//! Answers equal single-ray traversal's: each ray enters exactly the boxes
//! its own slab test enters and tests the same triangles with the
//! watertight test, so it is occluded exactly when it is alone.

use super::kernels::{slab_planes, Slab};
use super::triangle::Shear;
use super::stack::WalkStack;
use super::{ChildOrder, Node, WideBvh, EMPTY, LEAF_BIT};
use crate::accel::Hit;
use crate::geometry::RayTransform;
use crate::ray::Ray;
use std::mem::MaybeUninit;

/// Rays per stream: one bit each in a `u64` mask.
pub(super) const STREAM: usize = 64;

/// A stream's rays: their indices in the batch, and their slab constants in
/// SoA form (broadcast one ray at a time by the node tests). Shared with
/// the closest-hit streams (`hit_stream`), which lower `tmax` and `far` as
/// their rays find hits.
pub(super) struct StreamRays {
    pub(super) index: [u32; STREAM],
    pub(super) o: [[f32; STREAM]; 3],
    pub(super) inv: [[f32; STREAM]; 3],
    pub(super) tmin: [f32; STREAM],
    pub(super) tmax: [f32; STREAM],
    /// `tmax` enlarged by `ROBUST_SCALE`, as the slab test enlarges it.
    pub(super) far: [f32; STREAM],
}

impl StreamRays {
    /// The stream of `rays[i]` for `i` in `which` (at most `STREAM`, all valid).
    #[inline(always)]
    pub(super) fn new(rays: &[Ray], which: &[u32]) -> Self {
        let mut s = StreamRays { index: [0; STREAM], o: [[0.0; STREAM]; 3], inv: [[0.0; STREAM]; 3], tmin: [0.0; STREAM], tmax: [0.0; STREAM], far: [0.0; STREAM] };
        for (k, &i) in which.iter().enumerate() {
            let r = &rays[i as usize];
            let slab = Slab::new(r);
            s.index[k] = i;
            for a in 0..3 {
                s.o[a][k] = slab.o[a];
                s.inv[a][k] = slab.inv[a];
            }
            s.tmin[k] = r.tmin;
            s.tmax[k] = r.tmax;
            s.far[k] = r.tmax * crate::accel::bvh::ROBUST_SCALE;
        }
        s
    }

    /// The mask of the stream's first `n` rays.
    pub(super) fn all(n: usize) -> u64 {
        if n == STREAM { u64::MAX } else { (1u64 << n) - 1 }
    }
}

/// Calls `trace(which, oct)` for the valid rays of `rays` grouped by the
/// octant of their directions, in batch order, into streams of up to
/// `STREAM`: each stream as it fills, then each octant's rest.
#[inline(always)]
pub(super) fn octant_streams(rays: &[Ray], mut trace: impl FnMut(&[u32], usize)) {
    octant_streams_until(rays, |_, _| false, |which, oct| {
        trace(which, oct);
        true
    })
}

/// The octant of a direction: bit a set where its sign bit on axis a is.
#[inline(always)]
pub(super) fn octant(d: glam::Vec3) -> usize {
    (d.x.is_sign_negative() as usize) | (d.y.is_sign_negative() as usize) << 1 | (d.z.is_sign_negative() as usize) << 2
}

/// `octant_streams` of the rays but those that `skip(index, octant)`,
/// until `trace` returns false.
#[inline(always)]
pub(super) fn octant_streams_until(rays: &[Ray], skip: impl Fn(usize, usize) -> bool, mut trace: impl FnMut(&[u32], usize) -> bool) {
    let mut waiting = [[0u32; STREAM]; 8];
    let mut count = [0usize; 8];
    for (i, r) in rays.iter().enumerate() {
        if !r.is_valid() {
            continue;
        }
        let oct = octant(r.dir);
        if skip(i, oct) {
            continue;
        }
        waiting[oct][count[oct]] = i as u32;
        count[oct] += 1;
        if count[oct] == STREAM {
            if !trace(&waiting[oct][..STREAM], oct) {
                return;
            }
            count[oct] = 0;
        }
    }
    for oct in 0..8 {
        if count[oct] > 0 && !trace(&waiting[oct][..count[oct]], oct) {
            return;
        }
    }
}

/// The rays a batch's first stream traced (`stream_choice`'s `closest_streams_where_shared`):
/// the valid rays of octant `oct` up to index `last`, which the way the
/// rest of the batch goes skips. A value, not a closure, so that the
/// batch's single-ray and interleaved loops are one compiled function
/// whether or not a stream went first: two instances of the same loop
/// can differ in speed by their code's placement alone.
#[derive(Clone, Copy, Debug)]
pub(super) struct FirstStream {
    pub(super) last: usize,
    pub(super) oct: usize,
}

impl FirstStream {
    /// Whether `rays[i]` was traced in the first stream `first`.
    #[inline(always)]
    pub(super) fn traced(first: Option<FirstStream>, rays: &[Ray], i: usize) -> bool {
        first.is_some_and(|f| i <= f.last && rays[i].is_valid() && octant(rays[i].dir) == f.oct)
    }
}

/// The node rows a stream of octant `oct` reads as near and far planes
/// (indices into `Node::bounds`): one octant fixes them for all its rays.
pub(super) fn octant_planes(oct: usize) -> ([usize; 3], [usize; 3]) {
    let near = [0, 1, 2].map(|a| if oct >> a & 1 != 0 { 3 + a } else { a });
    (near, near.map(|p| (p + 3) % 6))
}

/// What a stream's rays found at one node (`WideBvh::stream_enter`).
pub(super) struct Entered {
    /// The children some ray entered, as bits.
    pub(super) children: u32,
    /// Per child, the rays that entered it, as two halves of 32.
    rays: [[u32; 8]; 2],
    /// Per child, the nearest entry distance of those rays.
    pub(super) near: [f32; 8],
}

impl Entered {
    /// The rays that entered child `lane`.
    #[inline(always)]
    pub(super) fn rays(&self, lane: usize) -> u64 {
        self.rays[0][lane] as u64 | (self.rays[1][lane] as u64) << 32
    }
}

/// Trees smaller than this never stream: they stay in the caches, where
/// 16-ray packets were faster on every scene measured (1 thread, shadow
/// Mrays/s, packets / streams): cow (0.4 MiB) 38.9 / 20.8, CBbunny (1.8
/// MiB) 42.2 / 25.0, beetle 23.2 / 15.4, maxplanck (3.5 MiB) 12.0 / 10.1.
pub(super) const STREAM_MIN_BYTES: usize = 16 << 20;

/// Which way a tree's occlusion batches go is fixed when it is built
/// (`Policy::shadows`): streams where its rays are expected to
/// miss the caches (the test that interleaves camera rays and unshared
/// closest-hit batches, `interleave_reach`), packets elsewhere. Neither way wins
/// everywhere, and that test separates them (1 thread, shadow Mrays/s,
/// packets / streams, 2-vCPU AMD EPYC, 2026-11-28): sphere:1M 4.35 / 6.39,
/// sphere:5M 2.30 / 3.41, subdiv:bunny:1.5M 3.73 / 5.21, grass:500k
/// 0.35 / 0.66 (rays start among dense small triangles and share nodes
/// without sharing a tight box: interleaved) against arch:2M 49.4 / 13.6
/// and stadium:2M 14.9 / 14.8 (large triangles over empty space, whose
/// packets are tight swept boxes: not interleaved).
impl<const W: usize> WideBvh<W> {
    /// `out[i]` = whether `rays[i]` is occluded, in streams of up to
    /// `STREAM` rays of one octant each.
    ///
    /// # Safety
    /// The CPU must have AVX2 and the caller must be compiled with it; `W`
    /// must be 8. Compiled with AVX2 itself (not only inlined into callers
    /// that are): the closure tracing each stream takes its target
    /// features from here; without them its intrinsics were calls.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn any_streams(&self, rays: &[Ray], out: &mut [bool], order: ChildOrder) {
        debug_assert!(W == 8);
        if self.tree.root & LEAF_BIT != 0 || self.tree.root == EMPTY {
            return self.any_all_ordered::<true>(rays, out, order);
        }
        out.fill(false);
        octant_streams(rays, |which, oct| self.any_stream(rays, which, oct, out, order));
    }

    /// Each ray of `todo` tests `node`'s boxes (`Slab::entry_exit`'s
    /// operations, with the stream's near and far `planes`), which gives
    /// each child the mask of the rays entering it; every child some ray
    /// entered starts its fetch first: the leaves are tested right away,
    /// and their misses then overlap. The node test of both kinds of
    /// stream.
    ///
    /// # Safety
    /// The CPU must have AVX2 and the caller must be compiled with it; `W`
    /// must be 8.
    #[inline(always)]
    pub(super) unsafe fn stream_enter(&self, node: &Node<W>, planes: &([usize; 3], [usize; 3]), s: &StreamRays, todo: u64) -> Entered {
        use std::arch::x86_64::*;
        let rows = node.bounds.as_ptr() as *const f32;
        // Spelled out, not `[0, 1, 2].map(..)`: see `RaysSoA::new_with`.
        let load = |p: usize| _mm256_load_ps(rows.add(p * W));
        let (near_plane, far_plane) = planes;
        let lo = [load(near_plane[0]), load(near_plane[1]), load(near_plane[2])];
        let hi = [load(far_plane[0]), load(far_plane[1]), load(far_plane[2])];
        // Per child, the rays entering it (two halves of 32) and their
        // nearest entry distance.
        let inf = _mm256_set1_ps(f32::INFINITY);
        let mut masks = [_mm256_setzero_si256(); 2];
        let mut near = inf;
        for (half, m) in masks.iter_mut().enumerate() {
            let mut t = (todo >> (32 * half)) as u32;
            while t != 0 {
                let r = t.trailing_zeros() as usize;
                t &= t - 1;
                let i = 32 * half + r;
                let (t0, t1) = slab_planes::<__m256>(&lo, &hi, [s.o[0][i], s.o[1][i], s.o[2][i]], [s.inv[0][i], s.inv[1][i], s.inv[2][i]], s.tmin[i], s.tmax[i]);
                let hit = _mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1);
                *m = _mm256_or_si256(*m, _mm256_and_si256(_mm256_castps_si256(hit), _mm256_set1_epi32(1 << r)));
                near = _mm256_min_ps(near, _mm256_blendv_ps(inf, t0, hit));
            }
        }
        let none = _mm256_cmpeq_epi32(_mm256_or_si256(masks[0], masks[1]), _mm256_setzero_si256());
        let children = !_mm256_movemask_ps(_mm256_castsi256_ps(none)) as u32 & 0xff;
        let mut e = Entered { children, rays: [[0; 8]; 2], near: [0.0; 8] };
        if children != 0 {
            _mm256_storeu_si256(e.rays[0].as_mut_ptr() as *mut __m256i, masks[0]);
            _mm256_storeu_si256(e.rays[1].as_mut_ptr() as *mut __m256i, masks[1]);
            _mm256_storeu_ps(e.near.as_mut_ptr(), near);
            let mut b = children;
            while b != 0 {
                let lane = b.trailing_zeros() as usize;
                b &= b - 1;
                self.prefetch(node.child[lane]);
            }
        }
        e
    }

    /// One stream: `which` (at most `STREAM` indices into `rays`, all valid,
    /// all of octant `oct`).
    #[inline(always)]
    unsafe fn any_stream(&self, rays: &[Ray], which: &[u32], oct: usize, out: &mut [bool], order: ChildOrder) {
        let s = StreamRays::new(rays, which);
        let planes = octant_planes(oct);
        let mut active = StreamRays::all(which.len());
        // Triangle-test constants, made the first time a ray reaches a leaf.
        let mut setup: u64 = 0;
        let mut rts: [MaybeUninit<RayTransform>; STREAM] = [const { MaybeUninit::uninit() }; STREAM];
        let mut shears: [MaybeUninit<Shear>; STREAM] = [const { MaybeUninit::uninit() }; STREAM];
        // Stack of (node, the rays' nearest entry, the rays that entered it).
        let mut stack = WalkStack::<u64>::new();
        let mut sp = 0;
        let (mut code, mut entered) = (self.tree.root, active);
        loop {
            let node = &self.tree.nodes[code as usize];
            let e = self.stream_enter(node, &planes, &s, entered & active);
            let mark = sp;
            let mut b = e.children;
            while b != 0 {
                let lane = b.trailing_zeros() as usize;
                b &= b - 1;
                let child = node.child[lane];
                let r = e.rays(lane) & active;
                if r == 0 || child == EMPTY {
                    continue;
                }
                if child & LEAF_BIT == 0 {
                    stack.push(&mut sp, child, e.near[lane], r);
                    continue;
                }
                // A leaf: the rays that entered it test its triangles.
                let leaf = self.leaf_of(child);
                let mut m = r;
                while m != 0 {
                    let k = m.trailing_zeros() as usize;
                    m &= m - 1;
                    ready(k, &mut setup, &mut rts, &mut shears, rays, s.index[k]);
                    if m != 0 && leaf.n_spheres == 0 {
                        let j = m.trailing_zeros() as usize;
                        m &= m - 1;
                        ready(j, &mut setup, &mut rts, &mut shears, rays, s.index[j]);
                        let found = self.leaf_pair_any(&leaf, [rts[k].assume_init_ref(), rts[j].assume_init_ref()], [shears[k].assume_init_ref(), shears[j].assume_init_ref()], [s.tmin[k], s.tmin[j]], [s.tmax[k], s.tmax[j]]);
                        for (q, f) in [k, j].into_iter().zip(found) {
                            if f {
                                out[s.index[q] as usize] = true;
                                active &= !(1u64 << q);
                            }
                        }
                        continue;
                    }
                    let ray = &rays[s.index[k] as usize];
                    if self.leaf(&leaf, ray, rts[k].assume_init_ref(), shears[k].assume_init_ref(), s.tmax[k], &mut |_: Hit| true) {
                        out[s.index[k] as usize] = true;
                        active &= !(1u64 << k);
                    }
                }
                if active == 0 {
                    return;
                }
            }
            // The child `order` visits next on top (see `ChildOrder`).
            stack.order_since(mark, sp, order);
            match stack.pop_where(&mut sp, |_, r| (r & active != 0).then_some(r)) {
                Some(e) => (code, entered) = e,
                None => return,
            }
        }
    }
}

/// Make ray `k`'s triangle-test constants the first time it reaches a
/// leaf (bit `k` of `setup`).
#[inline(always)]
pub(super) fn ready(k: usize, setup: &mut u64, rts: &mut [MaybeUninit<RayTransform>; STREAM], shears: &mut [MaybeUninit<Shear>; STREAM], rays: &[Ray], index: u32) {
    if *setup >> k & 1 == 0 {
        *setup |= 1 << k;
        let r = &rays[index as usize];
        let rt = RayTransform::new(r.origin, r.dir);
        shears[k].write(Shear::new(&rt));
        rts[k].write(rt);
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{avx_or_skip, rays, shapes};
    use super::*;
    use crate::accel::brute::BruteForce;
    use crate::accel::Traversal;
    use crate::accel::workloads::{camera_rays, shadow_rays};
    use crate::scene::generated::for_tests as load_bench_scene;
    use crate::camera::Camera;

    /// `any_streams` compiled with AVX2, as its callers are.
    #[target_feature(enable = "avx2")]
    unsafe fn streams(bvh: &WideBvh<8>, rays: &[Ray], out: &mut [bool], order: ChildOrder) {
        bvh.any_streams(rays, out, order)
    }

    /// Streams answer as brute force: meshes and a sphere in one tree,
    /// camera, random and tight rays of every octant (more than a stream
    /// of some), short rays, rays starting inside boxes, invalid rays
    /// among them; both child orders; batches of every size from one ray
    /// (a stream of one) to all of them.
    #[test]
    fn streams_match_brute_force() {
        if !avx_or_skip("the occlusion streams") {
            return;
        }
        let shapes = shapes();
        let rays = rays(&shapes);
        let brute = BruteForce::new(&shapes);
        let want: Vec<bool> = rays.iter().map(|r| brute.occluded(r)).collect();
        assert!(want.iter().filter(|&&o| o).count() > 1000 && want.iter().filter(|&&o| !o).count() > 1000, "too few of one answer");
        let bvh = WideBvh::<8>::build(&shapes);
        for order in [ChildOrder::FarthestFirst, ChildOrder::NearestFirst] {
            for chunk in [rays.len(), 4096, 777, 64, 65, 3, 1] {
                let mut got = vec![true; rays.len()];
                for (r, o) in rays.chunks(chunk).zip(got.chunks_mut(chunk)) {
                    unsafe { streams(&bvh, r, o, order) };
                }
                let bad: Vec<usize> = (0..rays.len()).filter(|&i| got[i] != want[i]).collect();
                assert!(bad.is_empty(), "{order:?}, batches of {chunk}: {} mismatches, first {:?}", bad.len(), bad.first().map(|&i| rays[i]));
            }
        }
    }

    /// On bench scenes whose shadow rays start among dense small triangles
    /// (the subdivided scan, grass), and with every ray's range ending
    /// exactly at its own closest hit (where the robust box bound decides),
    /// streams answer as single rays.
    #[test]
    fn streamed_shadow_rays_answer_as_single_rays() {
        if !avx_or_skip("the occlusion streams") {
            return;
        }
        for spec in ["subdiv:CBbunny:100k", "grass:30k"] {
            let scene = load_bench_scene(spec);
            let bvh = WideBvh::<8>::build(&scene.shapes);
            let cam = camera_rays(&Camera::from_scene(&scene), 256, 192);
            let mut rays = shadow_rays(&scene, &bvh, &cam);
            // Camera rays ending exactly at their hit: each is occluded.
            let ending: Vec<Ray> = cam.iter().filter_map(|r| bvh.intersect(r).map(|h| Ray::with_range(r.origin, r.dir, r.tmin, h.t))).collect();
            let n_ending = ending.len();
            rays.extend(ending);
            let mut got = vec![false; rays.len()];
            for (r, o) in rays.chunks(4096).zip(got.chunks_mut(4096)) {
                unsafe { streams(&bvh, r, o, ChildOrder::FarthestFirst) };
            }
            let bad = rays.iter().zip(&got).filter(|(r, o)| bvh.occluded(r) != **o).count();
            assert_eq!(bad, 0, "{spec}: streamed shadow rays differ from single rays");
            assert!(got[got.len() - n_ending..].iter().all(|&o| o), "{spec}: a ray ending at its hit was not occluded");
        }
    }

    /// Both ways answer as single rays on a tree that streams.
    #[test]
    fn packets_and_streams_answer_alike() {
        if !avx_or_skip("the occlusion streams") {
            return;
        }
        let shapes = shapes();
        let rays = rays(&shapes);
        let mut bvh = WideBvh::<8>::build(&shapes);
        let want: Vec<bool> = rays.iter().map(|r| bvh.occluded(r)).collect();
        for streams in [false, true] {
            bvh.policy.shadows = if streams { super::super::policy::ShadowBatches::Streams } else { super::super::policy::ShadowBatches::Packets };
            let mut got = vec![false; rays.len()];
            bvh.occluded_coherent(&rays, &mut got);
            assert_eq!(got, want, "streams {streams}");
        }
    }
}

