//! The native backend's build: a binary BVH by binned SAH (parallel with
//! rayon on large subtrees), which `bvh4` collapses into its 4-wide layout.
//!
//! Box tests (in `bvh4`) follow Ize (2013): the far slab distance is enlarged
//! by `ROBUST_SCALE` = 1 + 2*gamma(3), so rounding can never cull a box the ray
//! really enters; with the watertight triangle test, closed meshes stay closed.

use super::prims::Prim;
use crate::geometry::Aabb;
use glam::Vec3;
use rayon::prelude::*;

/// At most this many primitives per leaf; below it the SAH decides.
const MAX_LEAF: usize = 8;
const BINS: usize = 16;
/// Cost of one node visit relative to one primitive test, for the SAH.
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
/// Subtrees with more primitives than this are built in parallel.
const PARALLEL_THRESHOLD: usize = 4096;
/// Nodes with more primitives than this are also binned in parallel (the top
/// levels, where the subtree parallelism has not started yet), in chunks of
/// `BIN_CHUNK`. Bin counts and box unions are exact, so the tree does not
/// depend on the thread count.
const PARALLEL_BINNING: usize = 1 << 16;
const BIN_CHUNK: usize = 1 << 14;
/// Past this depth splits are medians: at most 32 more levels, so the
/// traversal stacks in `bvh4` are bounded.
const MAX_SAH_DEPTH: usize = 64;

/// Build-time primitive reference.
#[derive(Clone, Copy)]
struct PrimRef {
    bounds: Aabb,
    centroid: Vec3,
    index: u32,
}

/// The binary tree the SAH build produces; `bvh4` collapses it to 4-wide.
pub(super) enum BuildNode {
    /// `first..first+count` index the primitive order returned with the tree.
    Leaf { bounds: Aabb, first: usize, count: usize },
    Interior { bounds: Aabb, children: Box<(BuildNode, BuildNode)> },
}

impl BuildNode {
    pub(super) fn bounds(&self) -> &Aabb {
        match self {
            BuildNode::Leaf { bounds, .. } | BuildNode::Interior { bounds, .. } => bounds,
        }
    }
}

/// Binned-SAH build over `prims`: the tree and the primitive order its leaves
/// index. `None` for no primitives.
pub(super) fn build_tree(prims: &[Prim]) -> Option<(BuildNode, Vec<u32>)> {
    let mut refs: Vec<PrimRef> = prims
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let b = p.bounds();
            PrimRef { bounds: b, centroid: b.center(), index: i as u32 }
        })
        .collect();
    if refs.is_empty() {
        return None;
    }
    let root = build_recursive(&mut refs, 0, 0);
    Some((root, refs.iter().map(|r| r.index).collect()))
}

/// Ize's conservative factor, 1 + 2*gamma(3) with gamma(n) = n*eps/(1 - n*eps).
pub(super) const ROBUST_SCALE: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

/// Bounds of the primitives and of their centroids.
fn ref_bounds(refs: &[PrimRef]) -> (Aabb, Aabb) {
    let one = |refs: &[PrimRef]| {
        let (mut b, mut c) = (Aabb::EMPTY, Aabb::EMPTY);
        for r in refs {
            b = b.union(&r.bounds);
            c.grow(r.centroid);
        }
        (b, c)
    };
    if refs.len() > PARALLEL_BINNING {
        refs.par_chunks(BIN_CHUNK).map(one).reduce(|| (Aabb::EMPTY, Aabb::EMPTY), |a, b| (a.0.union(&b.0), a.1.union(&b.1)))
    } else {
        one(refs)
    }
}

fn build_recursive(refs: &mut [PrimRef], offset: usize, depth: usize) -> BuildNode {
    let (bounds, cbounds) = ref_bounds(refs);
    let n = refs.len();
    if n == 1 {
        return BuildNode::Leaf { bounds, first: offset, count: 1 };
    }
    // Past MAX_SAH_DEPTH the SAH could keep peeling one primitive at a time
    // off a pathological input; median splits bound the depth instead.
    let split = if depth < MAX_SAH_DEPTH { find_split(refs, &bounds, &cbounds) } else { None };
    let mid = match split {
        Some((axis, bin, _cost)) => {
            let (lo, extent) = (cbounds.min[axis], cbounds.extent()[axis]);
            let scale = BINS as f32 / extent;
            let m = partition(refs, |r| bin_index(r.centroid[axis], lo, scale) <= bin);
            if m == 0 || m == n {
                n / 2
            } else {
                m
            }
        }
        None if n <= MAX_LEAF => return BuildNode::Leaf { bounds, first: offset, count: n },
        None => {
            // Too many primitives for one leaf and no SAH split (all centroids
            // equal, or too deep): split at the median of the widest axis.
            let axis = cbounds.largest_axis();
            refs.select_nth_unstable_by(n / 2, |a, b| a.centroid[axis].total_cmp(&b.centroid[axis]));
            n / 2
        }
    };
    let (left, right) = refs.split_at_mut(mid);
    let (l, r) = if n > PARALLEL_THRESHOLD {
        rayon::join(|| build_recursive(left, offset, depth + 1), || build_recursive(right, offset + mid, depth + 1))
    } else {
        (build_recursive(left, offset, depth + 1), build_recursive(right, offset + mid, depth + 1))
    };
    BuildNode::Interior { bounds, children: Box::new((l, r)) }
}

