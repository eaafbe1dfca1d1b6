//! The native backend's build: binned SAH splits of primitive sets, which
//! `wide` applies to build its W-wide tree directly; spatial splits
//! (`spatial`) where a reference budget is given, which by default it is not.
//!
//! Box tests (in `wide`) follow Ize (2013): the far slab distance is enlarged
//! by `ROBUST_SCALE` = 1 + 2*gamma(3), so rounding can never cull a box the ray
//! really enters; with the watertight triangle test, closed meshes stay closed.

use super::prims::PrimTable;
use crate::geometry::Aabb;
use glam::Vec4;
use rayon::prelude::*;

mod partition;
mod spatial;
use partition::partition;

/// At most this many primitives per leaf; below it the SAH decides.
pub(super) const MAX_LEAF: usize = 8;
/// Sets of at most this many primitives (one `BLOCK`) are leaves without an
/// SAH test, as in Embree's BVH8 triangle builder (minimum leaf size 4):
/// splitting one block's worth pays only when the halves' areas sum to
/// under half the parent's, which almost never happens (the 1M-sphere and
/// subdivided-bunny trees' SAH costs are unchanged to 1e-4), while binning
/// those sets was ~7 % of the build (1 thread: sphere 229 -> 213 ms,
/// subdivided bunny 517 -> 488).
const LEAF_ALWAYS: usize = BLOCK;
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
/// Cost of a binary split relative to one block test, for the SAH. About
/// three binary splits make one 8-wide node visit, so a full node visit's
/// cost of 1 would overcharge them: with 1.0 the 1M-triangle tree's leaves
/// cost 3.78 expected block tests (Embree's 2.89), with 0.5 its SAH cost,
/// 15.81, matches Embree's 15.80.
const TRAVERSAL_COST: f32 = 0.5;
/// Leaves are tested `BLOCK` triangles at a time (`wide::LANES`), so the SAH
/// counts a side's primitives in whole blocks, as Embree's builder does: a
/// leaf of 3 triangles costs as much to test as one of 4. Counting single
/// primitives left the 1M-triangle mesh's groups half empty (2.03 triangles
/// per group of 4), doubling leaf memory and wasting lanes.
const BLOCK: usize = 4;

#[inline]
fn blocks(n: usize) -> f32 {
    n.div_ceil(BLOCK) as f32
}
/// Nodes with more primitives than this are also binned in parallel (the top
/// levels, where the subtree parallelism has not started yet), in chunks of
/// `BIN_CHUNK`. Bin counts and box unions are exact, so the tree does not
/// depend on the thread count.
const PARALLEL_BINNING: usize = 1 << 16;
const BIN_CHUNK: usize = 1 << 14;
/// Past this depth splits are medians: at most 32 more levels, so the
/// traversal stacks in `wide` are bounded.
const MAX_SAH_DEPTH: usize = 64;

/// Build-time primitive reference: the primitive's box as two SIMD vectors,
/// 32 bytes, the primitive's index carried in the `w` lanes (as Embree's
/// `PrimRef` does). Centroids are kept doubled (`lo + hi`), which bins the
/// same way and saves a multiply.
///
/// The index is split over both `w` lanes, 23 bits each, under the exponent
/// of 1.0, so each lane is a normal float in [1, 2). Stored as raw bits, a
/// small index is a denormal, and every SIMD add, multiply and min/max the
/// build does on whole vectors then takes the CPU's slow path for denormal
/// operands: binning cost 25 cycles per primitive instead of about 8, and
/// the whole 1M-triangle build ran at a third of its speed.
#[derive(Clone, Copy)]
pub(super) struct PrimRef {
    lo: Vec4,
    hi: Vec4,
}

const ONE_BITS: u32 = 0x3f80_0000;
const MANTISSA: u32 = 0x007f_ffff;

