//! Binned SAH object splits: the references' doubled centroids binned on
//! all three axes at once, the bins swept for the cheapest split. Counts
//! and box unions are exact, so the result does not depend on how the
//! binning was divided (in parallel chunks near the root) or ordered (in
//! rounds: a round's bin numbers first, then its updates).

use super::{blocks, Box4, PrimRef, BIN_CHUNK, PARALLEL_BINNING, TRAVERSAL_COST};
use glam::Vec4;
use rayon::prelude::*;

/// Bins per axis: few for small nodes, where filling and sweeping the bins
/// costs more than it buys, many near the root, where split quality
/// matters most. Like Embree's `min(32, 4 + 0.05 n)`, in four steps; with
/// 16 bins everywhere the 1M-triangle build spent a third of its time
/// clearing and sweeping bins of nodes with a handful of triangles.
fn bins_for(n: usize) -> usize {
    match n {
        0..80 => 4,
        80..240 => 8,
        240..560 => 16,
        _ => 32,
    }
}

/// Maps doubled centroids to bins, all three axes at once. Axes without
/// extent get scale 0 (everything in bin 0) and are skipped by the sweep.
pub(super) struct Binning {
    lo: Vec4,
    scale: Vec4,
    last: f32,
}

impl Binning {
    pub(super) fn new(cbounds: &Box4, bins: usize) -> Binning {
        let extent = cbounds.hi - cbounds.lo;
        let b = bins as f32;
        let scale = Vec4::new(
            if extent.x > 0.0 { b / extent.x } else { 0.0 },
            if extent.y > 0.0 { b / extent.y } else { 0.0 },
            if extent.z > 0.0 { b / extent.z } else { 0.0 },
            0.0,
        );
        Binning { lo: cbounds.lo, scale, last: b - 1.0 }
    }

    /// Bin per axis in lanes 0-2 (lane 3 is 0): `trunc((c - lo) * scale)`
    /// clamped to `0..bins`.
    #[inline(always)]
    fn bins_of(&self, c: Vec4) -> [u32; 4] {
        // Clamp as floats (centroids are finite and not below `lo`, so `x`
        // is too), then convert with one truncating SIMD instruction; glam's
        // `as_ivec4` converts lane by lane with saturation checks, which
        // took 40 % of the partition's time.
        let x = ((c - self.lo) * self.scale).max(Vec4::ZERO).min(Vec4::splat(self.last));
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::*;
            let mut i = [0u32; 4];
            // SAFETY: SSE2 is part of x86-64; `i` has room for 4 lanes.
            unsafe { _mm_storeu_si128(i.as_mut_ptr() as *mut __m128i, _mm_cvttps_epi32(x.into())) };
            i
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            [x.x as u32, x.y as u32, x.z as u32, 0]
        }
    }

    /// A test of whether a centroid falls in bin `bin` or below on `axis`,
    /// as `bin` decides it (`trunc(x) <= bin` is `x < bin + 1` for `x >= 0`).
    pub(super) fn left_of(&self, axis: usize, bin: usize) -> LeftOf {
        LeftOf { lo: self.lo, scale: self.scale, limit: Vec4::splat((bin + 1) as f32), axis }
    }
}

/// See `Binning::left_of`. All lanes are computed and the axis's lane's
/// comparison picked from the sign mask: indexing a `Vec4` by a run-time
/// axis compiled to a jump table in the partition's inner loop.
pub(super) struct LeftOf {
    lo: Vec4,
    scale: Vec4,
    limit: Vec4,
    axis: usize,
}

impl LeftOf {
    #[inline]
    pub(super) fn test(&self, c: Vec4) -> bool {
        let below = ((c - self.lo) * self.scale).cmplt(self.limit).bitmask();
        below >> self.axis & 1 != 0
    }
}

/// References per round of `Bins::fill`: their bins are computed first,
/// into a buffer of this many, then added.
const FILL_ROUND: usize = 64;

/// Per axis, how many centroids fall in each bin and the union of their boxes.
#[derive(Clone, Copy)]
struct Bins<const N: usize> {
    counts: [[u32; N]; 3],
    boxes: [[Box4; N]; 3],
}

