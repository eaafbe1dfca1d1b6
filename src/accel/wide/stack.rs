//! The stack every traversal walks the tree with, and its two steps: push
//! the entered children of a node (their fetches started, the one to visit
//! next on top, as the child order says) and pop past the entries that
//! cannot matter any more (the cull the traversal states: beyond one ray's
//! closest hit, no live ray in a packet's or stream's mask).
//!
//! An entry is a child's code, its entry distance and what entered it: `()`
//! for one ray, a ray mask for a packet (`u32`) or a stream (`u64`).

use super::kernels::{key_lane, nearest_first_keys, sort_far_first};
use super::{Node, WideBvh, STACK};
use std::mem::MaybeUninit;

/// A traversal stack of `(child code, entry distance, rays)`, not
/// initialised: only entries below the height are read. The height is the
/// caller's own local (`sp`), passed to each step: kept in the struct, it
/// lived in memory and every push and pop waited on its store (single
/// rays 25-45 % slower, measured). Aligned to a cache line, which makes the
/// traversal holding it realign its stack frame, so where the compiler
/// spills the ray's broadcast slab vectors (32-byte AVX loads on every node
/// visit) does not depend on the callers' frames. Without it, the same
/// machine code ran random rays 20 % slower in one build than in another
/// (CBbunny 12.5 against 15.5 Mrays/s, 1 thread): its spills straddled
/// cache lines.
#[repr(C, align(64))]
pub(super) struct WalkStack<M: Copy> {
    entries: [MaybeUninit<(u32, f32, M)>; STACK],
}

impl<M: Copy> WalkStack<M> {
    #[inline(always)]
    pub(super) fn new() -> Self {
        WalkStack { entries: [MaybeUninit::uninit(); STACK] }
    }

    #[inline(always)]
    pub(super) fn push(&mut self, sp: &mut usize, code: u32, near: f32, rays: M) {
        self.entries[*sp].write((code, near, rays));
        *sp += 1;
    }

    /// Sort the entries pushed since the height was `mark` (up to `sp`) so
    /// that the one `order` visits next is on top.
    #[inline(always)]
    pub(super) fn order_since(&mut self, mark: usize, sp: usize, order: ChildOrder) {
        // SAFETY: entries mark..sp were written by `push`.
        let pushed = unsafe { std::slice::from_raw_parts_mut(self.entries[mark..sp].as_mut_ptr() as *mut (u32, f32, M), sp - mark) };
        order.sort_pushed(pushed, |e| e.1);
    }

    /// Take the top entry's code and rays, with no cull: the child just
    /// pushed that the walk goes on with. The stack must not be empty.
    #[inline(always)]
    pub(super) fn take_top(&self, sp: &mut usize) -> (u32, M) {
        debug_assert!(*sp > 0);
        *sp -= 1;
        // SAFETY: every entry below the height was written.
        let (code, _, rays) = unsafe { self.entries[*sp].assume_init() };
        (code, rays)
    }

    /// Pop entries until `keep(entry distance, rays)` returns the rays to
    /// go on with; `None` when the stack runs out.
    #[inline(always)]
    pub(super) fn pop_where(&self, sp: &mut usize, mut keep: impl FnMut(f32, M) -> Option<M>) -> Option<(u32, M)> {
        while *sp > 0 {
            *sp -= 1;
            // SAFETY: every entry below the height was written.
            let (code, near, rays) = unsafe { self.entries[*sp].assume_init() };
            if let Some(r) = keep(near, rays) {
                return Some((code, r));
            }
        }
        None
    }

    /// The entries below the height `sp`, top first: each child's code and
    /// entry distance.
    #[inline(always)]
    pub(super) fn pending(&self, sp: usize) -> impl Iterator<Item = (u32, f32)> + '_ {
        // SAFETY: every entry below the height was written.
        self.entries[..sp].iter().rev().map(|e| {
            let (code, near, _) = unsafe { e.assume_init() };
            (code, near)
        })
    }
}

/// Whether a subtree entered at `near` may hold a hit closer than `tmax`:
/// scaled as the box tests scale it (`Slab::test`), so rounding never culls
/// a subtree the ray enters.
#[inline(always)]
pub(super) fn may_hold_closer(near: f32, tmax: f32) -> bool {
    near <= tmax * crate::accel::bvh::ROBUST_SCALE
}

impl WalkStack<()> {
    /// Pop until a child whose entry distance is within `tmax` (a subtree
    /// starting beyond it cannot hold a closer hit); `None` when the stack
    /// runs out.
    #[inline(always)]
    pub(super) fn pop_within(&self, sp: &mut usize, tmax: f32) -> Option<u32> {
        self.pop_where(sp, |near, ()| may_hold_closer(near, tmax).then_some(())).map(|(code, ())| code)
    }
}

impl<const W: usize> WideBvh<W> {
    /// Push the children of `node` in `mask` with their entry distances
    /// `near`, starting their fetches, the one to visit next on top as
    /// `order` says. `AVX` as for `Slab::test`.
    ///
    /// Nearest first goes by `nearest_first_keys` (sorted without a
    /// branch); farthest first keeps the insertion sort of the pushed
    /// entries: ordered by the keys too, the shadow batches of cow and
    /// maxplanck (coherent packets, farthest first, where the sort's
    /// branches are likely well predicted) ran 2-5 % slower.
    #[inline(always)]
    pub(super) fn push_entered<const AVX: bool>(&self, stack: &mut WalkStack<()>, sp: &mut usize, node: &Node<W>, mask: u32, near: &[f32; W], order: ChildOrder) {
        let mut push = |sp: &mut usize, lane: usize| {
            let code = node.child[lane];
            self.prefetch(code);
            stack.push(sp, code, near[lane], ());
        };
        if order == ChildOrder::NearestFirst {
            let keys = nearest_first_keys::<W, AVX>(near, mask);
            // The farthest pushed first, the nearest on top.
            for &key in keys[..mask.count_ones() as usize].iter().rev() {
                push(sp, key_lane(key));
            }
            return;
        }
        let mark = *sp;
        let mut m = mask;
        while m != 0 {
            push(sp, m.trailing_zeros() as usize);
            m &= m - 1;
        }
        stack.order_since(mark, *sp, order);
    }
}

/// The order a node's entered children are visited in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ChildOrder {
    /// Closest hit: nearest entry first, so later subtrees are culled by
    /// the hit found.
    NearestFirst,
    /// Any hit, unless `NearestFirst` visits less on the tree's sample
    /// (`any_order_of`): farthest entry first. Shadow rays leave a surface, so
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
    /// Hence the choice from a sample (`any_order_of`). With nearest first
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