impl PrimRef {
    fn new(b: &Aabb, index: u32) -> PrimRef {
        let lane = |bits: u32| f32::from_bits(ONE_BITS | (bits & MANTISSA));
        PrimRef { lo: b.min.extend(lane(index)), hi: b.max.extend(lane(index >> 23)) }
    }

    #[inline]
    pub(super) fn index(&self) -> u32 {
        (self.lo.w.to_bits() & MANTISSA) | (self.hi.w.to_bits() & MANTISSA) << 23
    }

    #[inline]
    fn centroid2(&self) -> Vec4 {
        self.lo + self.hi
    }

    /// This reference with box `b` (a spatial split's piece), same index.
    fn with_box(&self, b: Box4) -> PrimRef {
        PrimRef { lo: b.lo.truncate().extend(self.lo.w), hi: b.hi.truncate().extend(self.hi.w) }
    }
}

/// A box in SIMD form; the `w` lanes carry no meaning.
#[derive(Clone, Copy)]
struct Box4 {
    lo: Vec4,
    hi: Vec4,
}

impl Box4 {
    const EMPTY: Box4 = Box4 { lo: Vec4::splat(f32::INFINITY), hi: Vec4::splat(f32::NEG_INFINITY) };

    #[inline]
    fn union(self, o: Box4) -> Box4 {
        Box4 { lo: self.lo.min(o.lo), hi: self.hi.max(o.hi) }
    }

    #[inline]
    fn of(r: &PrimRef) -> Box4 {
        Box4 { lo: r.lo, hi: r.hi }
    }

    #[inline]
    fn grow(&mut self, p: Vec4) {
        self.lo = self.lo.min(p);
        self.hi = self.hi.max(p);
    }

    #[inline]
    fn half_area(&self) -> f32 {
        self.half_area_scaled(1.0)
    }

    /// Half the area of this box scaled by `s`. The split search measures
    /// boxes in units of their parent's largest extent: products of raw
    /// extents overflow f32 from coordinates near 1e18 (and, times the
    /// block count, sooner), which made the SAH pick arbitrary splits.
    #[inline]
    fn half_area_scaled(&self, s: f32) -> f32 {
        let e = (self.hi - self.lo).max(Vec4::ZERO) * s;
        e.x * e.y + e.y * e.z + e.z * e.x
    }

    fn aabb(&self) -> Aabb {
        Aabb { min: self.lo.truncate(), max: self.hi.truncate() }
    }
}

/// A node under construction: a run of the build's primitive references
/// with their bounds. `split` divides it by the SAH, in place, into the two
/// runs of its children; `wide` calls it until it has a node's `W` children,
/// so the W-wide tree is built directly, with no binary tree in between.
///
/// `refs` reaches past the set's `n` references to the end of its spare
/// room: the share of the build's reference budget that spatial splits
/// below it may fill with duplicated references (`spatial`). Each split
/// shares the room between the children in proportion to their sizes, as
/// Embree's spatial-split builder does, moving the right child's run up.
pub(super) struct BuildSet<'a> {
    refs: &'a mut [PrimRef],
    n: usize,
    bounds: Box4,
    cbounds: Box4,
    /// Binary splits above this set.
    depth: usize,
    /// Index of `refs[0]` in the root's references.
    offset: usize,
    /// The root's half area (in units of `scale`) when spatial splits are
    /// allowed.
    root: Option<RootArea>,
}

#[derive(Clone, Copy)]
struct RootArea {
    scale: f32,
    area: f32,
}

/// References to every primitive of `prims`, in order, with room after
/// them for `spare` more (duplicates made by spatial splits).
pub(super) fn prim_refs(prims: &PrimTable, spare: usize) -> Vec<PrimRef> {
    let mut refs: Vec<PrimRef> = super::huge::vec_with_capacity(prims.len() + spare);
    prims.par_map(&mut refs, |i, p| PrimRef::new(&p.bounds(), i));
    if let Some(&first) = refs.first() {
        refs.resize(prims.len() + spare, first);
    }
    refs
}