impl<const N: usize> Bins<N> {
    const EMPTY: Bins<N> = Bins { counts: [[0; N]; 3], boxes: [[Box4::EMPTY; N]; 3] };

    /// The bins of `refs`, in rounds of `FILL_ROUND`: all the round's bin
    /// numbers first, then the updates. Computed and used one reference
    /// at a time, each update's address waited on a chain of float and
    /// conversion steps, and the loads of later updates on the addresses
    /// of earlier stores; with the numbers in a buffer the updates' addresses
    /// are one load away. 32 bins, 1M references: 15 -> 9.5 ns per
    /// reference, random or coherent order (2-vCPU AMD EPYC, Zen 3).
    fn fill(refs: &[PrimRef], b: &Binning) -> Bins<N> {
        const { assert!(N.is_power_of_two(), "`add` masks bin numbers with N - 1") };
        let mut bins = Bins::EMPTY;
        let mut idx = [[0u32; 4]; FILL_ROUND];
        for round in refs.chunks(FILL_ROUND) {
            for (i, r) in idx.iter_mut().zip(round) {
                *i = b.bins_of(r.centroid2());
            }
            for (i, r) in idx.iter().zip(round) {
                bins.add(i, r);
            }
        }
        bins
    }

    /// Add reference `r`, whose bins per axis are `idx`.
    #[inline(always)]
    fn add(&mut self, idx: &[u32; 4], r: &PrimRef) {
        let rb = Box4::of(r);
        for axis in 0..3 {
            // `bins_of` clamps below `N`, a power of two: the mask only
            // spares the bounds check.
            let i = idx[axis] as usize & (N - 1);
            self.counts[axis][i] += 1;
            self.boxes[axis][i] = self.boxes[axis][i].union(rb);
        }
    }

    fn merge(mut self, o: Bins<N>) -> Bins<N> {
        for axis in 0..3 {
            for i in 0..N {
                self.counts[axis][i] += o.counts[axis][i];
                self.boxes[axis][i] = self.boxes[axis][i].union(o.boxes[axis][i]);
            }
        }
        self
    }
}

/// The best binned-SAH object split of a set: centroids in bins up to
/// `bin` (of `bins`) on `axis` go left. `cost` is in units of one block
/// test, with areas measured in units of `scale` (`parent_area` the set's
/// own); `overlap` is the part of the set's area where the two sides'
/// boxes overlap (spatial splits are tried where it is large; 0 where
/// `find_split` was not asked for it).
pub(super) struct ObjectSplit {
    pub(super) axis: usize,
    pub(super) bin: usize,
    pub(super) bins: usize,
    pub(super) cost: f32,
    pub(super) overlap: f32,
    pub(super) scale: f32,
    pub(super) parent_area: f32,
}

/// A power of two near 1 / (the box's largest extent): exact, so the
/// costs (and the tree) are those of the unscaled arithmetic wherever that
/// did not overflow.
pub(super) fn area_scale(bounds: &Box4) -> f32 {
    let size = (bounds.hi - bounds.lo).truncate().max_element();
    let exp = (size.to_bits() >> 23) & 0xff;
    if size > 0.0 && exp < 254 {
        f32::from_bits((254 - exp) << 23)
    } else {
        1.0
    }
}

/// Best binned-SAH object split, or `None` when the centroids do not
/// divide (all in one bin on every axis). Its sides' `overlap` is measured
/// only when asked for (`with_overlap`: spatial splits may follow), so the
/// default build does not pay for it.
pub(super) fn find_split(refs: &[PrimRef], bounds: &Box4, cbounds: &Box4, with_overlap: bool) -> Option<ObjectSplit> {
    match bins_for(refs.len()) {
        4 => find_split_in::<4>(refs, bounds, cbounds, with_overlap),
        8 => find_split_in::<8>(refs, bounds, cbounds, with_overlap),
        16 => find_split_in::<16>(refs, bounds, cbounds, with_overlap),
        _ => find_split_in::<32>(refs, bounds, cbounds, with_overlap),
    }
}

