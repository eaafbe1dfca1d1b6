//! Single rays, front to back: the 8-wide walk every other traversal
//! falls back on (`walk`), closest and any hit for one ray and for
//! batches traced ray by ray, and the child order any-hit rays take,
//! chosen per batch from a sample of its rays (`any_order`).

use super::kernels::{sort_far_first, Slab};
use super::triangle::Shear;
use super::{decayed_sum, CacheAligned, Node, WideBvh, EMPTY, LEAF_BIT, STACK};
use crate::accel::prims::closer;
use crate::accel::Hit;
use crate::geometry::RayTransform;
use crate::ray::Ray;
use std::mem::MaybeUninit;

/// Occlusion batches of at least this many rays may choose the any-hit
/// child order from `ORDER_SAMPLE` of them (`any_order`), every
/// `ORDER_REFRESH` such batches.
pub(super) const ORDER_MIN_BATCH: usize = 256;
const ORDER_SAMPLE: usize = 16;
const ORDER_REFRESH: u32 = 16;
/// Each sample's work is added to a running sum that keeps 3/4 of the
/// older ones, and the choice follows the sums: one sample of 16 rays
/// was too noisy. On the subdivided bunny's shadow rays (1 thread, 65
/// samples) the single samples chose nearest first 28 times while their
/// sums favoured farthest first 14.0k to 16.9k visits, and the batches
/// ran at 4.2 Mrays/s against 5.9 with farthest first throughout.
const ORDER_DECAY: (u32, u32) = (3, 4);
/// Nearest first is chosen only where its sampled work is below 7/8 of
/// farthest first's. The sample times single rays; coherent batches go in
/// packets, where nearest first's saving showed up smaller: on maxplanck
/// its sums were 5 % below farthest first's, yet its shadow rays ran at
/// 10.7 Mrays/s against 11.8 (1 thread); on stadium 22 % below (24.1
/// against 19.8 Mrays/s), on grass 62 % below (0.24 against 0.15).
const ORDER_MARGIN: (u64, u64) = (7, 8);

impl<const W: usize> WideBvh<W> {
    /// Front-to-back traversal; `visit` may lower `tmax` and returns true to
    /// stop. `AVX` selects the AVX2 box test, which the caller must have
    /// checked the CPU has (`self.avx`) and compiled for (`#[target_feature]`).
    #[inline(always)]
    fn walk<const AVX: bool, const ANY: bool, F: FnMut(Hit, &mut f32) -> bool>(&self, ray: &Ray, order: ChildOrder, work: &mut u32, mut visit: F) {
        if self.root == EMPTY {
            return;
        }
        let rt = RayTransform::new(ray.origin, ray.dir);
        let shear = Shear::new(&rt);
        let slab = Slab::new(ray);
        let mut tmax = ray.tmax;
        // Stack of (child code, entry distance), not initialised: only
        // entries below `sp` are read.
        let mut stack = CacheAligned([MaybeUninit::<(u32, f32)>::uninit(); STACK]);
        let stack = &mut stack.0;
        let mut sp = 0;
        let mut cur = self.root;
        loop {
            if cur & LEAF_BIT != 0 {
                let leaf = self.leaf_of(cur);
                *work += leaf.n_groups + leaf.n_spheres;
                let mut stop = false;
                self.leaf(&leaf, ray, &rt, &shear, tmax, &mut |h| {
                    stop = visit(h, &mut tmax);
                    stop
                });
                if stop {
                    return;
                }
            } else {
                *work += 1;
                let node = &self.nodes[cur as usize];
                let mut near = [0.0f32; W];
                let mask = slab.test::<W, AVX>(node, ray.tmin, tmax, &mut near);
                if mask != 0 {
                    let first = mask.trailing_zeros() as usize;
                    if mask & (mask - 1) == 0 {
                        // One child entered: no stack traffic.
                        cur = node.child[first];
                        continue;
                    }
                    // Push every entered child (the one `order` visits
                    // next on top), and continue with the top one.
                    sp = self.push_children(node, mask, &near, stack, sp, order);
                    sp -= 1;
                    // SAFETY: push_children wrote the entry at the old top.
                    cur = unsafe { stack[sp].assume_init() }.0;
                    continue;
                }
            }
            // Pop, skipping subtrees that start beyond the current closest hit.
            match pop_within(stack, &mut sp, tmax) {
                Some(code) => cur = code,
                None => return,
            }
        }
    }

