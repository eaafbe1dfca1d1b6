//! Coherent rays (camera rays, shadow rays towards one light) traced 16 at
//! a time through the 8-wide tree: interior nodes are tested once per
//! packet against the packet's *interval* ray (the box of its origins and
//! of its reciprocal directions); each leaf box the interval ray enters is
//! then tested against all the packet's rays at once (`RaysSoA::test`, 8
//! rays per instruction; the rays are set up together, `packet`), and only
//! the rays that enter it intersect its triangles, two rays per AVX2
//! instruction (`intersect_group_x2`).
//!
//! Measured (1 thread, Mrays/s, camera/shadow): testing each ray against
//! the 8 boxes of a leaf parent instead of each leaf box against the rays
//! cost 15-30 % (1M-triangle sphere 23.5/5.4 against 27.2/6.3, CBbunny
//! 40.8/17.3 against 52.6/20.4, cow 46.1/12.7 against 56.5/14.8); pairing
//! the rays' triangle tests then gave CBbunny 57/22.7, cow 63/16.6, 1M
//! sphere 27.9/6.5.
//!
//! Camera batches take packets on every tree, also where incoherent
//! batches interleave (`interleave`): one packet's walk of the upper tree
//! serves 16 rays, most of which miss or hit the same few leaves.
//! Measured in one process, chunks alternated (1 thread, 2-vCPU AMD EPYC
//! Zen 3, 1024x1024 camera rays, Mrays/s, packets / interleaved / Embree
//! 4's 8-ray packets): subdivided bunny 1.5M 20.7 / 13.2 / 16.0, sphere
//! 1M 19.3 / 10.9 / 13.1, sphere 5M 13.8 / 10.1 / 10.1, grass 2M 3.3 /
//! 2.9 / 2.5.
//!
//! Answers equal single-ray traversal bit for bit: the interval test is
//! conservative (it enters every box any ray of the packet enters, see
//! `Frustum::test`), the per-ray leaf box test does the single-ray slab
//! test's operations on each lane, and the tie rule makes the closest hit
//! independent of the order leaves are visited in.
//!
//! Shadow packets of finite segments go to swept boxes first (`sweep`);
//! the interval ray serves those the sweep refuses (rays to infinity, end
//! points spread over a nearby area light). Packets whose rays cannot
//! share an interval ray (a zero or mixed-sign direction component, an
//! invalid ray) are traced one ray at a time, or, for shadow rays, with a
//! ray mask per node (`masked`).

use super::occluders::OccluderCache;
use super::packet::{RaysSoA, PACKET};
use super::stack::WalkStack;
use super::{Shear, WideBvh, EMPTY, LEAF_BIT};
use crate::accel::bvh::ROBUST_SCALE;
use crate::accel::prims::closer;
use crate::accel::Hit;
use crate::geometry::RayTransform;
use crate::ray::Ray;
use std::mem::MaybeUninit;

/// A packet gives up and finishes ray by ray once more than this many of
/// the leaf boxes its interval ray entered were entered by none of its rays,
/// and those are more than the useful ones: the interval is then too loose
/// for the packet to pay. Measured (1 thread, Mrays/s, 1024x768 camera rays
/// and their shadow rays, before -> after): arch:2M camera 21.9 -> 38.9,
/// subdiv:bunny:500k shadow 0.86 -> 2.58 (its single rays: 2.5), the CS184
/// scans, stadium and grass within 2 %, sphere:1M camera 20.5 -> 18.7 and
/// shadow 4.6 -> 4.3. A plain budget of node visits also rescued arch and
/// subdiv but halved grass:200k's camera rays (15.6 -> 8.4), whose packets
/// go deep and stay tight. The rays of a packet that gives up go on from
/// the subtrees it had still to visit, not from the root: camera rays, one
/// process, subtrees ÷ root 1.035-1.07 on the subdivided bunny 1.5M, sphere
/// 1M and 5M and grass 2M (1 packet in 35-310 gives up), arch 2M 0.98.
pub(super) const WASTED_LEAF_TESTS: u32 = 32;