impl<'a> BuildSet<'a> {
    /// The root set over the first `n` of `refs` (the rest is spare room
    /// for spatial splits, which are made only if there is any); `None`
    /// when there are none.
    pub(super) fn root(refs: &'a mut [PrimRef], n: usize) -> Option<BuildSet<'a>> {
        if n == 0 {
            return None;
        }
        let (bounds, cbounds) = ref_bounds(&refs[..n]);
        let scale = area_scale(&bounds);
        let root = (refs.len() > n).then(|| RootArea { scale, area: bounds.half_area_scaled(scale).max(f32::MIN_POSITIVE) });
        Some(BuildSet { refs, n, bounds, cbounds, depth: 0, offset: 0, root })
    }

    pub(super) fn len(&self) -> usize {
        self.n
    }

    pub(super) fn bounds(&self) -> Aabb {
        self.bounds.aabb()
    }

    pub(super) fn half_area(&self) -> f32 {
        self.bounds.half_area()
    }

    /// The primitives' indices, in the set's order.
    pub(super) fn indices(&self) -> impl Iterator<Item = u32> + '_ {
        self.refs[..self.n].iter().map(|r| r.index())
    }

    /// Where the set starts in the references `root` was given; they keep
    /// the set's order once the build is done with it.
    pub(super) fn offset(&self) -> usize {
        self.offset
    }

    /// The two children by binned SAH (object or, where it pays and the
    /// budget allows, spatial), or `Err(self)` when this set is a leaf: at
    /// most `LEAF_ALWAYS` primitives, or at most `MAX_LEAF` that the SAH
    /// prefers to test together. `prims` gives spatial splits the
    /// triangles to clip.
    pub(super) fn split(self, prims: &PrimTable) -> Result<(BuildSet<'a>, BuildSet<'a>), BuildSet<'a>> {
        let n = self.n;
        if n <= LEAF_ALWAYS {
            return Err(self);
        }
        // Spatial splits need room for their duplicates.
        let room_for_spatial = self.root.filter(|_| self.refs.len() > n);
        // Past MAX_SAH_DEPTH the SAH could keep peeling one primitive at a
        // time off a pathological input; median splits bound the depth instead.
        let object = if self.depth < MAX_SAH_DEPTH { find_split(&self.refs[..n], &self.bounds, &self.cbounds, room_for_spatial.is_some()) } else { None };
        let spatial = match (&object, room_for_spatial) {
            (Some(o), Some(root)) if o.overlap * self.bounds.half_area_scaled(root.scale) > spatial::ALPHA * root.area => {
                spatial::find(&self.refs[..n], prims, &self.bounds, o.scale, o.parent_area).filter(|s| s.cost < o.cost && s.left + s.right <= self.refs.len())
            }
            _ => None,
        };
        let cost = spatial.map(|s| s.cost).or(object.as_ref().map(|o| o.cost));
        if n <= MAX_LEAF && cost.map_or(true, |c| c >= blocks(n)) {
            return Err(self);
        }
        let BuildSet { refs, cbounds, depth, offset, root, .. } = self;
        if let Some(s) = spatial {
            let (nl, right_start, nr) = spatial::apply(refs, n, prims, &s);
            let (l, r) = refs.split_at_mut(right_start);
            let (lb, rb) = (ref_bounds(&l[..nl]), ref_bounds(&r[..nr]));
            let left = BuildSet { refs: l, n: nl, bounds: lb.0, cbounds: lb.1, depth: depth + 1, offset, root };
            let right = BuildSet { refs: r, n: nr, bounds: rb.0, cbounds: rb.1, depth: depth + 1, offset: offset + right_start, root };
            return Ok((left, right));
        }
        let sides = match object {
            Some(o) => {
                let left_of = Binning::new(&cbounds, o.bins).left_of(o.axis, o.bin);
                let (m, (left, right)) = partition(&mut refs[..n], |r| left_of.test(r.centroid2()));
                if m == 0 || m == n {
                    None
                } else {
                    Some((m, left, right))
                }
            }
            None => None,
        };
        let (mid, left, right) = sides.unwrap_or_else(|| {
            // Too many primitives for one leaf and no SAH split (all centroids
            // equal, or too deep): split at the median of the widest axis.
            let axis = cbounds.aabb().largest_axis();
            refs[..n].select_nth_unstable_by(n / 2, |a, b| a.centroid2()[axis].total_cmp(&b.centroid2()[axis]));
            (n / 2, ref_bounds(&refs[..n / 2]), ref_bounds(&refs[n / 2..n]))
        });
        // The left child's share of the spare room goes between the runs.
        let spare = refs.len() - n;
        let room = (spare as u64 * mid as u64 / n as u64) as usize;
        if room > 0 {
            refs.copy_within(mid..n, mid + room);
        }
        let (l, r) = refs.split_at_mut(mid + room);
        Ok((BuildSet { refs: l, n: mid, bounds: left.0, cbounds: left.1, depth: depth + 1, offset, root }, BuildSet { refs: r, n: n - mid, bounds: right.0, cbounds: right.1, depth: depth + 1, offset: offset + mid + room, root }))
    }
}