    /// Push the children of `node` in `mask` with their entry distances,
    /// starting their fetches, the one to visit next on top as `order`
    /// says. Returns the new stack height.
    #[inline(always)]
    pub(super) fn push_children(&self, node: &Node<W>, mask: u32, near: &[f32; W], stack: &mut [MaybeUninit<(u32, f32)>; STACK], mut sp: usize, order: ChildOrder) -> usize {
        let base = sp;
        let mut m = mask;
        while m != 0 {
            let lane = m.trailing_zeros() as usize;
            m &= m - 1;
            let code = node.child[lane];
            self.prefetch(code);
            stack[sp].write((code, near[lane]));
            sp += 1;
        }
        // SAFETY: entries base..sp were written just above.
        let pushed = unsafe { std::slice::from_raw_parts_mut(stack[base..sp].as_mut_ptr() as *mut (u32, f32), sp - base) };
        order.sort_pushed(pushed, |e| e.1);
        sp
    }

    #[inline(always)]
    pub(super) fn closest<const AVX: bool>(&self, ray: &Ray) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        self.walk::<AVX, false, _>(ray, ChildOrder::NearestFirst, &mut 0, |h, tmax| {
            if closer(h, &best) {
                *tmax = h.t;
                best = Some(h);
            }
            false
        });
        best
    }

    #[inline(always)]
    pub(super) fn any<const AVX: bool>(&self, ray: &Ray, order: ChildOrder) -> bool {
        self.any_counted::<AVX>(ray, order, &mut 0)
    }

    /// `any`, adding the nodes and leaf groups it visits to `work`.
    #[inline(always)]
    fn any_counted<const AVX: bool>(&self, ray: &Ray, order: ChildOrder, work: &mut u32) -> bool {
        let mut hit = false;
        self.walk::<AVX, true, _>(ray, order, work, |_, _| {
            hit = true;
            true
        });
        hit
    }

    /// The child order for occlusion rays: whichever of farthest-first and
    /// nearest-first visits fewer nodes and leaf groups over `ORDER_SAMPLE`
    /// rays (spread over a batch) and the samples before it (`ORDER_DECAY`),
    /// nearest first only by a margin (`ORDER_MARGIN`). Which order
    /// finds occluders sooner depends on the scene (see `ChildOrder`); both
    /// give the same answers. The sample costs about what tracing a batch
    /// of 4096 shadow rays in packets costs 5 % of, so the choice is kept
    /// and made again every `ORDER_REFRESH` batches of at least
    /// `ORDER_MIN_BATCH` rays (smaller ones use the kept choice). Which
    /// batch samples depends on the order threads call in, so the speed
    /// may vary from run to run; the answers cannot.
    #[inline(always)]
    pub(super) fn any_order<const AVX: bool>(&self, rays: &[Ray]) -> ChildOrder {
        use std::sync::atomic::Ordering::Relaxed;
        let kept = self.any_order.load(Relaxed);
        if rays.len() < ORDER_MIN_BATCH || self.root == EMPTY || (kept != 0 && self.order_calls.fetch_add(1, Relaxed) % ORDER_REFRESH != 0) {
            return if kept == 2 { ChildOrder::NearestFirst } else { ChildOrder::FarthestFirst };
        }
        let (mut far, mut near) = (0u32, 0u32);
        for k in 0..ORDER_SAMPLE {
            let r = &rays[k * rays.len() / ORDER_SAMPLE];
            if r.is_valid() {
                self.any_counted::<AVX>(r, ChildOrder::FarthestFirst, &mut far);
                self.any_counted::<AVX>(r, ChildOrder::NearestFirst, &mut near);
            }
        }
        let (far, near) = (decayed_sum(&self.order_work[0], far, ORDER_DECAY), decayed_sum(&self.order_work[1], near, ORDER_DECAY));
        let nearest = (near as u64) * ORDER_MARGIN.1 < (far as u64) * ORDER_MARGIN.0;
        self.any_order.store(1 + nearest as u8, Relaxed);
        if nearest {
            ChildOrder::NearestFirst
        } else {
            ChildOrder::FarthestFirst
        }
    }

    #[inline(always)]
    pub(super) fn closest_all<const AVX: bool>(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        for (r, h) in rays.iter().zip(hits.iter_mut()) {
            *h = if r.is_valid() { self.closest::<AVX>(r) } else { None };
        }
    }

    #[inline(always)]
    pub(super) fn any_all<const AVX: bool>(&self, rays: &[Ray], out: &mut [bool]) {
        let order = self.any_order::<AVX>(rays);
        self.any_all_ordered::<AVX>(rays, out, order)
    }

    #[inline(always)]
    pub(super) fn any_all_ordered<const AVX: bool>(&self, rays: &[Ray], out: &mut [bool], order: ChildOrder) {
        for (r, o) in rays.iter().zip(out.iter_mut()) {
            *o = r.is_valid() && self.any::<AVX>(r, order);
        }
    }

    // The same traversal compiled for AVX2: the box test's intrinsics inline
    // only into functions built with the feature. Callers check `self.avx`.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn closest_all_avx(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        self.closest_all::<true>(rays, hits)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn any_all_avx(&self, rays: &[Ray], out: &mut [bool]) {
        self.any_all::<true>(rays, out)
    }
}