#[cfg(test)]
thread_local! {
    /// Camera packets traced as frusta on this thread (tests check which
    /// way a batch went).
    pub(super) static FRUSTUM_PACKETS: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
}

/// Packets that gave up (tests check the fallback gives the same answers).
#[cfg(test)]
pub(super) static BAILOUTS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// Shadow packets whose unit directions differ by more than this in some
/// component go to `masked` traversal: the interval ray of a fanned-out
/// packet (shadow rays near their light) enters many boxes none of its rays
/// enters. Measured with that fallback (1 thread, noisy machine): 0.05 and
/// 0.1 alike, 0.2 lost on cow and grass, masked for every packet lost on
/// cow and beetle.
const MAX_SPREAD: f32 = 0.1;

/// Camera packets spreading wider than this (relative to their largest
/// direction component) are traced ray by ray too. Adjacent pixels never do
/// (16 pixels of an 800-pixel, 50° frame span 0.017), but a packet that
/// wraps from the end of one scanline to the start of the next spans the
/// whole frame: with 591-pixel rows, 1 packet in 37 did, and on the
/// architecture scene (few rays hit, the rest skim a dense facade) those
/// packets made camera rays 3.5 Mrays/s instead of 31. Loose enough for
/// 16-pixel rows of a 128-pixel frame (0.11).
const MAX_CAMERA_SPREAD: f32 = 0.25;

/// The interval ray of a packet: per axis, the range of origins and of
/// reciprocal directions (all of one sign), and which plane is near.
pub(super) struct Frustum {
    o_lo: [f32; 3],
    o_hi: [f32; 3],
    inv_lo: [f32; 3],
    inv_hi: [f32; 3],
    pub(super) near_plane: [usize; 3],
    tmin: f32,
}

impl Frustum {
    /// `None` when the rays do not all go the same way on every axis (or
    /// one is invalid, or has a zero direction component) or, with
    /// `limit_spread` (shadow rays), when their unit directions fan out by
    /// more than `MAX_SPREAD`. Camera rays are checked against
    /// `MAX_CAMERA_SPREAD` on their raw directions. The bounds come from
    /// the packet's set-up (`RaysSoA::new`).
    pub(super) fn of(soa: &RaysSoA, limit_spread: bool) -> Option<Frustum> {
        let b = &soa.bounds;
        if !b.uniform {
            return None;
        }
        let spread = |lo: &[f32; 3], hi: &[f32; 3]| (0..3).map(|a| hi[a] - lo[a]).fold(f32::NEG_INFINITY, f32::max);
        if limit_spread && spread(&b.unit_lo, &b.unit_hi) > MAX_SPREAD {
            return None;
        }
        let largest = (0..3).map(|a| b.d_lo[a].abs().max(b.d_hi[a].abs())).fold(0.0f32, f32::max);
        if !limit_spread && spread(&b.d_lo, &b.d_hi) > MAX_CAMERA_SPREAD * largest {
            return None;
        }
        Some(Frustum {
            o_lo: b.o_lo,
            o_hi: b.o_hi,
            inv_lo: b.inv_lo,
            inv_hi: b.inv_hi,
            near_plane: [0, 1, 2].map(|a| if soa.neg[a] & 1 != 0 { 3 + a } else { a }),
            tmin: b.tmin,
        })
    }

    /// `of` the rays' own set-up (for the tests; the CPU must have AVX2).
    #[cfg(test)]
    pub(super) fn new(rays: &[Ray], limit_spread: bool) -> Option<Frustum> {
        assert!(is_x86_feature_detected!("avx2"), "the packet set-up needs AVX2");
        // SAFETY: AVX2 checked just above.
        Frustum::of(&unsafe { RaysSoA::new(rays) }, limit_spread)
    }