/// Ize's conservative factor, 1 + 2*gamma(3) with gamma(n) = n*eps/(1 - n*eps).
pub(super) const ROBUST_SCALE: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

/// Bounds of the primitives and of their (doubled) centroids.
fn ref_bounds(refs: &[PrimRef]) -> (Box4, Box4) {
    let one = |refs: &[PrimRef]| {
        let (mut b, mut c) = (Box4::EMPTY, Box4::EMPTY);
        for r in refs {
            b = b.union(Box4::of(r));
            c.grow(r.centroid2());
        }
        (b, c)
    };
    if refs.len() > PARALLEL_BINNING {
        refs.par_chunks(BIN_CHUNK).map(one).reduce(|| (Box4::EMPTY, Box4::EMPTY), |a, b| (a.0.union(b.0), a.1.union(b.1)))
    } else {
        one(refs)
    }
}

/// Maps doubled centroids to bins, all three axes at once. Axes without
/// extent get scale 0 (everything in bin 0) and are skipped by the sweep.
struct Binning {
    lo: Vec4,
    scale: Vec4,
    last: f32,
}

impl Binning {
    fn new(cbounds: &Box4, bins: usize) -> Binning {
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

    /// Bin per axis: `trunc((c - lo) * scale)` clamped to `0..bins`.
    #[inline]
    fn bin(&self, c: Vec4) -> [usize; 3] {
        // Clamp as floats (centroids are finite and not below `lo`, so `x`
        // is too), then convert with one truncating SIMD instruction; glam's
        // `as_ivec4` converts lane by lane with saturation checks, which
        // took 40 % of the partition's time.
        let x = ((c - self.lo) * self.scale).max(Vec4::ZERO).min(Vec4::splat(self.last));
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::*;
            let mut i = [0i32; 4];
            // SAFETY: SSE2 is part of x86-64; `i` has room for 4 lanes.
            unsafe { _mm_storeu_si128(i.as_mut_ptr() as *mut __m128i, _mm_cvttps_epi32(x.into())) };
            [i[0] as usize, i[1] as usize, i[2] as usize]
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            [x.x as usize, x.y as usize, x.z as usize]
        }
    }

    /// A test of whether a centroid falls in bin `bin` or below on `axis`,
    /// as `bin` decides it (`trunc(x) <= bin` is `x < bin + 1` for `x >= 0`).
    fn left_of(&self, axis: usize, bin: usize) -> LeftOf {
        LeftOf { lo: self.lo, scale: self.scale, limit: Vec4::splat((bin + 1) as f32), axis }
    }
}

/// See `Binning::left_of`. All lanes are computed and the axis's lane's
/// comparison picked from the sign mask: indexing a `Vec4` by a run-time
/// axis compiled to a jump table in the partition's inner loop.
struct LeftOf {
    lo: Vec4,
    scale: Vec4,
    limit: Vec4,
    axis: usize,
}

