//! Partitioning build references in place by a split's side, with the
//! bounds of both sides gathered in the same pass.
//!
//! Large sets are partitioned in parallel, as Embree's builder does: every
//! `CHUNK` of the set is partitioned on its own, in parallel; then the
//! right-side references that landed before the final boundary are swapped,
//! in parallel, with the left-side references that landed after it. Why: a
//! wide node's children come from several binary splits of its set in turn
//! (`layout::gather`), so the top node of a 1M-triangle mesh partitions
//! about 3M references before any of its subtrees can start. Serial, that
//! was about 13 ms of the 48-52 ms tree build on a 16-vCPU Intel Xeon
//! (build phases timed there; all the partitions of sets over 2^16 took
//! 20-25 ms). The chunks are cut at fixed offsets, so the result never
//! depends on the thread count.

use super::{ref_bounds_serial, Box4, PrimRef};
use rayon::prelude::*;

/// Sets larger than this are partitioned in parallel.
pub(super) const PARALLEL_PARTITION: usize = 1 << 16;

/// References per chunk of the parallel partition (512 KiB).
const CHUNK: usize = 1 << 14;

/// Swaps per task in the parallel partition's second pass.
const SWAP_TASK: usize = 1 << 14;

/// Sides' bounds: (primitive bounds, centroid bounds) of the left and the
/// right side.
pub(super) type SideBounds = ((Box4, Box4), (Box4, Box4));

/// In-place partition: the refs for which `pred` holds first. Returns their
/// number and the (primitive, centroid) bounds of both sides, gathered in
/// the same pass so the children need not scan their refs again.
pub(super) fn partition<F: Fn(&PrimRef) -> bool + Sync>(v: &mut [PrimRef], pred: F) -> (usize, SideBounds) {
    if v.len() > PARALLEL_PARTITION {
        partition_parallel(v, &pred)
    } else {
        partition_serial(v, &pred)
    }
}