    /// Bit i set when some ray of the packet may enter child i in
    /// [tmin, tmax]; `near` gets a lower bound of the rays' entry distances.
    ///
    /// A ray's slab distance is `fl(fl(plane - o) * inv)`. With `o` in
    /// [o_lo, o_hi], `fl(plane - o)` lies in [fl(plane - o_hi),
    /// fl(plane - o_lo)] because rounding is monotonic; the product of two
    /// intervals is bounded by its four corner products, again rounded
    /// monotonically. So the smallest corner bounds every ray's near
    /// distance from below and the largest (times `ROBUST_SCALE`) every far
    /// distance from above: a ray that passes its own test passes this one.
    /// Inputs are finite and non-zero, so no product is NaN.
    ///
    /// # Safety
    /// The CPU must have AVX2; `W` must be 8.
    #[inline(always)]
    unsafe fn test<const W: usize>(&self, n: &super::Node<W>, tmax: f32, near: &mut [f32; W]) -> u32 {
        use std::arch::x86_64::*;
        debug_assert_eq!(W, 8);
        let rows = n.bounds.as_ptr() as *const f32;
        let mut t0 = _mm256_set1_ps(self.tmin);
        let mut t1 = _mm256_set1_ps(tmax * ROBUST_SCALE);
        for a in 0..3 {
            let (o_lo, o_hi) = (_mm256_set1_ps(self.o_lo[a]), _mm256_set1_ps(self.o_hi[a]));
            let (i_lo, i_hi) = (_mm256_set1_ps(self.inv_lo[a]), _mm256_set1_ps(self.inv_hi[a]));
            let np = _mm256_load_ps(rows.add(self.near_plane[a] * W));
            let fp = _mm256_load_ps(rows.add((self.near_plane[a] + 3) % 6 * W));
            let (d0, d1) = (_mm256_sub_ps(np, o_hi), _mm256_sub_ps(np, o_lo));
            let tn = _mm256_min_ps(
                _mm256_min_ps(_mm256_mul_ps(d0, i_lo), _mm256_mul_ps(d0, i_hi)),
                _mm256_min_ps(_mm256_mul_ps(d1, i_lo), _mm256_mul_ps(d1, i_hi)),
            );
            let (d0, d1) = (_mm256_sub_ps(fp, o_hi), _mm256_sub_ps(fp, o_lo));
            let tf = _mm256_max_ps(
                _mm256_max_ps(_mm256_mul_ps(d0, i_lo), _mm256_mul_ps(d0, i_hi)),
                _mm256_max_ps(_mm256_mul_ps(d1, i_lo), _mm256_mul_ps(d1, i_hi)),
            );
            t0 = _mm256_max_ps(tn, t0);
            t1 = _mm256_min_ps(_mm256_mul_ps(tf, _mm256_set1_ps(ROBUST_SCALE)), t1);
        }
        _mm256_storeu_ps(near.as_mut_ptr(), t0);
        _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1)) as u32
    }
}

impl<const W: usize> WideBvh<W> {
    /// `closest_coherent_avx` with the AVX-512 packet kernels.
    ///
    /// # Safety
    /// The CPU must have AVX2 and AVX-512F (`self.policy.avx512()`); `W` must be 8.
    #[target_feature(enable = "avx2,avx512f")]
    pub(super) unsafe fn closest_coherent_avx512(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        self.closest_packets::<true>(rays, hits)
    }

    /// `any_coherent_avx` with the AVX-512 packet kernels.
    ///
    /// # Safety
    /// As `closest_coherent_avx512`.
    #[target_feature(enable = "avx2,avx512f")]
    pub(super) unsafe fn any_coherent_avx512(&self, rays: &[Ray], out: &mut [bool]) {
        self.any_packets::<true>(rays, out)
    }