/// The order a node's entered children are visited in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ChildOrder {
    /// Closest hit: nearest entry first, so later subtrees are culled by
    /// the hit found.
    NearestFirst,
    /// Any hit, where it visits less than `NearestFirst` on a batch's
    /// sample (`any_order`): farthest entry first. Shadow rays leave a surface, so
    /// their nearest boxes hold that surface's own neighbourhood, which
    /// they start just off; the occluder is usually farther along.
    /// Measured against the tree's own order (the binary SAH's, last child
    /// first), 1 thread, shadow Mrays/s single rays / 16-ray packets:
    /// arch:200k 6.6 -> 11.1 / 1.7 -> 14.7 (99 % occluded), beetle 3.9 ->
    /// 4.4 / 5.1 -> 6.2, cow 6.5 -> 6.6 / 8.6 -> 9.4, CBbunny, sphere:1M
    /// and subdiv:bunny:500k unchanged; but stadium:200k 6.0 -> 5.2 / 6.8 ->
    /// 6.0, grass:200k 0.49 -> 0.40 / 0.41 -> 0.37, maxplanck 3.5 -> 3.3
    /// (occluders next to the origin). Path-traced renders unchanged
    /// (CBbunny, CBgems 32 spp -m 5: 8.62-8.76 s either way). Nearest first
    /// was worst (cow 6.7 -> 3.6).
    ///
    /// Hence the choice from a sample (`any_order`). With nearest first
    /// for every batch, shadow packets (1 thread, Mrays/s) gained on
    /// grass:500k 0.30-0.35 -> 0.40-0.42 and stadium:500k 13.1 -> 16.5-16.7
    /// but lost on arch:500k (33-34 -> 6.3-6.9), cow (24 -> 14),
    /// subdiv:bunny:500k (3.3 -> 2.0), CBbunny, beetle, maxplanck and
    /// sphere:1M (4-15 %); choosing per batch from a sample, grass 0.42,
    /// stadium 16.1, the rest within 2 % of farthest first (maxplanck's
    /// samples split between the orders: 8.1-8.2 against 8.3). Sampling
    /// every batch instead of every 16th cost 2-5 %.
    FarthestFirst,
}

impl ChildOrder {
    /// Sort children just pushed (entry distance `dist`) so that the one
    /// this order visits next is on top, at the end.
    #[inline(always)]
    pub(super) fn sort_pushed<T: Copy>(self, pushed: &mut [T], dist: impl Fn(&T) -> f32) {
        match self {
            ChildOrder::NearestFirst => sort_far_first(pushed, dist),
            ChildOrder::FarthestFirst => sort_far_first(pushed, |e| -dist(e)),
        }
    }
}

/// Pop stacked children until one whose entry distance is within `tmax`
/// (a subtree starting beyond it cannot hold a closer hit); `None` when the
/// stack runs out.
#[inline(always)]
pub(super) fn pop_within(stack: &[MaybeUninit<(u32, f32)>; STACK], sp: &mut usize, tmax: f32) -> Option<u32> {
    while *sp > 0 {
        *sp -= 1;
        // SAFETY: every entry below the stack height was written.
        let (code, dist) = unsafe { stack[*sp].assume_init() };
        // Scaled as the box tests scale it (`Slab::test`).
        if dist <= tmax * crate::accel::bvh::ROBUST_SCALE {
            return Some(code);
        }
    }
    None
}