thread_local! {
    /// The right side's references while `partition_serial` runs: one per
    /// thread, grown to the largest set it partitioned (at most
    /// `PARALLEL_PARTITION` references, 2 MiB).
    static RIGHT: std::cell::RefCell<Vec<PrimRef>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// A stable partition without branches on the side: every reference is
/// written both to the left side's place in `v` and to the right side's
/// buffer, and only the cursor of its own side moves. The two-ended scan
/// it replaced branched on every reference's side, which the CPU cannot
/// predict within a set being split; this one built the same trees 4-18 %
/// faster (docs/notes/2026-11-29-builds-and-thin-streams.md). The sides'
/// bounds are gathered in a second pass over references still in cache.
fn partition_serial<F: Fn(&PrimRef) -> bool>(v: &mut [PrimRef], pred: &F) -> (usize, SideBounds) {
    let n = v.len();
    let left = RIGHT.with(|right| {
        let mut right = right.borrow_mut();
        right.clear();
        right.reserve(n);
        let (base, out) = (v.as_mut_ptr(), right.as_mut_ptr());
        let (mut l, mut r) = (0usize, 0usize);
        for i in 0..n {
            // SAFETY: `l <= i < n`, so the write to `v` lands on an element
            // already read (or this one); `r <= i < n` fits the buffer's
            // reserved room. Both cursors count the references written
            // before `i` to their side.
            unsafe {
                let x = *base.add(i);
                let goes_left = pred(&x);
                *base.add(l) = x;
                *out.add(r) = x;
                l += goes_left as usize;
                r += !goes_left as usize;
            }
        }
        // SAFETY: the buffer's first `r` elements were written above.
        unsafe { right.set_len(r) };
        v[l..].copy_from_slice(&right);
        l
    });
    (left, (ref_bounds_serial(&v[..left]), ref_bounds_serial(&v[left..])))
}

fn merge(a: SideBounds, b: SideBounds) -> SideBounds {
    ((a.0 .0.union(b.0 .0), a.0 .1.union(b.0 .1)), (a.1 .0.union(b.1 .0), a.1 .1.union(b.1 .1)))
}

/// One contiguous run of swaps: `len` references from `left` (right-side
/// references before the boundary) with as many from `right` (left-side
/// references after it), both offsets into the whole set.
struct Swap {
    left: usize,
    right: usize,
    len: usize,
}

fn partition_parallel<F: Fn(&PrimRef) -> bool + Sync>(v: &mut [PrimRef], pred: &F) -> (usize, SideBounds) {
    let n = v.len();
    let parts: Vec<(usize, SideBounds)> = v.par_chunks_mut(CHUNK).map(|c| partition_serial(c, pred)).collect();
    let empty = ((Box4::EMPTY, Box4::EMPTY), (Box4::EMPTY, Box4::EMPTY));
    let bounds = parts.iter().fold(empty, |acc, p| merge(acc, p.1));
    let m: usize = parts.iter().map(|p| p.0).sum();
    // Chunk k holds its left side at [s, s + m_k) and its right side at
    // [s + m_k, e). Misplaced: right-side refs below m, left-side refs at or
    // above m; there are as many of one as of the other.
    let (mut wrong_right, mut wrong_left) = (Vec::new(), Vec::new());
    for (k, &(mk, _)) in parts.iter().enumerate() {
        let (s, e) = (k * CHUNK, ((k + 1) * CHUNK).min(n));
        let (lo, hi) = (s + mk, e.min(m));
        if lo < hi {
            wrong_right.push((lo, hi));
        }
        let (lo, hi) = (s.max(m), s + mk);
        if lo < hi {
            wrong_left.push((lo, hi));
        }
    }
    // Pair them off in order, in runs contiguous on both sides, cut to
    // tasks of at most SWAP_TASK.
    let mut swaps = Vec::new();
    let (mut a, mut b) = (wrong_right.into_iter().peekable(), wrong_left.into_iter().peekable());
    let (mut ra, mut rb) = (a.next(), b.next());
    while let (Some((a0, a1)), Some((b0, b1))) = (ra, rb) {
        let len = (a1 - a0).min(b1 - b0).min(SWAP_TASK);
        swaps.push(Swap { left: a0, right: b0, len });
        ra = if a0 + len < a1 { Some((a0 + len, a1)) } else { a.next() };
        rb = if b0 + len < b1 { Some((b0 + len, b1)) } else { b.next() };
    }
    debug_assert!(ra.is_none() && rb.is_none(), "as many misplaced on each side");
    let (below, above) = v.split_at_mut(m);
    let (below, above) = (Shared(below.as_mut_ptr()), Shared(above.as_mut_ptr()));
    swaps.par_iter().for_each(|s| {
        // SAFETY: every swap's `left` run lies in [0, m) and its `right` run
        // in [m, n); runs on one side never overlap (each misplaced ref is in
        // exactly one run), so the tasks write disjoint memory of `v`.
        unsafe {
            let l = std::slice::from_raw_parts_mut(below.get().add(s.left), s.len);
            let r = std::slice::from_raw_parts_mut(above.get().add(s.right - m), s.len);
            l.swap_with_slice(r);
        }
    });
    (m, bounds)
}

/// A pointer into the set, shared by the swap tasks (see the SAFETY note).
#[derive(Clone, Copy)]
struct Shared(*mut PrimRef);

// SAFETY: the swap tasks write disjoint ranges through it.
unsafe impl Send for Shared {}
unsafe impl Sync for Shared {}

impl Shared {
    fn get(self) -> *mut PrimRef {
        self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Aabb;
    use crate::rng::Rng;
    use glam::Vec3;

    fn refs(n: usize, seed: u64) -> Vec<PrimRef> {
        let mut rng = Rng::new(seed, 1);
        (0..n as u32)
            .map(|i| {
                let p = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 100.0;
                PrimRef::new(&Aabb { min: p, max: p + Vec3::splat(rng.uniform()) }, i)
            })
            .collect()
    }

    fn same(a: &Box4, b: &Box4) -> bool {
        a.lo.truncate() == b.lo.truncate() && a.hi.truncate() == b.hi.truncate()
    }

    /// The parallel partition puts exactly the refs `pred` holds for first,
    /// keeps every ref once, and returns the serial partition's count and
    /// bounds, whatever the split of the set into chunks: a set of one
    /// chunk and a bit, uneven sides, one side empty, every ref on one side.
    #[test]
    fn parallel_partition_agrees_with_the_serial_one() {
        for (n, cut) in [(PARALLEL_PARTITION + 1, 50.0), (5 * CHUNK + 777, 20.0), (9 * CHUNK, 97.0), (3 * CHUNK + 5, -1.0), (3 * CHUNK + 5, 1000.0), (CHUNK + 1, 50.0)] {
            let pred = |r: &PrimRef| r.centroid2().x < 2.0 * cut;
            let mut par = refs(n, n as u64);
            let mut ser = par.clone();
            let (m, b) = partition_parallel(&mut par, &pred);
            let (ms, bs) = partition_serial(&mut ser, &pred);
            assert_eq!(m, ms, "n {n}, cut {cut}");
            assert!(par[..m].iter().all(pred) && !par[m..].iter().any(pred), "n {n}, cut {cut}: sides mixed");
            let mut ids: Vec<u32> = par.iter().map(|r| r.index()).collect();
            ids.sort_unstable();
            assert!(ids.iter().enumerate().all(|(i, &id)| id == i as u32), "n {n}: refs lost or repeated");
            for (x, y) in [(b.0 .0, bs.0 .0), (b.0 .1, bs.0 .1), (b.1 .0, bs.1 .0), (b.1 .1, bs.1 .1)] {
                assert!(same(&x, &y), "n {n}, cut {cut}: bounds differ");
            }
        }
    }

    /// The serial partition keeps each side in the set's order, with every
    /// side's bounds, on sets of every size up to the parallel threshold
    /// (the per-thread buffer is reused from a larger set to a smaller).
    #[test]
    fn serial_partition_is_stable_with_each_sides_bounds() {
        for (n, cut) in [(PARALLEL_PARTITION, 50.0), (1000, 10.0), (1, 50.0), (0, 50.0), (777, -1.0), (777, 1000.0)] {
            let pred = |r: &PrimRef| r.centroid2().z < 2.0 * cut;
            let mut v = refs(n, 11 + n as u64);
            let want: Vec<u32> = v.iter().filter(|r| pred(r)).chain(v.iter().filter(|r| !pred(r))).map(|r| r.index()).collect();
            let m_want = v.iter().filter(|r| pred(r)).count();
            let (m, ((lb, lc), (rb, rc))) = partition_serial(&mut v, &pred);
            assert_eq!(m, m_want, "n {n}, cut {cut}");
            assert_eq!(v.iter().map(|r| r.index()).collect::<Vec<_>>(), want, "n {n}, cut {cut}: order");
            let ((wlb, wlc), (wrb, wrc)) = (ref_bounds_serial(&v[..m]), ref_bounds_serial(&v[m..]));
            assert!(same(&lb, &wlb) && same(&lc, &wlc) && same(&rb, &wrb) && same(&rc, &wrc), "n {n}, cut {cut}: bounds");
        }
    }

    /// The same set gives the same order at any thread count.
    #[test]
    fn parallel_partition_is_deterministic() {
        let n = 7 * CHUNK + 123;
        let pred = |r: &PrimRef| r.centroid2().y < 90.0;
        let run = |threads: usize| {
            let mut v = refs(n, 5);
            rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| partition_parallel(&mut v, &pred));
            v.iter().map(|r| r.index()).collect::<Vec<_>>()
        };
        assert_eq!(run(1), run(3));
    }
}