    /// `hits[i]` = the closest hit of `rays[i]`, packets of `PACKET` rays.
    ///
    /// # Safety
    /// The CPU must have AVX2 (`self.policy.avx()`); `W` must be 8.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn closest_coherent_avx(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        self.closest_packets::<false>(rays, hits)
    }

    /// `out[i]` = whether `rays[i]` is occluded, packets of `PACKET` rays.
    ///
    /// # Safety
    /// As `closest_coherent_avx`.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn any_coherent_avx(&self, rays: &[Ray], out: &mut [bool]) {
        self.any_packets::<false>(rays, out)
    }

    /// The coherent entry points' body, inlined into each so it is compiled
    /// with its instruction set: packets as frusta where their rays allow,
    /// else ray by ray.
    #[inline(always)]
    unsafe fn closest_packets<const WIDE: bool>(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        let mut unused = [false; PACKET];
        for (r, h) in rays.chunks(PACKET).zip(hits.chunks_mut(PACKET)) {
            if self.tree.root & LEAF_BIT != 0 || r.len() < 2 {
                self.closest_all::<true>(r, h);
                continue;
            }
            let soa = RaysSoA::new(r);
            match Frustum::of(&soa, false) {
                Some(f) => {
                    #[cfg(test)]
                    FRUSTUM_PACKETS.with(|c| c.set(c.get() + 1));
                    self.frustum_packet::<false, WIDE>(&f, &soa, r, h, &mut unused, super::ChildOrder::NearestFirst)
                }
                None => self.closest_all::<true>(r, h),
            }
        }
    }

    /// As `closest_packets`, for occlusion; on trees that stream their
    /// shadow rays (`stream_shadows`), in streams.
    #[inline(always)]
    unsafe fn any_packets<const WIDE: bool>(&self, rays: &[Ray], out: &mut [bool]) {
        let order = self.policy.any_order;
        if self.policy.shadows == super::policy::ShadowBatches::Streams {
            return self.any_streams(rays, out, order);
        }
        self.any_packet_way::<WIDE>(rays, out, order)
    }

    /// Occlusion in packets of `PACKET` rays: the occluder cache, then swept
    /// boxes, interval rays or ray masks per node.
    #[inline(always)]
    pub(super) unsafe fn any_packet_way<const WIDE: bool>(&self, rays: &[Ray], out: &mut [bool], order: super::ChildOrder) {
        let mut unused = [None; PACKET];
        let mut cache = OccluderCache::default();
        for (r, o) in rays.chunks(PACKET).zip(out.chunks_mut(PACKET)) {
            if self.tree.root & LEAF_BIT != 0 || r.len() < 2 {
                self.any_all_ordered::<true>(r, o, order);
                continue;
            }
            let mut soa = RaysSoA::new_with::<false>(r);
            let pre = cache.occluded(self, &soa, r.len());
            if pre == (1u32 << r.len()) - 1 {
                o.fill(true);
                continue;
            }
            // Segments of finite length: swept boxes (`sweep`), of the rays
            // the cache left.
            if !self.any_sweep_packet(&soa, r, o, order, pre) {
                soa.fill_bounds();
                match Frustum::of(&soa, true) {
                    Some(f) => self.frustum_packet::<true, WIDE>(&f, &soa, r, &mut unused, o, order),
                    // Fanned out or of mixed signs: a ray mask per node.
                    None => self.any_masked(&soa, r, o, order),
                }
            }
            cache.record(soa.occluder.get());
        }
    }

    /// Closest hits into `hits` or, with `ANY`, occlusion into `occluded`
    /// (rays leave the packet once occluded). `WIDE`: with the AVX-512
    /// kernels (16 rays per leaf box test, 4 per triangle group test).
    #[inline(always)]
    pub(super) unsafe fn frustum_packet<const ANY: bool, const WIDE: bool>(&self, f: &Frustum, soa: &RaysSoA, rays: &[Ray], hits: &mut [Option<Hit>], occluded: &mut [bool], order: super::ChildOrder) {
        let n = rays.len();
        // The triangle-test constants are copied out of the set-up the
        // first time a ray reaches a leaf.
        let mut rts: [MaybeUninit<RayTransform>; PACKET] = [const { MaybeUninit::uninit() }; PACKET];
        let mut shears: [MaybeUninit<Shear>; PACKET] = [const { MaybeUninit::uninit() }; PACKET];
        let mut setup: u64 = 0;
        let mut tmax = [0.0f32; PACKET];
        for (i, r) in rays.iter().enumerate() {
            tmax[i] = r.tmax;
            if ANY {
                occluded[i] = false;
            } else {
                hits[i] = None;
            }
        }
        let mut active: u64 = (1u64 << n) - 1;
        let mut far = tmax[..n].iter().fold(f32::NEG_INFINITY, |m, &t| m.max(t));
        let mut stack = WalkStack::<()>::new();
        let mut sp = 0;
        let mut cur = self.tree.root;
        let (mut wasted, mut useful) = (0u32, 0u32);
        // Occlusion with one axis permutation for all rays: leaves test 8
        // rays against one triangle from the packet's own set-up.
        let shared_axes = if ANY { soa.shared_axes() } else { None };
        loop {
            if wasted > WASTED_LEAF_TESTS && wasted > useful {
                #[cfg(test)]
                BAILOUTS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                // Incoherent after all: finish ray by ray, each in the
                // subtrees the packet had still to visit (the node it was
                // about to test, then its stack), keeping what it found.
                // The interval ray enters every box any of its rays
                // enters, so those subtrees hold every hit left; a hit's
                // range only shortens the single-ray walk, so answers are
                // unchanged.
                let mut left = active;
                while left != 0 {
                    let i = left.trailing_zeros() as usize;
                    left &= left - 1;
                    let roots = std::iter::once((cur, f32::NEG_INFINITY)).chain(stack.pending(sp));
                    let (rt, shear) = soa.shear(i);
                    let ray = Ray { tmax: tmax[i], ..rays[i] };
                    if ANY {
                        let mut found = false;
                        self.walk_subtrees::<true, true, _>(roots, &ray, &rt, &shear, &soa.slab(i), order, |_, _| {
                            found = true;
                            true
                        });
                        occluded[i] = found;
                    } else {
                        let best = &mut hits[i];
                        self.walk_subtrees::<true, false, _>(roots, &ray, &rt, &shear, &soa.slab(i), order, |h, t| {
                            if closer(h, best) {
                                *t = h.t;
                                *best = Some(h);
                            }
                            false
                        });
                    }
                }
                return;
            }
            // `cur` is always an interior node: leaves are intersected from
            // their parent, ray by ray.
            let node = &self.tree.nodes[cur as usize];
            let mut near = [0.0f32; W];
            let mask = f.test::<W>(node, far, &mut near);
            let mut leaves = 0u32;
            for lane in 0..W {
                if node.child[lane] & LEAF_BIT != 0 && node.child[lane] != EMPTY {
                    leaves |= 1 << lane;
                }
            }
            if mask & leaves != 0 {
                // Start fetching the leaves while the rays test the node.
                self.prefetch_entered(node, mask & leaves);
                // Leaf by leaf, the rays that enter it (tested 8 at a time,
                // the single-ray slab test's operations lane by lane).
                let mut todo = mask & leaves;
                while todo != 0 {
                    let lane = todo.trailing_zeros() as usize;
                    todo &= todo - 1;
                    let mut rays_in = if WIDE { soa.test512(&f.near_plane, node, lane, &tmax) } else { soa.test(&f.near_plane, node, lane, &tmax) } & active;
                    if rays_in == 0 {
                        wasted += 1;
                        continue;
                    }
                    useful += 1;
                    let leaf = self.leaf_of(node.child[lane]);
                    if let (true, Some(k)) = (ANY, shared_axes.filter(|_| leaf.n_spheres == 0)) {
                        let found = self.leaf_rays_x8(&leaf, soa, rays_in, k, &tmax);
                        let mut f = found;
                        while f != 0 {
                            let i = f.trailing_zeros() as usize;
                            f &= f - 1;
                            occluded[i] = true;
                            tmax[i] = f32::NEG_INFINITY;
                        }
                        active &= !found;
                        continue;
                    }
                    macro_rules! ensure {
                        ($i:expr) => {
                            if setup & (1u64 << $i) == 0 {
                                setup |= 1u64 << $i;
                                let (rt, sh) = soa.shear($i);
                                shears[$i].write(sh);
                                rts[$i].write(rt);
                            }
                        };
                    }
                    while rays_in != 0 {
                        let i = rays_in.trailing_zeros() as usize;
                        rays_in &= rays_in - 1;
                        ensure!(i);
                        // Four rays at a time through triangle-only leaves
                        // with AVX-512 (the last repeated when there are
                        // three), else two.
                        if WIDE && rays_in.count_ones() >= 2 && leaf.n_spheres == 0 {
                            let mut quad = [i; 4];
                            for q in 1..4 {
                                if rays_in != 0 {
                                    quad[q] = rays_in.trailing_zeros() as usize;
                                    rays_in &= rays_in - 1;
                                    ensure!(quad[q]);
                                } else {
                                    quad[q] = quad[q - 1];
                                }
                            }
                            let found = self.leaf_quad::<ANY>(&leaf, quad, rays, &rts, &shears, &mut tmax, hits);
                            for (k, hit) in quad.into_iter().zip(found) {
                                if ANY && hit {
                                    occluded[k] = true;
                                    active &= !(1u64 << k);
                                    tmax[k] = f32::NEG_INFINITY;
                                }
                            }
                            continue;
                        }
                        // Two rays at a time through triangle-only leaves.
                        if rays_in != 0 && leaf.n_spheres == 0 {
                            let j = rays_in.trailing_zeros() as usize;
                            rays_in &= rays_in - 1;
                            ensure!(j);
                            let found = self.leaf_pair::<ANY>(&leaf, [i, j], rays, &rts, &shears, &mut tmax, hits);
                            for (k, hit) in [i, j].into_iter().zip(found) {
                                if ANY && hit {
                                    occluded[k] = true;
                                    active &= !(1u64 << k);
                                    tmax[k] = f32::NEG_INFINITY;
                                }
                            }
                            continue;
                        }
                        let (best, t) = (&mut hits[i], &mut tmax[i]);
                        let found = self.leaf(&leaf, &rays[i], rts[i].assume_init_ref(), shears[i].assume_init_ref(), *t, &mut |h| {
                            if ANY {
                                return true;
                            }
                            if closer(h, best) {
                                *t = h.t;
                                *best = Some(h);
                            }
                            false
                        });
                        if ANY && found {
                            // The ray leaves the packet: nothing it could
                            // still enter bounds the packet's range.
                            occluded[i] = true;
                            active &= !(1u64 << i);
                            tmax[i] = f32::NEG_INFINITY;
                        }
                    }
                }
                if active == 0 {
                    return;
                }
                far = tmax[..n].iter().fold(f32::NEG_INFINITY, |m, &t| m.max(t));
            }
            let inner = mask & !leaves;
            if inner != 0 {
                // `order`: nearest first for the closest hit, the batch's
                // tree's choice for any hit (`Policy::any_order`); a packet stops only
                // once every ray is occluded.
                self.push_entered::<true>(&mut stack, &mut sp, node, inner, &near, order);
            }
            // Pop the nearest child that may still hold a closer hit (the
            // leaves just tested may have shortened the rays).
            match stack.pop_within(&mut sp, far) {
                Some(code) => cur = code,
                None => return,
            }
        }
    }
}
