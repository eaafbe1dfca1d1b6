//! Incoherent closest-hit batches over structures whose rays miss the
//! core's caches traced `IN_FLIGHT` rays at a time, step by step in turn, so
//! one ray's node fetch overlaps the other rays' box and triangle tests
//! (on large structures, the batches whose first stream's rays do not
//! share its nodes: `interleave_reach`, `stream_choice`; camera batches go in
//! packets on every tree, `frustum`).
//!
//! On the 1M-triangle mesh, random rays spent 42 % of their samples on the
//! instruction after a node load: a lone ray's traversal is a chain of
//! dependent cache misses. Independent walkers in one loop give the
//! out-of-order core several chains to work on. Each ray still takes exactly
//! the single-ray path (same tests, same order), so answers are identical.

use super::stack::WalkStack;
use super::{Shear, Slab, WideBvh, EMPTY, LEAF_BIT};
use crate::accel::prims::closer;
use crate::accel::Hit;
use crate::geometry::RayTransform;
use crate::ray::Ray;

/// Structures at least this large trace incoherent batches interleaved.
/// Random rays, 4 in flight against 1 (`pathtracer bench`, 2-core EPYC with
/// 32 MiB of L3): 1M triangles (68 MB) +23 %, 400k (26 MB) +17 %, 200k
/// (13 MB) -4 %, CBbunny (1.7 MB) -32 %: below this size the walkers' extra
/// state costs more than the overlapped misses save. With 12 in flight and
/// the prefetch, still (1 thread, random / diffuse batches, Mrays/s, auto
/// against interleaved): cow 9.7 / 13.0 against 8.5 / 6.5, CBbunny 11.3-11.9
/// / 10.5-10.7 against 8.5-8.7 / 6.3, maxplanck 5.8-6.6 / 7.4-7.5 against
/// 6.2-6.4 / 3.3-4.3.
pub(super) const INTERLEAVE_BYTES: usize = 16 << 20;

/// Size is not enough: what interleaving overlaps is cache misses, and a
/// large structure whose rays mostly stay in a small part of it misses
/// little. So a structure is also interleaved only when a ray is expected
/// to fetch at least `COLD_LINES` cache lines from outside its `HOT_ITEMS`
/// most likely nodes and leaves (`cold_lines`; 4096 nodes are 1 MiB, this
/// EPYC's L2 per core). Measured (1 thread, random rays, Mrays/s, two runs
/// each, interleaved against single rays; cold lines in brackets): sphere
/// 400k 3.63-3.75 against 2.96-3.06 (18.5), sphere 1M 3.33-3.38 /
/// 2.82-2.88 (21.2), sphere 5M 2.42-2.58 / 1.79-2.02 (29.9), grass 2M
/// 0.41-0.44 / 0.32-0.35 (288), subdiv bunny 1.5M 6.97-7.17 / 6.50-6.80
/// (8.1); but arch 2M 16.80-16.90 / 18.82-18.83 (0.37), arch 10M
/// 15.64-15.68 / 17.13-17.56 (0.86), stadium 2M 7.83-7.85 / 8.81-8.89
/// (1.5): the teapot-in-a-stadium and architecture scenes are mostly large
/// triangles over empty space, whose few nodes stay cached.
pub(super) const HOT_ITEMS: usize = 4096;
pub(super) const COLD_LINES: f64 = 3.0;

