//! The native backend: a binary BVH built with binned SAH, flattened in
//! depth-first order, traversed front to back with `t` clipping.
//!
//! Box tests follow Ize (2013): the far slab distance is enlarged by
//! `1 + 2*gamma(3)` so rounding can never cull a box the ray really enters;
//! together with the watertight triangle test this keeps closed meshes closed.

use super::prims::{self, closer, Prim};
use super::{Hit, Traversal};
use crate::geometry::{Aabb, RayTransform};
use crate::ray::Ray;
use crate::scene::Shape;
use glam::Vec3;

/// At most this many primitives per leaf; below it the SAH decides.
const MAX_LEAF: usize = 8;
const BINS: usize = 16;
/// Cost of one node visit relative to one primitive test, for the SAH.
const TRAVERSAL_COST: f32 = 1.0;
/// Subtrees with more primitives than this are built in parallel.
const PARALLEL_THRESHOLD: usize = 4096;
/// Depth bound: MAX_SAH_DEPTH SAH levels, then at most 32 median levels.
const MAX_SAH_DEPTH: usize = 64;
const STACK_SIZE: usize = MAX_SAH_DEPTH + 40;

/// A flattened node: 32 bytes. The left child of an interior node directly
/// follows it; `offset` is the right child (interior) or the first primitive
/// (leaf, `count > 0`).
#[derive(Clone, Copy, Debug)]
#[repr(C)]
struct Node {
    min: [f32; 3],
    offset: u32,
    max: [f32; 3],
    count: u16,
    axis: u16,
}

pub struct Bvh {
    nodes: Vec<Node>,
    prims: Vec<Prim>,
    depth: usize,
}

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
    Interior { bounds: Aabb, axis: usize, children: Box<(BuildNode, BuildNode)> },
}

impl BuildNode {
    pub(super) fn bounds(&self) -> &Aabb {
        match self {
            BuildNode::Leaf { bounds, .. } | BuildNode::Interior { bounds, .. } => bounds,
        }
    }
}

impl Bvh {
    pub fn build(shapes: &[Shape]) -> Self {
        Self::from_prims(prims::collect(shapes))
    }

    fn from_prims(prims: Vec<Prim>) -> Self {
        let Some((root, order)) = build_tree(&prims) else {
            let empty = Node { min: [f32::INFINITY; 3], offset: 0, max: [f32::NEG_INFINITY; 3], count: 0, axis: 0 };
            return Bvh { nodes: vec![empty], prims, depth: 0 };
        };
        let ordered: Vec<Prim> = order.iter().map(|&i| prims[i as usize]).collect();
        let mut nodes = Vec::with_capacity(2 * ordered.len() / 2 + 1);
        let depth = flatten(&root, &mut nodes, 1);
        Bvh { nodes, prims: ordered, depth }
    }

    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    pub fn depth(&self) -> usize {
        self.depth
    }

    /// SAH cost of the built tree (node visit 1, primitive test 1), the
    /// number the build minimises greedily.
    pub fn sah_cost(&self) -> f64 {
        let area = |n: &Node| {
            let e = [n.max[0] - n.min[0], n.max[1] - n.min[1], n.max[2] - n.min[2]];
            (e[0] * e[1] + e[1] * e[2] + e[2] * e[0]) as f64
        };
        let root = area(&self.nodes[0]).max(f64::MIN_POSITIVE);
        self.nodes
            .iter()
            .map(|n| if n.count > 0 { area(n) / root * n.count as f64 } else { area(n) / root * TRAVERSAL_COST as f64 })
            .sum()
    }

    #[inline]
    fn walk<F: FnMut(&Prim, &mut f32) -> bool>(&self, ray: &Ray, mut visit: F) {
        let slab = SlabRay::new(ray.origin, ray.dir);
        let mut tmax = ray.tmax;
        let mut stack = [0u32; STACK_SIZE];
        let mut sp = 0usize;
        let mut idx = 0usize;
        loop {
            let n = &self.nodes[idx];
            if box_hit(n, &slab, ray.tmin, tmax) {
                if n.count > 0 {
                    let first = n.offset as usize;
                    for p in &self.prims[first..first + n.count as usize] {
                        if visit(p, &mut tmax) {
                            return;
                        }
                    }
                } else {
                    let (near, far) = if slab.neg[n.axis as usize] { (n.offset as usize, idx + 1) } else { (idx + 1, n.offset as usize) };
                    stack[sp] = far as u32;
                    sp += 1;
                    idx = near;
                    continue;
                }
            }
            if sp == 0 {
                return;
            }
            sp -= 1;
            idx = stack[sp] as usize;
        }
    }
}