#[inline]
fn bin_index(c: f32, lo: f32, scale: f32) -> usize {
    (((c - lo) * scale) as usize).min(BINS - 1)
}

/// Per axis, how many centroids fall in each bin and the union of their boxes.
#[derive(Clone, Copy)]
struct Bins {
    counts: [[usize; BINS]; 3],
    boxes: [[Aabb; BINS]; 3],
}

impl Bins {
    const EMPTY: Bins = Bins { counts: [[0; BINS]; 3], boxes: [[Aabb::EMPTY; BINS]; 3] };

    fn fill(refs: &[PrimRef], lo: Vec3, scale: [f32; 3]) -> Bins {
        let mut b = Bins::EMPTY;
        for r in refs {
            for axis in 0..3 {
                if scale[axis] > 0.0 {
                    let i = bin_index(r.centroid[axis], lo[axis], scale[axis]);
                    b.counts[axis][i] += 1;
                    b.boxes[axis][i] = b.boxes[axis][i].union(&r.bounds);
                }
            }
        }
        b
    }

    fn merge(mut self, o: Bins) -> Bins {
        for axis in 0..3 {
            for i in 0..BINS {
                self.counts[axis][i] += o.counts[axis][i];
                self.boxes[axis][i] = self.boxes[axis][i].union(&o.boxes[axis][i]);
            }
        }
        self
    }
}

/// Best binned-SAH split as `(axis, last bin of the left side, cost)`, or
/// `None` when making a leaf is cheaper (only allowed for small nodes).
fn find_split(refs: &[PrimRef], bounds: &Aabb, cbounds: &Aabb) -> Option<(usize, usize, f32)> {
    let n = refs.len();
    let parent_area = bounds.half_area().max(f32::MIN_POSITIVE);
    let extent = cbounds.extent();
    // Axes without extent get scale 0 and are skipped.
    let scale = [0, 1, 2].map(|a| if extent[a] > 0.0 { BINS as f32 / extent[a] } else { 0.0 });
    let lo = cbounds.min;
    let bins = if n > PARALLEL_BINNING {
        refs.par_chunks(BIN_CHUNK).map(|c| Bins::fill(c, lo, scale)).reduce(|| Bins::EMPTY, Bins::merge)
    } else {
        Bins::fill(refs, lo, scale)
    };
    let mut best: Option<(usize, usize, f32)> = None;
    for axis in 0..3 {
        if !(extent[axis] > 0.0) {
            continue;
        }
        let (counts, boxes) = (&bins.counts[axis], &bins.boxes[axis]);
        // Sweep from the right to get the area*count of every right side.
        let mut right_cost = [0.0f32; BINS];
        let mut acc = Aabb::EMPTY;
        let mut cnt = 0;
        for i in (1..BINS).rev() {
            acc = acc.union(&boxes[i]);
            cnt += counts[i];
            right_cost[i] = if cnt > 0 { acc.half_area() * blocks(cnt) } else { 0.0 };
        }
        let mut acc = Aabb::EMPTY;
        let mut cnt = 0;
        for i in 0..BINS - 1 {
            acc = acc.union(&boxes[i]);
            cnt += counts[i];
            if cnt == 0 || cnt == n {
                continue;
            }
            let cost = TRAVERSAL_COST + (acc.half_area() * blocks(cnt) + right_cost[i + 1]) / parent_area;
            if best.map_or(true, |b| cost < b.2) {
                best = Some((axis, i, cost));
            }
        }
    }
    match best {
        Some((_, _, cost)) if n <= MAX_LEAF && cost >= blocks(n) => None,
        other => other,
    }
}

/// In-place partition; returns the number of elements for which `pred` holds.
fn partition<T, F: Fn(&T) -> bool>(v: &mut [T], pred: F) -> usize {
    let mut i = 0;
    for j in 0..v.len() {
        if pred(&v[j]) {
            v.swap(i, j);
            i += 1;
        }
    }
    i
}