/// Trees from this size up to `INTERLEAVE_BYTES` whose rays are expected to
/// fetch `COLD_LINES` trace their incoherent closest-hit batches
/// interleaved, and keep packets for camera rays and streams for coherent
/// batches (`ClosestBatches::StreamsElseInterleaved`): their rays miss the
/// core's own caches and wait on the shared one. Random batches, native ÷
/// Embree 4 in one run (2-vCPU AMD EPYC, Zen 3; 1 thread, four runs each,
/// one ray at a time / interleaved; size and cold lines in brackets):
/// sphere 200k 0.82-0.94 / 1.18-1.34 (12.7 MB, 13.1), grass 200k
/// 0.84-1.09 / 1.72-1.76 (13.2 MB, 34.2), sphere 100k 0.79-0.90 /
/// 0.98-1.22 (6.6 MB, 10.2); camera and diffuse batches unchanged. Below
/// 4 MiB, where the rule first began, mixed then (two runs each): sphere
/// 50k 0.77-0.91 / 0.86-1.00 (3.3 MB, 6.9), maxplanck 0.74-0.87 /
/// 0.86-0.94 (3.4 MB, 7.5); and the small scans (cow, beetle, CBbunny,
/// under 2 MB) lost 9-17 %. Since the walkers prefetch what they enter,
/// trees from 2 MiB with the cold lines gain too (random batches of sphere
/// 50k and maxplanck +18-35 % in one process alternating with Embree every
/// 8192 rays; in the bench, each tree warm in the caches, sphere 50k +14 %,
/// maxplanck level) while CBbunny (1.8 MB, 0.6 cold lines) and the scans
/// under 1 MB lose 13-26 %: docs/notes/2026-12-02-one-ray-calls.md.
pub(super) const INTERLEAVE_INCOHERENT_BYTES: usize = 2 << 20;

/// Rays in flight per thread. With each walker prefetching the one child
/// it enters (`step`), more walkers keep more misses in flight: random
/// batches, native ÷ Embree 4 in one run, 1 thread, two runs, 4 / 8 / 12
/// / 16 in flight: sphere 1M 1.18-1.27 / 1.47-1.50 / 1.57-1.58 /
/// 1.51-1.74, subdivided bunny 1.5M 0.98-1.03 / 1.06-1.17 / 1.21-1.26 /
/// 1.11-1.13, sphere 5M 1.31-1.39 / 1.62-1.65 / 1.66-1.71 / 1.46-1.72
/// (4 in flight measured at 2 threads). Without the prefetch 4 had been
/// best of 2, 4 and 8.
const IN_FLIGHT: usize = 12;

/// Which closest-hit batches a tree traces interleaved (`interleave_reach`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum InterleaveReach {
    None,
    /// Batches whose rays do not start close together.
    Incoherent,
    /// Every closest-hit batch but those whose first stream's rays share
    /// its nodes (`stream_choice`).
    All,
}

/// One ray's traversal state between steps; cache-aligned, which also
/// aligns the frame of the function holding the walkers (`WalkStack`).
#[repr(align(64))]
struct Walker {
    /// Index of the ray in the batch.
    ray: usize,
    rt: RayTransform,
    shear: Shear,
    slab: Slab,
    tmax: f32,
    best: Option<Hit>,
    cur: u32,
    sp: usize,
    stack: WalkStack<()>,
}

impl Walker {
    fn idle() -> Walker {
        let r = Ray::new(glam::Vec3::ZERO, glam::Vec3::X);
        let rt = RayTransform::new(r.origin, r.dir);
        Walker { ray: usize::MAX, shear: Shear::new(&rt), rt, slab: Slab::new(&r), tmax: 0.0, best: None, cur: EMPTY, sp: 0, stack: WalkStack::new() }
    }

    fn start(&mut self, i: usize, r: &Ray, root: u32) {
        self.ray = i;
        self.rt = RayTransform::new(r.origin, r.dir);
        self.shear = Shear::new(&self.rt);
        self.slab = Slab::new(r);
        self.tmax = r.tmax;
        self.best = None;
        self.cur = root;
        self.sp = 0;
    }
}

impl<const W: usize> WideBvh<W> {
    /// Which closest-hit batches gain from interleaving on this tree: none
    /// where it is small or its rays are expected to stay in the caches;
    /// every kind where it is large (`INTERLEAVE_BYTES`, `All`); the incoherent
    /// ones in between (`INTERLEAVE_INCOHERENT_BYTES`).
    pub(super) fn interleave_reach(&self) -> InterleaveReach {
        use super::Traversal;
        let bytes = self.memory_bytes();
        if bytes < INTERLEAVE_INCOHERENT_BYTES || self.cold_lines(HOT_ITEMS).0 < COLD_LINES {
            InterleaveReach::None
        } else if bytes >= INTERLEAVE_BYTES {
            InterleaveReach::All
        } else {
            InterleaveReach::Incoherent
        }
    }