impl Traversal for Bvh {
    fn name(&self) -> &'static str {
        "native"
    }

    fn describe(&self) -> String {
        format!("native (binary BVH, binned SAH, {} nodes, SAH {:.2})", self.nodes.len(), self.sah_cost())
    }

    fn memory_bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<Node>() + self.prims.len() * std::mem::size_of::<Prim>()
    }

    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        let rt = RayTransform::new(ray.origin, ray.dir);
        let mut best: Option<Hit> = None;
        self.walk(ray, |p, tmax| {
            if let Some((t, u, v)) = p.intersect(&rt, ray.dir, ray.tmin, *tmax) {
                let h = p.hit(t, u, v);
                if closer(h, &best) {
                    *tmax = t;
                    best = Some(h);
                }
            }
            false
        });
        best
    }

    fn occluded(&self, ray: &Ray) -> bool {
        if !ray.is_valid() {
            return false;
        }
        let rt = RayTransform::new(ray.origin, ray.dir);
        let mut hit = false;
        self.walk(ray, |p, tmax| {
            hit = p.intersect(&rt, ray.dir, ray.tmin, *tmax).is_some();
            hit
        });
        hit
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

/// Per-ray constants of the slab test. `inv` is the true reciprocal, with
/// infinities for zero components; the near/far planes are chosen by the sign
/// bit (so -0 counts as negative). A zero component with the origin exactly on
/// a slab plane gives 0 * inf = NaN, which the comparisons in `box_hit` ignore:
/// the ray then runs inside the closed slab, which constrains nothing.
#[derive(Clone, Copy)]
struct SlabRay {
    o: Vec3,
    inv: Vec3,
    neg: [bool; 3],
}

impl SlabRay {
    #[inline]
    fn new(o: Vec3, d: Vec3) -> Self {
        SlabRay { o, inv: Vec3::ONE / d, neg: [d.x.is_sign_negative(), d.y.is_sign_negative(), d.z.is_sign_negative()] }
    }
}

#[inline(always)]
fn box_hit(n: &Node, r: &SlabRay, tmin: f32, tmax: f32) -> bool {
    let mut t0 = tmin;
    let mut t1 = tmax;
    for a in 0..3 {
        let (lo, hi) = if r.neg[a] { (n.max[a], n.min[a]) } else { (n.min[a], n.max[a]) };
        let near = (lo - r.o[a]) * r.inv[a];
        let far = (hi - r.o[a]) * r.inv[a] * ROBUST_SCALE;
        // Written so that a NaN never changes t0 or t1.
        if near > t0 {
            t0 = near;
        }
        if far < t1 {
            t1 = far;
        }
    }
    t0 <= t1
}

fn build_recursive(refs: &mut [PrimRef], offset: usize, depth: usize) -> BuildNode {
    let mut bounds = Aabb::EMPTY;
    let mut cbounds = Aabb::EMPTY;
    for r in refs.iter() {
        bounds = bounds.union(&r.bounds);
        cbounds.grow(r.centroid);
    }
    let n = refs.len();
    if n == 1 {
        return BuildNode::Leaf { bounds, first: offset, count: 1 };
    }
    // Past MAX_SAH_DEPTH the SAH could keep peeling one primitive at a time
    // off a pathological input; median splits bound the depth instead.
    let split = if depth < MAX_SAH_DEPTH { find_split(refs, &bounds, &cbounds) } else { None };
    let (axis, mid) = match split {
        Some((axis, bin, _cost)) => {
            let (lo, extent) = (cbounds.min[axis], cbounds.extent()[axis]);
            let scale = BINS as f32 / extent;
            let m = partition(refs, |r| bin_index(r.centroid[axis], lo, scale) <= bin);
            (axis, if m == 0 || m == n { n / 2 } else { m })
        }
        None if n <= MAX_LEAF => return BuildNode::Leaf { bounds, first: offset, count: n },
        None => {
            // Too many primitives for one leaf and no SAH split (all centroids
            // equal, or too deep): split at the median of the widest axis.
            let axis = cbounds.largest_axis();
            refs.select_nth_unstable_by(n / 2, |a, b| a.centroid[axis].total_cmp(&b.centroid[axis]));
            (axis, n / 2)
        }
    };
    let (left, right) = refs.split_at_mut(mid);
    let (l, r) = if n > PARALLEL_THRESHOLD {
        rayon::join(|| build_recursive(left, offset, depth + 1), || build_recursive(right, offset + mid, depth + 1))
    } else {
        (build_recursive(left, offset, depth + 1), build_recursive(right, offset + mid, depth + 1))
    };
    BuildNode::Interior { bounds, axis, children: Box::new((l, r)) }
}

#[inline]
fn bin_index(c: f32, lo: f32, scale: f32) -> usize {
    (((c - lo) * scale) as usize).min(BINS - 1)
}

/// Best binned-SAH split as `(axis, last bin of the left side, cost)`, or
/// `None` when making a leaf is cheaper (only allowed for small nodes).
fn find_split(refs: &[PrimRef], bounds: &Aabb, cbounds: &Aabb) -> Option<(usize, usize, f32)> {
    let n = refs.len();
    let parent_area = bounds.half_area().max(f32::MIN_POSITIVE);
    let mut best: Option<(usize, usize, f32)> = None;
    for axis in 0..3 {
        let extent = cbounds.extent()[axis];
        if !(extent > 0.0) {
            continue;
        }
        let lo = cbounds.min[axis];
        let scale = BINS as f32 / extent;
        let mut counts = [0usize; BINS];
        let mut boxes = [Aabb::EMPTY; BINS];
        for r in refs {
            let b = bin_index(r.centroid[axis], lo, scale);
            counts[b] += 1;
            boxes[b] = boxes[b].union(&r.bounds);
        }
        // Sweep from the right to get the area*count of every right side.
        let mut right_cost = [0.0f32; BINS];
        let mut acc = Aabb::EMPTY;
        let mut cnt = 0;
        for i in (1..BINS).rev() {
            acc = acc.union(&boxes[i]);
            cnt += counts[i];
            right_cost[i] = if cnt > 0 { acc.half_area() * cnt as f32 } else { 0.0 };
        }
        let mut acc = Aabb::EMPTY;
        let mut cnt = 0;
        for i in 0..BINS - 1 {
            acc = acc.union(&boxes[i]);
            cnt += counts[i];
            if cnt == 0 || cnt == n {
                continue;
            }
            let cost = TRAVERSAL_COST + (acc.half_area() * cnt as f32 + right_cost[i + 1]) / parent_area;
            if best.map_or(true, |b| cost < b.2) {
                best = Some((axis, i, cost));
            }
        }
    }
    match best {
        Some((_, _, cost)) if n <= MAX_LEAF && cost >= n as f32 => None,
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

/// Depth-first flattening; returns the depth of the subtree.
fn flatten(node: &BuildNode, out: &mut Vec<Node>, depth: usize) -> usize {
    let b = node.bounds();
    let idx = out.len();
    out.push(Node { min: b.min.to_array(), offset: 0, max: b.max.to_array(), count: 0, axis: 0 });
    match node {
        BuildNode::Leaf { first, count, .. } => {
            out[idx].offset = *first as u32;
            out[idx].count = *count as u16;
            depth
        }
        BuildNode::Interior { axis, children, .. } => {
            out[idx].axis = *axis as u16;
            let dl = flatten(&children.0, out, depth + 1);
            out[idx].offset = out.len() as u32;
            let dr = flatten(&children.1, out, depth + 1);
            assert!(dl.max(dr) < STACK_SIZE, "BVH deeper than the traversal stack");
            dl.max(dr)
        }
    }
}
