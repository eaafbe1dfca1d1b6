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

mod binning;
mod partition;
mod spatial;
use binning::{area_scale, find_split, Binning};
use partition::partition;

/// At most this many primitives per leaf; below it the SAH decides
/// (`SplitRole`).
pub(super) const MAX_LEAF: usize = 8;
/// Sets of at most this many primitives (one `BLOCK`) are leaves without an
/// SAH test, as in Embree's BVH8 triangle builder (minimum leaf size 4):
/// splitting one block's worth pays only when the halves' areas sum to
/// under half the parent's, which almost never happens (the 1M-sphere and
/// subdivided-bunny trees' SAH costs are unchanged to 1e-4), while binning
/// those sets was ~7 % of the build (1 thread: sphere 229 -> 213 ms,
/// subdivided bunny 517 -> 488).
const LEAF_ALWAYS: usize = BLOCK;
/// Cost of a binary split relative to one block test, added to every
/// candidate split's SAH (it orders splits the same either way) and the
/// leaf test of a set filled into a node that spans it (`SplitRole::Lane`).
const TRAVERSAL_COST: f32 = 0.5;
/// Cost of a wide node's visit relative to one block test, for the leaf
/// test of a set that would become a node (`SplitRole::Node`), Embree's
/// `travCost`.
const NODE_COST: f32 = 1.0;
/// A set filled into a node whose box has at least this share of the
/// node's half-area may stay a leaf (`SplitRole::Lane`).
const SPANNING: f32 = 0.5;

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

/// What a set is split for, which decides when it is a leaf instead.
///
/// A wide node is filled by splitting its largest child again until it has
/// `W` (`wide::layout::gather`). Those splits cost no node visit, the halves
/// being lanes of the same node, so a child above a block is split whatever
/// the binary SAH says; the SAH decides leaves where a set would become a
/// node of its own, against a whole node visit (`NODE_COST`), as Embree's
/// builder does. Deciding leaves at every binary split instead (at
/// `TRAVERSAL_COST`) built a fifth more nodes and SAH costs a little above
/// Embree's, where these are at or just below them; the subdivided bunny's
/// and grass's rays gained most (`docs/notes/2026-11-30-node-fill.md`).
///
/// One exception keeps a set spanning its node a leaf where the binary SAH
/// prefers it: primitives as large as the node (arch's ground and floor
/// slabs, two triangles each crossing everything) then stay in a leaf near
/// the root, which shadow rays test at once and which occludes nearly all
/// of them. Split down like the rest, they cut arch's SAH cost by a fifth
/// but made its shadow batches 3-7 times slower: the SAH counts
/// closest-hit work and nothing of where any-hit rays stop.
#[derive(Clone, Copy, Debug)]
pub(super) enum SplitRole {
    /// The set becomes a node unless the SAH prefers a leaf: its leaf cost
    /// against a node visit and its best split's.
    Node,
    /// The set is a child of the node being filled, whose half-area is
    /// `node_area`: split when it holds more than a block, unless it spans
    /// at least `SPANNING` of the node and the binary SAH prefers a leaf.
    Lane { node_area: f32 },
}

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
    /// most `LEAF_ALWAYS` primitives, no split found, or at most `MAX_LEAF`
    /// that `role`'s test keeps together. `prims` gives spatial splits the
    /// triangles to clip.
    pub(super) fn split(self, prims: &PrimTable, role: SplitRole) -> Result<(BuildSet<'a>, BuildSet<'a>), BuildSet<'a>> {
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
        let leaf_preferred = |c: f32| match role {
            SplitRole::Node => c - TRAVERSAL_COST + NODE_COST >= blocks(n),
            SplitRole::Lane { node_area } => c >= blocks(n) && self.half_area() >= SPANNING * node_area,
        };
        if n <= MAX_LEAF && cost.map_or(true, leaf_preferred) {
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
    if refs.len() > PARALLEL_BINNING {
        refs.par_chunks(BIN_CHUNK).map(ref_bounds_serial).reduce(|| (Box4::EMPTY, Box4::EMPTY), |a, b| (a.0.union(b.0), a.1.union(b.1)))
    } else {
        ref_bounds_serial(refs)
    }
}

/// `ref_bounds` in one pass on this thread.
fn ref_bounds_serial(refs: &[PrimRef]) -> (Box4, Box4) {
    let (mut b, mut c) = (Box4::EMPTY, Box4::EMPTY);
    for r in refs {
        b = b.union(Box4::of(r));
        c.grow(r.centroid2());
    }
    (b, c)
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
        assert!(BuildSet::root(&mut four, LEAF_ALWAYS).unwrap().split(&prims, SplitRole::Node).is_err(), "{LEAF_ALWAYS} primitives must make a leaf");
        let mut five = refs_of(LEAF_ALWAYS + 1);
        let (l, r) = BuildSet::root(&mut five, LEAF_ALWAYS + 1).unwrap().split(&prims, SplitRole::Node).ok().expect("five far-apart primitives must split");
        assert_eq!((l.len(), r.len()), (3, 2));
    }

    /// Six long slivers lying across one another (each spans the set's x,
    /// their centroids a little apart in y): every split leaves both sides
    /// nearly the set's size, so the SAH prefers one leaf of two blocks. A
    /// node of its own keeps them together, and so does a node being
    /// filled that they span; filled into a node ten times wider, they are
    /// split like any child above a block.
    #[test]
    fn leaves_are_decided_against_a_node_visit_and_split_when_filling_a_node() {
        let sliver = |i: usize| {
            let y = i as f32 * 0.01;
            Aabb { min: glam::Vec3::new(0.0, y, 0.0), max: glam::Vec3::new(10.0, y + 1.0, 0.1) }
        };
        let shapes: Vec<crate::scene::Shape> = Vec::new();
        let prims = PrimTable::new(&shapes);
        let split_as = |role: fn(f32) -> SplitRole| {
            let mut refs: Vec<PrimRef> = (0..6).map(|i| PrimRef::new(&sliver(i), i as u32)).collect();
            let set = BuildSet::root(&mut refs, 6).unwrap();
            let area = set.half_area();
            set.split(&prims, role(area)).is_ok()
        };
        assert!(!split_as(|_| SplitRole::Node), "the SAH prefers one leaf to a node");
        assert!(!split_as(|a| SplitRole::Lane { node_area: a }), "a set spanning its node stays a leaf");
        assert!(split_as(|a| SplitRole::Lane { node_area: 10.0 * a }), "a child filled into a wider node is split");
        // More than `MAX_LEAF` coincident primitives have no SAH split; in
        // either role they are split at the median, never one leaf.
        for role in [SplitRole::Node, SplitRole::Lane { node_area: 1.0 }] {
            let b = Aabb { min: glam::Vec3::ZERO, max: glam::Vec3::ONE };
            let mut refs: Vec<PrimRef> = (0..3 * MAX_LEAF as u32).map(|i| PrimRef::new(&b, i)).collect();
            let n = refs.len();
            assert!(BuildSet::root(&mut refs, n).unwrap().split(&prims, role).is_ok(), "{role:?}: {n} coincident primitives made one leaf");
        }
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