impl LeftOf {
    #[inline]
    fn test(&self, c: Vec4) -> bool {
        let below = ((c - self.lo) * self.scale).cmplt(self.limit).bitmask();
        below >> self.axis & 1 != 0
    }
}

/// Per axis, how many centroids fall in each bin and the union of their boxes.
#[derive(Clone, Copy)]
struct Bins<const N: usize> {
    counts: [[u32; N]; 3],
    boxes: [[Box4; N]; 3],
}

impl<const N: usize> Bins<N> {
    const EMPTY: Bins<N> = Bins { counts: [[0; N]; 3], boxes: [[Box4::EMPTY; N]; 3] };

    fn fill(refs: &[PrimRef], b: &Binning) -> Bins<N> {
        let mut bins = Bins::EMPTY;
        for r in refs {
            let idx = b.bin(r.centroid2());
            let rb = Box4::of(r);
            for axis in 0..3 {
                let i = idx[axis];
                bins.counts[axis][i] += 1;
                bins.boxes[axis][i] = bins.boxes[axis][i].union(rb);
            }
        }
        bins
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
struct ObjectSplit {
    axis: usize,
    bin: usize,
    bins: usize,
    cost: f32,
    overlap: f32,
    scale: f32,
    parent_area: f32,
}

/// A power of two near 1 / (the box's largest extent): exact, so the
/// costs (and the tree) are those of the unscaled arithmetic wherever that
/// did not overflow.
fn area_scale(bounds: &Box4) -> f32 {
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
fn find_split(refs: &[PrimRef], bounds: &Box4, cbounds: &Box4, with_overlap: bool) -> Option<ObjectSplit> {
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

    /// Sets of up to `LEAF_ALWAYS` primitives are leaves even where the SAH
    /// would split them (two tiny pairs far apart: the split costs about
    /// 0.5 block tests against the leaf's 1); one more primitive and the
    /// SAH splits.
    #[test]
    fn sets_of_one_block_are_leaves_without_an_sah_test() {
        let tiny = |x: f32| Aabb { min: glam::Vec3::new(x, 0.0, 0.0), max: glam::Vec3::new(x + 0.01, 0.01, 0.01) };
        let at = [0.0, 0.02, 100.0, 100.02, 0.04];
        let refs_of = |n: usize| -> Vec<PrimRef> { (0..n).map(|i| PrimRef::new(&tiny(at[i]), i as u32)).collect() };
        let mut four = refs_of(LEAF_ALWAYS);
        let shapes: Vec<crate::scene::Shape> = Vec::new();
        let prims = PrimTable::new(&shapes);
        assert!(BuildSet::root(&mut four, LEAF_ALWAYS).unwrap().split(&prims).is_err(), "{LEAF_ALWAYS} primitives must make a leaf");
        let mut five = refs_of(LEAF_ALWAYS + 1);
        let (l, r) = BuildSet::root(&mut five, LEAF_ALWAYS + 1).unwrap().split(&prims).ok().expect("five far-apart primitives must split");
        assert_eq!((l.len(), r.len()), (3, 2));
    }

    /// Indices survive the split encoding up to the largest `u32`, and the
    /// `w` lanes holding them are normal floats (no denormal slow path).
    #[test]
    fn prim_ref_index_round_trips_in_normal_lanes() {
        let b = Aabb { min: glam::Vec3::splat(-1.0), max: glam::Vec3::ONE };
        for i in [0u32, 1, 7, (1 << 23) - 1, 1 << 23, (1 << 23) + 5, 123_456_789, 1 << 31, u32::MAX] {
            let r = PrimRef::new(&b, i);
            assert_eq!(r.index(), i);
            assert!(r.lo.w.is_normal() && r.hi.w.is_normal(), "index {i}: w lanes {} {}", r.lo.w, r.hi.w);
            assert!(r.centroid2().w.is_normal());
        }
    }
}