fn find_split_in<const N: usize>(refs: &[PrimRef], bounds: &Box4, cbounds: &Box4, with_overlap: bool) -> Option<ObjectSplit> {
    let n = refs.len();
    let scale = area_scale(bounds);
    let parent_area = bounds.half_area_scaled(scale).max(f32::MIN_POSITIVE);
    let extent = cbounds.hi - cbounds.lo;
    let binning = Binning::new(cbounds, N);
    let bins = if n > PARALLEL_BINNING {
        refs.par_chunks(BIN_CHUNK).map(|c| Bins::<N>::fill(c, &binning)).reduce(|| Bins::EMPTY, Bins::merge)
    } else {
        Bins::<N>::fill(refs, &binning)
    };
    let mut best: Option<(usize, usize, f32)> = None;
    for axis in 0..3 {
        if !(extent[axis] > 0.0) {
            continue;
        }
        let (counts, boxes) = (&bins.counts[axis], &bins.boxes[axis]);
        // Sweep from the right to get the area*blocks of every right side.
        let mut right_cost = [0.0f32; N];
        let mut acc = Box4::EMPTY;
        let mut cnt = 0;
        for i in (1..N).rev() {
            acc = acc.union(boxes[i]);
            cnt += counts[i] as usize;
            right_cost[i] = if cnt > 0 { acc.half_area_scaled(scale) * blocks(cnt) } else { 0.0 };
        }
        let mut acc = Box4::EMPTY;
        let mut cnt = 0;
        for i in 0..N - 1 {
            acc = acc.union(boxes[i]);
            cnt += counts[i] as usize;
            if cnt == 0 || cnt == n {
                continue;
            }
            let cost = TRAVERSAL_COST + (acc.half_area_scaled(scale) * blocks(cnt) + right_cost[i + 1]) / parent_area;
            if best.map_or(true, |b| cost < b.2) {
                best = Some((axis, i, cost));
            }
        }
    }
    let (axis, bin, cost) = best?;
    let overlap = if with_overlap {
        // The chosen sides' boxes, for their overlap.
        let (boxes, split) = (&bins.boxes[axis], bin + 1);
        let left = boxes[..split].iter().fold(Box4::EMPTY, |a, b| a.union(*b));
        let right = boxes[split..].iter().fold(Box4::EMPTY, |a, b| a.union(*b));
        let both = Box4 { lo: left.lo.max(right.lo), hi: left.hi.min(right.hi) };
        both.half_area_scaled(scale) / parent_area
    } else {
        0.0
    };
    Some(ObjectSplit { axis, bin, bins: N, cost, overlap, scale, parent_area })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Aabb;

    /// Binning in rounds gives the bins of one reference at a time, count
    /// for count and bit for bit, on both sides of a round's size and at
    /// odd sizes.
    #[test]
    fn binning_in_rounds_equals_one_reference_at_a_time() {
        let mut seed = 12345u32;
        let mut next = || {
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            (seed >> 8) as f32 / (1 << 24) as f32
        };
        for n in [1, FILL_ROUND - 1, FILL_ROUND, FILL_ROUND + 1, 1001] {
            let refs: Vec<PrimRef> = (0..n)
                .map(|i| {
                    let lo = glam::Vec3::new(next(), next(), next()) * 10.0;
                    PrimRef::new(&Aabb { min: lo, max: lo + glam::Vec3::new(next(), next(), next()) }, i as u32)
                })
                .collect();
            let (_, cbounds) = super::super::ref_bounds(&refs);
            let binning = Binning::new(&cbounds, 16);
            let got = Bins::<16>::fill(&refs, &binning);
            let mut want = Bins::<16>::EMPTY;
            for r in &refs {
                let c = r.centroid2();
                let i = ((c - cbounds.lo) * binning.scale).to_array();
                let idx = [0, 1, 2, 3].map(|a| if a < 3 { (i[a] as u32).min(15) } else { 0 });
                want.add(&idx, r);
            }
            assert_eq!(got.counts, want.counts, "{n} references");
            assert_eq!(got.counts[0].iter().sum::<u32>(), n as u32, "{n} references");
            let bits = |b: &Bins<16>| b.boxes.iter().flatten().flat_map(|x| x.lo.to_array().into_iter().chain(x.hi.to_array())).map(f32::to_bits).collect::<Vec<_>>();
            assert_eq!(bits(&got), bits(&want), "{n} references");
        }
    }
}