    /// `hits[i]` = the closest hit of `rays[i]`, `IN_FLIGHT` rays at a time.
    ///
    /// # Safety
    /// The CPU must have AVX2 (`self.policy.avx()`).
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn closest_interleaved_avx(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        self.closest_interleaved_except(rays, hits, None);
    }

    /// `closest_interleaved_avx` of the rays but those that the batch's
    /// `first` stream traced, whose hits are left as they are. Never
    /// inlined: one compiled loop for every caller (`FirstStream`).
    ///
    /// # Safety
    /// As `closest_interleaved_avx`.
    #[target_feature(enable = "avx2")]
    #[inline(never)]
    pub(super) unsafe fn closest_interleaved_except(&self, rays: &[Ray], hits: &mut [Option<Hit>], first: Option<super::stream::FirstStream>) {
        if self.tree.root == EMPTY {
            hits.fill(None);
            return;
        }
        let mut next = 0;
        // The next valid ray not yet traced, answering invalid ones on the way.
        let mut take = |hits: &mut [Option<Hit>]| -> Option<usize> {
            while next < rays.len() {
                let i = next;
                next += 1;
                if super::stream::FirstStream::traced(first, rays, i) {
                    continue;
                }
                if rays[i].is_valid() {
                    return Some(i);
                }
                hits[i] = None;
            }
            None
        };
        let mut w: [Walker; IN_FLIGHT] = std::array::from_fn(|_| Walker::idle());
        let mut live = 0u32;
        for k in 0..IN_FLIGHT {
            if let Some(i) = take(hits) {
                w[k].start(i, &rays[i], self.tree.root);
                live |= 1 << k;
            }
        }
        while live != 0 {
            for k in 0..IN_FLIGHT {
                if live & (1 << k) == 0 {
                    continue;
                }
                let wk = &mut w[k];
                if self.step(wk, &rays[wk.ray]) {
                    hits[wk.ray] = wk.best;
                    match take(hits) {
                        Some(i) => wk.start(i, &rays[i], self.tree.root),
                        None => live &= !(1 << k),
                    }
                }
            }
        }
    }

    /// Advance `w` by one node or leaf; true when its traversal is over.
    #[inline(always)]
    unsafe fn step(&self, w: &mut Walker, ray: &Ray) -> bool {
        if w.cur & LEAF_BIT != 0 {
            let leaf = self.leaf_of(w.cur);
            let (best, tmax) = (&mut w.best, &mut w.tmax);
            self.leaf(&leaf, ray, &w.rt, &w.shear, *tmax, &mut |h| {
                if closer(h, best) {
                    *tmax = h.t;
                    *best = Some(h);
                }
                false
            });
        } else {
            let node = &self.tree.nodes[w.cur as usize];
            let mut near = [0.0f32; W];
            let mask = w.slab.test::<W, true>(node, ray.tmin, w.tmax, &mut near);
            if mask != 0 {
                if mask & (mask - 1) == 0 {
                    // The other walkers step before this one enters it:
                    // time for the fetch to arrive (random batches +9-25 %
                    // on the 1M+ meshes at 4 in flight).
                    w.cur = node.child[mask.trailing_zeros() as usize];
                    self.prefetch(w.cur);
                    return false;
                }
                self.push_entered::<true>(&mut w.stack, &mut w.sp, node, mask, &near, super::ChildOrder::NearestFirst);
                w.cur = w.stack.take_top(&mut w.sp).0;
                return false;
            }
        }
        match w.stack.pop_within(&mut w.sp, w.tmax) {
            Some(code) => {
                w.cur = code;
                false
            }
            None => true,
        }
    }
}
