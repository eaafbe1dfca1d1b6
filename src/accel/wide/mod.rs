//! The native backend's fast layout: the binned-SAH binary tree collapsed
//! into a `W`-wide BVH (`W` = 4 or 8), whose child boxes are tested all at
//! once (AVX2 for 8 boxes where the CPU has it, chosen at run time; SSE2,
//! part of every x86-64 CPU, 4 boxes at a time otherwise), and leaves of
//! triangles packed 4 to a group and tested together.
//!
//! Traversal modes: single rays front to back (any-hit rays skip the
//! sorting, since any hit will do); coherent batches as 16-ray frusta
//! (`frustum`); incoherent batches over structures larger than the caches
//! with 4 rays interleaved (`interleave`).
//!
//! Every lane performs exactly the scalar operations of `intersect_triangle`
//! and of a scalar slab test, in the same order, so answers are
//! bit-identical to the scalar code (and so to the brute-force oracle)
//! whatever the instruction set. Other targets run the scalar lane loops,
//! which give the same answers.

mod frustum;
mod interleave;

use super::bvh::{build_tree, BuildNode, ROBUST_SCALE};
use super::prims::{self, closer, Prim};
use super::{Hit, Traversal};
use crate::geometry::{intersect_triangle, Aabb, RayTransform};
use crate::ray::Ray;
use crate::scene::Shape;
use glam::Vec3;
use rayon::prelude::*;
use std::ops::Div;

/// Triangles per group, and rays per packet: one SSE register.
const LANES: usize = 4;
/// The width the native backend uses. Measured with `pathtracer bench` (1
/// thread, Mrays/s, camera/shadow/random): cow 4-wide 31.4/9.2/8.6, 8-wide
/// 43.1/12.4/9.7; CBbunny 28.3/14.3/9.9 against 38.5/15.7/11.7; 1M-triangle
/// sphere 17.3/4.3/2.4 against 23.1/5.3/3.4. Without AVX2 (SSE2 box tests
/// in two halves, no frustum packets, no interleaving) 8-wide still matches
/// or beats 4-wide: 30.5/9.2/9.3, 34.5/15.9/11.1, 18.9/4.9/2.6.
pub const NATIVE_WIDTH: usize = 8;
const EMPTY: u32 = u32::MAX;
const LEAF_BIT: u32 = 1 << 31;
/// A leaf of triangles only, up to three groups, described by the child code
/// itself: `LEAF_BIT | INLINE_BIT | n_groups << 28 | first group`. Traversal
/// then goes from the node straight to the triangle data: the profile of
/// random rays on a 1M-triangle mesh spent 12 % of its samples waiting for
/// the separate leaf record.
const INLINE_BIT: u32 = 1 << 30;
const INLINE_GROUP_LIMIT: u32 = (1 << 28) - 1;
/// Traversal stack entries: the binary tree is at most 96 levels deep
/// (`bvh::MAX_SAH_DEPTH` + 32 median levels) and each wide level pushes at
/// most 7 children.
const STACK: usize = 7 * 96 + 8;

/// `W` children's boxes in SoA form, and what each child is: a node index,
/// a leaf (`LEAF_BIT | leaf record index`, or an inline leaf, see
/// `INLINE_BIT`) or `EMPTY`. 128 bytes (two cache lines) for `W` = 4, 256
/// for 8.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Node<const W: usize> {
    /// `bounds[0..3]` = min x, y, z; `bounds[3..6]` = max x, y, z.
    bounds: [[f32; W]; 6],
    child: [u32; W],
}

/// Four triangles, SoA: `v[k][axis][lane]` is vertex k's coordinate.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct TriGroup {
    v: [[[f32; LANES]; 3]; 3],
}

#[derive(Clone, Copy, Debug)]
struct Leaf {
    /// Triangle groups `groups[group..group+n_groups]`; lane i of group g
    /// is the triangle `ids[4*g + i]` (geometry, primitive), or padding.
    group: u32,
    n_groups: u32,
    /// Spheres: `spheres[sphere..sphere+n_spheres]`.
    sphere: u32,
    n_spheres: u32,
}

pub struct WideBvh<const W: usize> {
    nodes: Vec<Node<W>>,
    leaves: Vec<Leaf>,
    groups: Vec<TriGroup>,
    /// Per group lane: (geometry id, primitive id), geometry `EMPTY` for padding.
    ids: Vec<[u32; 2]>,
    spheres: Vec<Prim>,
    /// The root: a node, or a leaf when the scene is tiny.
    root: u32,
    /// Half area of the root's box, for the SAH cost (computed on demand,
    /// see `sah`: it is a report, not part of the build).
    root_area: f64,
    /// Box tests with AVX2 (8 boxes per instruction): `W` = 8 on a CPU that
    /// has it, unless `PATHTRACER_NATIVE_ISA=sse` asks for the SSE2 path.
    avx: bool,
    /// Trace incoherent batches several rays at a time (`interleave`): the
    /// structure is too large for the caches, so traversal waits on memory.
    interleave: bool,
}

/// The two halves of the SAH cost: the node part depends on the width (an
/// 8-wide tree has about half the nodes of a 4-wide one), the leaf part on how
/// well the build grouped the primitives.
#[derive(Clone, Copy, Debug, Default)]
struct SahCost {
    nodes: f64,
    leaves: f64,
}

/// The arrays of a tree being laid out.
struct Arrays<const W: usize> {
    nodes: Vec<Node<W>>,
    leaves: Vec<Leaf>,
    groups: Vec<TriGroup>,
    ids: Vec<[u32; 2]>,
    spheres: Vec<Prim>,
}

impl<const W: usize> Default for Arrays<W> {
    fn default() -> Self {
        Arrays { nodes: Vec::new(), leaves: Vec::new(), groups: Vec::new(), ids: Vec::new(), spheres: Vec::new() }
    }
}

/// Structures at least this large trace incoherent batches interleaved.
/// Random rays, 4 in flight against 1 (`pathtracer bench`, 2-core EPYC with
/// 32 MiB of L3): 1M triangles (68 MB) +23 %, 400k (26 MB) +17 %, 200k
/// (13 MB) -4 %, CBbunny (1.7 MB) -32 %: below this size the walkers' extra
/// state costs more than the overlapped misses save.
const INTERLEAVE_BYTES: usize = 16 << 20;

/// Subtrees with more primitives than this are laid out in parallel.
const PARALLEL_EMIT: usize = 1 << 15;

/// The children of `node`'s wide node: open the largest interior child until
/// `W` children (or only leaves) remain, keeping them in tree order.
fn collapse<const W: usize>(node: &BuildNode) -> ([&BuildNode; W], usize) {
    let mut kids: [&BuildNode; W] = [node; W];
    let mut n = 1;
    while n < W {
        let mut best: Option<(usize, f32)> = None;
        for (i, k) in kids[..n].iter().enumerate() {
            if let BuildNode::Interior { bounds, .. } = k {
                let a = bounds.half_area();
                if best.map_or(true, |(_, b)| a > b) {
                    best = Some((i, a));
                }
            }
        }
        let Some((i, _)) = best else { break };
        let BuildNode::Interior { children, .. } = kids[i] else { unreachable!() };
        kids.copy_within(i + 1..n, i + 2);
        kids[i] = &children.0;
        kids[i + 1] = &children.1;
        n += 1;
    }
    (kids, n)
}

impl<const W: usize> Arrays<W> {
    /// Empty arrays with room for a subtree of `prims` triangles: the
    /// block-counted SAH fills groups of 4 to about 3.8 triangles, and the
    /// 8-wide tree of the 1M mesh has a node per 13 triangles.
    fn with_room_for(prims: usize) -> Self {
        let groups = prims / 3 + 8;
        Arrays {
            nodes: Vec::with_capacity(prims / (W + 4) + 8),
            leaves: Vec::new(),
            groups: Vec::with_capacity(groups),
            ids: Vec::with_capacity(groups * LANES),
            spheres: Vec::new(),
        }
    }

    /// Flatten `node` depth-first; returns its child code. Leaves index
    /// `prims` through `order`.
    fn emit(&mut self, node: &BuildNode, prims: &[Prim], order: &[u32]) -> u32 {
        match node {
            BuildNode::Leaf { first, count, .. } => self.emit_leaf(prims, &order[*first..*first + *count]),
            BuildNode::Interior { .. } => {
                let (kids, n_kids) = collapse::<W>(node);
                let idx = self.push_node();
                for (lane, k) in kids[..n_kids].iter().enumerate() {
                    let code = self.emit(k, prims, order);
                    self.set_child(idx, lane, k.bounds(), code);
                }
                idx as u32
            }
        }
    }

    /// `emit`, with the subtrees of large nodes laid out in parallel into
    /// arrays of their own and appended in depth-first order, so the result
    /// is the serial layout exactly.
    fn emit_parallel(&mut self, node: &BuildNode, prims: &[Prim], order: &[u32]) -> u32 {
        if node.count() <= PARALLEL_EMIT || matches!(node, BuildNode::Leaf { .. }) {
            return self.emit(node, prims, order);
        }
        let (kids, n_kids) = collapse::<W>(node);
        let idx = self.push_node();
        let parts: Vec<(Arrays<W>, u32)> = kids[..n_kids]
            .par_iter()
            .map(|k| {
                let mut a = Arrays::with_room_for(k.count());
                let code = a.emit_parallel(k, prims, order);
                (a, code)
            })
            .collect();
        for (lane, (part, code)) in parts.into_iter().enumerate() {
            let code = self.append(part, code);
            self.set_child(idx, lane, kids[lane].bounds(), code);
        }
        idx as u32
    }

    fn push_node(&mut self) -> usize {
        self.nodes.push(Node { bounds: [[f32::INFINITY; W], [f32::INFINITY; W], [f32::INFINITY; W], [f32::NEG_INFINITY; W], [f32::NEG_INFINITY; W], [f32::NEG_INFINITY; W]], child: [EMPTY; W] });
        self.nodes.len() - 1
    }

    fn set_child(&mut self, idx: usize, lane: usize, b: &Aabb, code: u32) {
        let n = &mut self.nodes[idx];
        for a in 0..3 {
            n.bounds[a][lane] = b.min[a];
            n.bounds[3 + a][lane] = b.max[a];
        }
        n.child[lane] = code;
    }

    /// Append `part` (laid out on its own, root `code`), shifting its
    /// indices; returns the root's code here.
    fn append(&mut self, part: Arrays<W>, code: u32) -> u32 {
        let (nodes, groups, leaves, spheres) = (self.nodes.len() as u32, self.groups.len() as u32, self.leaves.len() as u32, self.spheres.len() as u32);
        let mut extra_leaves = Vec::new();
        let mut fix = |c: u32| -> u32 {
            if c == EMPTY {
                c
            } else if c & LEAF_BIT == 0 {
                c + nodes
            } else if c & INLINE_BIT == 0 {
                LEAF_BIT | ((c & !LEAF_BIT) + leaves)
            } else {
                let g = (c & INLINE_GROUP_LIMIT) + groups;
                if g < INLINE_GROUP_LIMIT {
                    (c & !INLINE_GROUP_LIMIT) | g
                } else {
                    // Beyond the inline field's range: a leaf record instead.
                    extra_leaves.push(Leaf { group: g, n_groups: (c >> 28) & 3, sphere: 0, n_spheres: 0 });
                    LEAF_BIT | (leaves + part.leaves.len() as u32 + extra_leaves.len() as u32 - 1)
                }
            }
        };
        let root = fix(code);
        self.nodes.extend(part.nodes.iter().map(|n| {
            let mut n = *n;
            for c in n.child.iter_mut() {
                *c = fix(*c);
            }
            n
        }));
        self.leaves.extend(part.leaves.iter().map(|l| Leaf { group: l.group + groups, sphere: l.sphere + spheres, ..*l }));
        self.leaves.extend(extra_leaves);
        assert!(self.leaves.len() < INLINE_BIT as usize, "too many leaf records");
        self.groups.extend(part.groups);
        self.ids.extend(part.ids);
        self.spheres.extend(part.spheres);
        root
    }

    fn emit_leaf(&mut self, prims: &[Prim], order: &[u32]) -> u32 {
        let group = self.groups.len() as u32;
        let sphere = self.spheres.len() as u32;
        let mut tris = order.iter().map(|&i| &prims[i as usize]).filter(|p| !p.is_sphere()).peekable();
        while tris.peek().is_some() {
            let mut g = TriGroup { v: [[[0.0; LANES]; 3]; 3] };
            let mut first: Option<&Prim> = None;
            for lane in 0..LANES {
                // Padding lanes repeat the group's first triangle; `ids` marks them empty.
                let (p, real) = match tris.next() {
                    Some(p) => (p, true),
                    None => (first.expect("a group has a triangle"), false),
                };
                first.get_or_insert(p);
                for k in 0..3 {
                    for a in 0..3 {
                        g.v[k][a][lane] = p.v[k][a];
                    }
                }
                self.ids.push(if real { [p.geom_id(), p.prim_id] } else { [EMPTY, EMPTY] });
            }
            self.groups.push(g);
        }
        self.spheres.extend(order.iter().map(|&i| prims[i as usize]).filter(|p| p.is_sphere()));
        let leaf = Leaf { group, n_groups: self.groups.len() as u32 - group, sphere, n_spheres: self.spheres.len() as u32 - sphere };
        if leaf.n_spheres == 0 && leaf.n_groups <= 3 && group < INLINE_GROUP_LIMIT {
            return LEAF_BIT | INLINE_BIT | leaf.n_groups << 28 | group;
        }
        self.leaves.push(leaf);
        assert!(self.leaves.len() < INLINE_BIT as usize, "too many leaf records");
        LEAF_BIT | (self.leaves.len() as u32 - 1)
    }
}

/// Whether this CPU runs the AVX2 box test (and the caller did not ask for SSE2).
fn avx_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::env::var("PATHTRACER_NATIVE_ISA").map_or(true, |v| v != "sse") && is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

impl<const W: usize> WideBvh<W> {
    pub fn build(shapes: &[Shape]) -> Self {
        assert!(W == 4 || W == 8, "WideBvh supports widths 4 and 8");
        let prims = prims::collect(shapes);
        let mut out = Arrays::<W>::default();
        let tree = build_tree(&prims);
        let (mut root, mut root_area) = (EMPTY, 0.0);
        if let Some((tree, order)) = &tree {
            out = Arrays::with_room_for(prims.len());
            root = out.emit_parallel(tree, &prims, order);
            root_area = tree.bounds().half_area() as f64;
        }
        let mut b = WideBvh { nodes: out.nodes, leaves: out.leaves, groups: out.groups, ids: out.ids, spheres: out.spheres, root, root_area, avx: W == 8 && avx_available(), interleave: false };
        b.interleave = b.avx && b.memory_bytes() >= INTERLEAVE_BYTES;
        b
    }

    /// SAH cost of the built tree, as Embree's BVH statistics (`verbose=2`)
    /// count it: expected node visits and expected 4-triangle group (or
    /// sphere) tests for a ray through the root's box, traversal and
    /// intersection costs both 1.
    fn sah(&self) -> SahCost {
        if self.root == EMPTY {
            return SahCost::default();
        }
        self.sah_cost(self.root, self.root_area)
    }

    /// Surface-area-weighted cost of the subtree `code` (whose box has half
    /// area `area`), relative to a root of half area `root`.
    fn sah_cost(&self, code: u32, root: f64) -> SahCost {
        let root = root.max(f64::MIN_POSITIVE);
        let mut cost = SahCost::default();
        let mut stack = vec![(code, root)];
        while let Some((c, area)) = stack.pop() {
            if c & LEAF_BIT != 0 {
                let l = self.leaf_of(c);
                cost.leaves += area / root * (l.n_groups + l.n_spheres) as f64;
                continue;
            }
            cost.nodes += area / root; // one visit tests all W child boxes
            let n = &self.nodes[c as usize];
            for lane in 0..W {
                if n.child[lane] != EMPTY {
                    let e = [0, 1, 2].map(|a| (n.bounds[3 + a][lane] - n.bounds[a][lane]).max(0.0) as f64);
                    stack.push((n.child[lane], e[0] * e[1] + e[1] * e[2] + e[2] * e[0]));
                }
            }
        }
        cost
    }

    /// The leaf a child code (with `LEAF_BIT`) stands for.
    #[inline(always)]
    fn leaf_of(&self, code: u32) -> Leaf {
        if code & INLINE_BIT != 0 {
            Leaf { group: code & INLINE_GROUP_LIMIT, n_groups: (code >> 28) & 3, sphere: 0, n_spheres: 0 }
        } else {
            self.leaves[(code & !LEAF_BIT) as usize]
        }
    }

    /// Intersect a leaf; `visit(hit)` returns true to stop.
    #[inline]
    fn leaf<F: FnMut(Hit) -> bool>(&self, leaf: &Leaf, ray: &Ray, rt: &RayTransform, shear: &Shear, tmax: f32, visit: &mut F) -> bool {
        for gi in leaf.group..leaf.group + leaf.n_groups {
            let g = &self.groups[gi as usize];
            let ids = &self.ids[gi as usize * LANES..gi as usize * LANES + LANES];
            let mut out = [LaneHit::default(); LANES];
            let mask = intersect_group(g, rt, shear, ray.tmin, tmax, &mut out);
            for lane in 0..LANES {
                if mask & (1 << lane) != 0 && ids[lane][0] != EMPTY {
                    let h = out[lane];
                    if visit(Hit { t: h.t, u: h.u, v: h.v, geom_id: ids[lane][0], prim_id: ids[lane][1] }) {
                        return true;
                    }
                }
            }
        }
        for p in &self.spheres[leaf.sphere as usize..(leaf.sphere + leaf.n_spheres) as usize] {
            if let Some((t, u, v)) = p.intersect(rt, ray.dir, ray.tmin, tmax) {
                if visit(p.hit(t, u, v)) {
                    return true;
                }
            }
        }
        false
    }

    /// Front-to-back traversal; `visit` may lower `tmax` and returns true to
    /// stop. `AVX` selects the AVX2 box test, which the caller must have
    /// checked the CPU has (`self.avx`) and compiled for (`#[target_feature]`).
    #[inline(always)]
    fn walk<const AVX: bool, const ANY: bool, F: FnMut(Hit, &mut f32) -> bool>(&self, ray: &Ray, mut visit: F) {
        if self.root == EMPTY {
            return;
        }
        let rt = RayTransform::new(ray.origin, ray.dir);
        let shear = Shear::new(&rt);
        let slab = Slab::new(ray);
        let mut tmax = ray.tmax;
        // Stack of (child code, entry distance), not initialised: only
        // entries below `sp` are read.
        let mut stack = [std::mem::MaybeUninit::<(u32, f32)>::uninit(); STACK];
        let mut sp = 0;
        let mut cur = self.root;
        loop {
            if cur & LEAF_BIT != 0 {
                let leaf = self.leaf_of(cur);
                let mut stop = false;
                self.leaf(&leaf, ray, &rt, &shear, tmax, &mut |h| {
                    stop = visit(h, &mut tmax);
                    stop
                });
                if stop {
                    return;
                }
            } else {
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
                    // Push every entered child, sort them far to near, and
                    // continue with the nearest.
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
                    if !ANY { sort_far_first(pushed, |e| e.1); }
                    sp -= 1;
                    cur = pushed[pushed.len() - 1].0;
                    continue;
                }
            }
            // Pop, skipping subtrees that start beyond the current closest hit.
            loop {
                if sp == 0 {
                    return;
                }
                sp -= 1;
                // SAFETY: every entry below the old `sp` was written.
                let (code, dist) = unsafe { stack[sp].assume_init() };
                if dist <= tmax {
                    cur = code;
                    break;
                }
            }
        }
    }

    /// Start loading child `code`'s node (all its cache lines) or its first
    /// triangle group before the traversal needs it.
    #[inline(always)]
    fn prefetch(&self, code: u32) {
        #[cfg(target_arch = "x86_64")]
        unsafe {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let (ptr, bytes) = if code & LEAF_BIT == 0 {
                (self.nodes.as_ptr().add(code as usize) as *const i8, std::mem::size_of::<Node<W>>())
            } else if code & INLINE_BIT != 0 {
                (self.groups.as_ptr().add((code & INLINE_GROUP_LIMIT) as usize) as *const i8, ((code >> 28) & 3) as usize * std::mem::size_of::<TriGroup>())
            } else {
                return;
            };
            let mut off = 0;
            while off < bytes {
                _mm_prefetch::<_MM_HINT_T0>(ptr.add(off));
                off += 64;
            }
        }
    }

    #[inline(always)]
    fn closest<const AVX: bool>(&self, ray: &Ray) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        self.walk::<AVX, false, _>(ray, |h, tmax| {
            if closer(h, &best) {
                *tmax = h.t;
                best = Some(h);
            }
            false
        });
        best
    }

    #[inline(always)]
    fn any<const AVX: bool>(&self, ray: &Ray) -> bool {
        let mut hit = false;
        self.walk::<AVX, true, _>(ray, |_, _| {
            hit = true;
            true
        });
        hit
    }

    #[inline(always)]
    fn closest_all<const AVX: bool>(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        for (r, h) in rays.iter().zip(hits.iter_mut()) {
            *h = if r.is_valid() { self.closest::<AVX>(r) } else { None };
        }
    }

    #[inline(always)]
    fn any_all<const AVX: bool>(&self, rays: &[Ray], out: &mut [bool]) {
        for (r, o) in rays.iter().zip(out.iter_mut()) {
            *o = r.is_valid() && self.any::<AVX>(r);
        }
    }

    // The same traversal compiled for AVX2: the box test's intrinsics inline
    // only into functions built with the feature. Callers check `self.avx`.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn closest_all_avx(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        self.closest_all::<true>(rays, hits)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn any_all_avx(&self, rays: &[Ray], out: &mut [bool]) {
        self.any_all::<true>(rays, out)
    }
}

impl<const W: usize> Traversal for WideBvh<W> {
    fn name(&self) -> &'static str {
        "native"
    }

    fn sah_cost(&self) -> Option<(f64, f64)> {
        let sah = self.sah();
        Some((sah.nodes, sah.leaves))
    }

    fn describe(&self) -> String {
        let sah = self.sah();
        format!(
            "native ({W}-wide BVH, binned SAH, {}, {} nodes, {} triangle groups of 4, {} leaf records, SAH cost {:.2} = nodes {:.2} + leaves {:.2})",
            if self.avx { "AVX2" } else { "SSE2" },
            self.nodes.len(),
            self.groups.len(),
            self.leaves.len(),
            sah.nodes + sah.leaves,
            sah.nodes,
            sah.leaves
        )
    }

    fn memory_bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<Node<W>>()
            + self.leaves.len() * std::mem::size_of::<Leaf>()
            + self.groups.len() * std::mem::size_of::<TriGroup>()
            + self.ids.len() * 8
            + self.spheres.len() * std::mem::size_of::<Prim>()
    }

    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        let mut hit = [None];
        #[cfg(target_arch = "x86_64")]
        if self.avx {
            // SAFETY: `avx` is only set when the CPU has AVX2.
            unsafe { self.closest_all_avx(std::slice::from_ref(ray), &mut hit) };
            return hit[0];
        }
        self.closest_all::<false>(std::slice::from_ref(ray), &mut hit);
        hit[0]
    }

    fn occluded(&self, ray: &Ray) -> bool {
        let mut out = [false];
        self.occluded_batch(std::slice::from_ref(ray), &mut out);
        out[0]
    }

    fn intersect_batch(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), hits.len());
        #[cfg(target_arch = "x86_64")]
        if self.avx {
            // SAFETY: `avx` is only set when the CPU has AVX2.
            return unsafe {
                if self.interleave {
                    self.closest_interleaved_avx(rays, hits)
                } else {
                    self.closest_all_avx(rays, hits)
                }
            };
        }
        self.closest_all::<false>(rays, hits)
    }

    fn occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len());
        #[cfg(target_arch = "x86_64")]
        if self.avx {
            // SAFETY: as above.
            return unsafe { self.any_all_avx(rays, out) };
        }
        self.any_all::<false>(rays, out)
    }

    fn intersect_coherent(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), hits.len());
        #[cfg(target_arch = "x86_64")]
        if self.avx && W == 8 {
            // SAFETY: `avx` is only set when the CPU has AVX2.
            return unsafe { self.closest_coherent_avx(rays, hits) };
        }
        self.closest_all::<false>(rays, hits)
    }

    fn occluded_coherent(&self, rays: &[Ray], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len());
        #[cfg(target_arch = "x86_64")]
        if self.avx && W == 8 {
            // SAFETY: as above.
            return unsafe { self.any_coherent_avx(rays, out) };
        }
        self.any_all::<false>(rays, out)
    }
}

/// Insertion sort of at most 8 entered children by entry distance, farthest
/// first: pushed in that order, the nearest is visited next.
#[inline(always)]
fn sort_far_first<T: Copy>(h: &mut [T], dist: impl Fn(&T) -> f32) {
    for i in 1..h.len() {
        let mut j = i;
        while j > 0 && dist(&h[j - 1]) < dist(&h[j]) {
            h.swap(j - 1, j);
            j -= 1;
        }
    }
}

/// Per-ray slab-test constants:
/// true reciprocals, near/far planes chosen by the direction's sign bit, and
/// comparisons written so a NaN (origin on a plane, zero direction) is ignored.
struct Slab {
    o: [f32; 3],
    inv: [f32; 3],
    /// Index into `Node::bounds` of the near plane per axis (min or max).
    near_plane: [usize; 3],
}

impl Slab {
    fn new(ray: &Ray) -> Self {
        let d = ray.dir;
        let neg = [d.x.is_sign_negative(), d.y.is_sign_negative(), d.z.is_sign_negative()];
        Slab {
            o: ray.origin.to_array(),
            // One SIMD division; each lane is the exact scalar quotient.
            inv: glam::Vec3A::ONE.div(glam::Vec3A::from(d)).to_array(),
            near_plane: [if neg[0] { 3 } else { 0 }, if neg[1] { 4 } else { 1 }, if neg[2] { 5 } else { 2 }],
        }
    }

    /// Bit i set when child i's box is entered in [tmin, tmax]; `near` gets
    /// entry distances. Every path does the same per-lane operations: the
    /// far distance enlarged by `ROBUST_SCALE`, and `max(tn, t0)` /
    /// `min(tf, t1)` returning their second operand when the first is NaN.
    #[inline(always)]
    fn test<const W: usize, const AVX: bool>(&self, n: &Node<W>, tmin: f32, tmax: f32, near: &mut [f32; W]) -> u32 {
        #[cfg(target_arch = "x86_64")]
        unsafe {
            use std::arch::x86_64::*;
            let rows = n.bounds.as_ptr() as *const f32;
            if AVX && W == 8 {
                // SAFETY: the caller runs with AVX2 enabled; rows are 32 bytes
                // and the node is 64-byte aligned.
                let mut t0 = _mm256_set1_ps(tmin);
                let mut t1 = _mm256_set1_ps(tmax);
                let scale = _mm256_set1_ps(ROBUST_SCALE);
                for a in 0..3 {
                    let o = _mm256_set1_ps(self.o[a]);
                    let inv = _mm256_set1_ps(self.inv[a]);
                    let lo = _mm256_load_ps(rows.add(self.near_plane[a] * W));
                    let hi = _mm256_load_ps(rows.add((self.near_plane[a] + 3) % 6 * W));
                    let tn = _mm256_mul_ps(_mm256_sub_ps(lo, o), inv);
                    let tf = _mm256_mul_ps(_mm256_mul_ps(_mm256_sub_ps(hi, o), inv), scale);
                    t0 = _mm256_max_ps(tn, t0);
                    t1 = _mm256_min_ps(tf, t1);
                }
                _mm256_storeu_ps(near.as_mut_ptr(), t0);
                return _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1)) as u32;
            }
            let mut mask = 0;
            for c in (0..W).step_by(4) {
                let mut t0 = _mm_set1_ps(tmin);
                let mut t1 = _mm_set1_ps(tmax);
                let scale = _mm_set1_ps(ROBUST_SCALE);
                for a in 0..3 {
                    let o = _mm_set1_ps(self.o[a]);
                    let inv = _mm_set1_ps(self.inv[a]);
                    let lo = _mm_load_ps(rows.add(self.near_plane[a] * W + c));
                    let hi = _mm_load_ps(rows.add((self.near_plane[a] + 3) % 6 * W + c));
                    let tn = _mm_mul_ps(_mm_sub_ps(lo, o), inv);
                    let tf = _mm_mul_ps(_mm_mul_ps(_mm_sub_ps(hi, o), inv), scale);
                    // maxps(a, b) = a > b ? a : b, so a NaN in tn leaves t0 as it is.
                    t0 = _mm_max_ps(tn, t0);
                    t1 = _mm_min_ps(tf, t1);
                }
                _mm_storeu_ps(near.as_mut_ptr().add(c), t0);
                mask |= (_mm_movemask_ps(_mm_cmple_ps(t0, t1)) as u32) << c;
            }
            mask
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            self.test_scalar(n, tmin, tmax, near)
        }
    }

    /// `test` one lane at a time, for targets without x86 SIMD (and the
    /// unit tests, which check that every path gives the same bits).
    #[cfg_attr(target_arch = "x86_64", allow(dead_code))]
    fn test_scalar<const W: usize>(&self, n: &Node<W>, tmin: f32, tmax: f32, near: &mut [f32; W]) -> u32 {
        let mut mask = 0;
        for lane in 0..W {
            let (mut t0, mut t1) = (tmin, tmax);
            for a in 0..3 {
                let lo = n.bounds[self.near_plane[a]][lane];
                let hi = n.bounds[(self.near_plane[a] + 3) % 6][lane];
                let tn = (lo - self.o[a]) * self.inv[a];
                let tf = (hi - self.o[a]) * self.inv[a] * ROBUST_SCALE;
                // As maxps/minps: a NaN distance leaves the bound as it is.
                if tn > t0 {
                    t0 = tn;
                }
                if tf < t1 {
                    t1 = tf;
                }
            }
            near[lane] = t0;
            if t0 <= t1 {
                mask |= 1 << lane;
            }
        }
        mask
    }
}

/// The watertight test's per-ray shear, as axis indices and broadcastable constants.
struct Shear {
    k: [usize; 3],
    s: [f32; 3],
    o: [f32; 3],
}

impl Shear {
    fn new(rt: &RayTransform) -> Self {
        let (k, s) = rt.shear();
        Shear { k, s, o: rt.origin.to_array() }
    }
}

#[derive(Clone, Copy, Default)]
struct LaneHit {
    t: f32,
    u: f32,
    v: f32,
}

/// The watertight test on four triangles at once; bit i set when lane i hits
/// in (tmin, tmax]. Lane results equal `intersect_triangle` bit for bit; a
/// lane with an edge function exactly 0 (which needs the f64 path) is
/// handed to `intersect_triangle` itself.
#[inline(always)]
fn intersect_group(g: &TriGroup, rt: &RayTransform, sh: &Shear, tmin: f32, tmax: f32, out: &mut [LaneHit; LANES]) -> u32 {
    #[cfg(target_arch = "x86_64")]
    unsafe {
        use std::arch::x86_64::*;
        let [kx, ky, kz] = sh.k;
        let ld = |k: usize, a: usize| _mm_load_ps(g.v[k][a].as_ptr());
        let (ox, oy, oz) = (_mm_set1_ps(sh.o[kx]), _mm_set1_ps(sh.o[ky]), _mm_set1_ps(sh.o[kz]));
        let (sx, sy, sz) = (_mm_set1_ps(sh.s[0]), _mm_set1_ps(sh.s[1]), _mm_set1_ps(sh.s[2]));
        // a = p - origin, per needed axis, then the shear.
        let axk = _mm_sub_ps(ld(0, kx), ox);
        let ayk = _mm_sub_ps(ld(0, ky), oy);
        let azk = _mm_sub_ps(ld(0, kz), oz);
        let bxk = _mm_sub_ps(ld(1, kx), ox);
        let byk = _mm_sub_ps(ld(1, ky), oy);
        let bzk = _mm_sub_ps(ld(1, kz), oz);
        let cxk = _mm_sub_ps(ld(2, kx), ox);
        let cyk = _mm_sub_ps(ld(2, ky), oy);
        let czk = _mm_sub_ps(ld(2, kz), oz);
        let ax = _mm_sub_ps(axk, _mm_mul_ps(sx, azk));
        let ay = _mm_sub_ps(ayk, _mm_mul_ps(sy, azk));
        let bx = _mm_sub_ps(bxk, _mm_mul_ps(sx, bzk));
        let by = _mm_sub_ps(byk, _mm_mul_ps(sy, bzk));
        let cx = _mm_sub_ps(cxk, _mm_mul_ps(sx, czk));
        let cy = _mm_sub_ps(cyk, _mm_mul_ps(sy, czk));
        // edge(p, q) = qx*py - qy*px, as in the scalar code.
        let e0 = _mm_sub_ps(_mm_mul_ps(cx, by), _mm_mul_ps(cy, bx));
        let e1 = _mm_sub_ps(_mm_mul_ps(ax, cy), _mm_mul_ps(ay, cx));
        let e2 = _mm_sub_ps(_mm_mul_ps(bx, ay), _mm_mul_ps(by, ax));
        let zero = _mm_setzero_ps();
        let any_zero = _mm_movemask_ps(_mm_or_ps(_mm_or_ps(_mm_cmpeq_ps(e0, zero), _mm_cmpeq_ps(e1, zero)), _mm_cmpeq_ps(e2, zero))) as u32;
        let neg = _mm_or_ps(_mm_or_ps(_mm_cmplt_ps(e0, zero), _mm_cmplt_ps(e1, zero)), _mm_cmplt_ps(e2, zero));
        let pos = _mm_or_ps(_mm_or_ps(_mm_cmpgt_ps(e0, zero), _mm_cmpgt_ps(e1, zero)), _mm_cmpgt_ps(e2, zero));
        let det = _mm_add_ps(_mm_add_ps(e0, e1), e2);
        // det finite: |det| < inf (false for NaN).
        let abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7fff_ffff));
        let finite = _mm_cmplt_ps(_mm_and_ps(det, abs_mask), _mm_set1_ps(f32::INFINITY));
        let mut ok = _mm_andnot_ps(_mm_and_ps(neg, pos), _mm_and_ps(finite, _mm_cmpneq_ps(det, zero)));
        let az = _mm_mul_ps(sz, azk);
        let bz = _mm_mul_ps(sz, bzk);
        let cz = _mm_mul_ps(sz, czk);
        let ts = _mm_add_ps(_mm_add_ps(_mm_mul_ps(e0, az), _mm_mul_ps(e1, bz)), _mm_mul_ps(e2, cz));
        // Behind the origin: det and t_scaled of opposite signs (or t_scaled 0).
        let behind = _mm_or_ps(_mm_and_ps(_mm_cmpgt_ps(det, zero), _mm_cmple_ps(ts, zero)), _mm_and_ps(_mm_cmplt_ps(det, zero), _mm_cmpge_ps(ts, zero)));
        ok = _mm_andnot_ps(behind, ok);
        let mut mask = _mm_movemask_ps(ok) as u32 & !any_zero;
        if mask != 0 {
            let inv = _mm_div_ps(_mm_set1_ps(1.0), det);
            let t = _mm_mul_ps(ts, inv);
            let in_range = _mm_and_ps(_mm_cmpgt_ps(t, _mm_set1_ps(tmin)), _mm_cmple_ps(t, _mm_set1_ps(tmax)));
            mask &= _mm_movemask_ps(in_range) as u32;
            let (mut tt, mut uu, mut vv) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
            _mm_storeu_ps(tt.as_mut_ptr(), t);
            _mm_storeu_ps(uu.as_mut_ptr(), _mm_mul_ps(e1, inv));
            _mm_storeu_ps(vv.as_mut_ptr(), _mm_mul_ps(e2, inv));
            for lane in 0..LANES {
                out[lane] = LaneHit { t: tt[lane], u: uu[lane], v: vv[lane] };
            }
        }
        // Lanes with an exact zero edge function: the scalar test decides (in f64).
        let mut z = any_zero;
        while z != 0 {
            let lane = z.trailing_zeros() as usize;
            z &= z - 1;
            if let Some((t, u, v)) = scalar_lane(g, lane, rt, tmin, tmax) {
                out[lane] = LaneHit { t, u, v };
                mask |= 1 << lane;
            }
        }
        mask
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = sh;
        intersect_group_scalar(g, rt, tmin, tmax, out)
    }
}

/// `intersect_group` one lane at a time with `intersect_triangle` itself,
/// for targets without x86 SIMD (and the unit tests).
#[cfg_attr(target_arch = "x86_64", allow(dead_code))]
fn intersect_group_scalar(g: &TriGroup, rt: &RayTransform, tmin: f32, tmax: f32, out: &mut [LaneHit; LANES]) -> u32 {
    let mut mask = 0;
    for lane in 0..LANES {
        if let Some((t, u, v)) = scalar_lane(g, lane, rt, tmin, tmax) {
            out[lane] = LaneHit { t, u, v };
            mask |= 1 << lane;
        }
    }
    mask
}

#[inline]
fn scalar_lane(g: &TriGroup, lane: usize, rt: &RayTransform, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
    let p = |k: usize| Vec3::new(g.v[k][0][lane], g.v[k][1][lane], g.v[k][2][lane]);
    intersect_triangle(rt, p(0), p(1), p(2), tmin, tmax)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::brute::BruteForce;
    use crate::bench::{camera_rays, procedural_scene, random_rays};
    use crate::camera::Camera;
    use crate::rng::Rng;

    /// A small mesh with a sphere inside it, so leaves hold both kinds.
    fn shapes() -> Vec<Shape> {
        let mut shapes = procedural_scene(3000).shapes;
        shapes.push(Shape::Sphere { center: Vec3::new(0.1, 0.0, 0.2), radius: 0.3 });
        shapes
    }

    /// Packets of 16 nearly parallel rays from nearly the same point, so
    /// most pass `Frustum::new`; every fourth packet spreads wider.
    fn tight_packets(n: usize, seed: u64) -> Vec<Ray> {
        let mut rng = Rng::new(seed, 1);
        let mut rays = Vec::new();
        for p in 0..n {
            let spread = if p % 4 == 3 { 0.2 } else { 1e-3 };
            let o = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 4.0 - 2.0;
            let d = (Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0 - 1.0).normalize_or(Vec3::X);
            for _ in 0..frustum::PACKET {
                let jo = (Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) - 0.5) * spread;
                let jd = (Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) - 0.5) * spread;
                rays.push(Ray::new(o + jo, d + jd));
            }
        }
        rays
    }

    fn rays(shapes: &[Shape]) -> Vec<Ray> {
        let mut scene = procedural_scene(3000);
        scene.shapes = shapes.to_vec();
        let mut rays = camera_rays(&Camera::from_scene(&scene), 64, 48);
        rays.extend(random_rays(&scene, 3000, 5));
        rays.extend(tight_packets(200, 9));
        // Short rays that end inside boxes, and rays that start inside them.
        for (i, r) in rays.iter_mut().enumerate().skip(7).step_by(13) {
            r.tmax = 0.5 + (i % 5) as f32;
        }
        // Invalid rays among valid ones, in packets and batches.
        rays[10].dir = Vec3::ZERO;
        rays[3100].origin.x = f32::NAN;
        let last = rays.len() - 1;
        rays[last].dir.y = f32::INFINITY;
        rays
    }

    #[test]
    fn every_width_and_instruction_set_matches_brute_force() {
        let shapes = shapes();
        let rays = rays(&shapes);
        let brute = BruteForce::new(&shapes);
        let want: Vec<Option<Hit>> = rays.iter().map(|r| brute.intersect(r)).collect();
        let want_occ: Vec<bool> = rays.iter().map(|r| brute.occluded(r)).collect();
        let mut sse8 = WideBvh::<8>::build(&shapes);
        let avx8_on = sse8.avx;
        sse8.avx = false;
        // Interleaved batches are only switched on for large structures;
        // force them here.
        let mut interleaved = WideBvh::<8>::build(&shapes);
        interleaved.interleave = interleaved.avx;
        let candidates: Vec<(&str, Box<dyn Traversal>)> = vec![
            ("4-wide", Box::new(WideBvh::<4>::build(&shapes))),
            ("8-wide SSE2", Box::new(sse8)),
            ("8-wide default", Box::new(WideBvh::<8>::build(&shapes))),
            ("8-wide interleaved", Box::new(interleaved)),
        ];
        if !avx8_on {
            eprintln!("note: this CPU has no AVX2; the AVX2 paths were not exercised");
        }
        for (name, b) in &candidates {
            let mut hits = vec![None; rays.len()];
            let mut occ = vec![false; rays.len()];
            for (what, f) in [("batch", false), ("coherent", true)] {
                if f {
                    b.intersect_coherent(&rays, &mut hits);
                    b.occluded_coherent(&rays, &mut occ);
                } else {
                    b.intersect_batch(&rays, &mut hits);
                    b.occluded_batch(&rays, &mut occ);
                }
                let bad = hits.iter().zip(&want).filter(|(a, b)| a != b).count();
                let bad_occ = occ.iter().zip(&want_occ).filter(|(a, b)| a != b).count();
                assert_eq!((bad, bad_occ), (0, 0), "{name} {what}: closest-hit and occlusion mismatches against brute force");
            }
            assert_eq!(b.intersect(&rays[100]), want[100]);
        }
    }

    /// The SIMD kernels (SSE2 and AVX2 box tests, the SSE2 triangle group
    /// test) give exactly the bits of the scalar code the other targets run.
    #[test]
    fn simd_kernels_equal_the_scalar_fallback() {
        let shapes = shapes();
        let bvh = WideBvh::<8>::build(&shapes);
        let mut rays = rays(&shapes);
        // Rays aimed at child-box corners, where entry and exit distances
        // meet and the far plane's rounding allowance decides.
        for node in bvh.nodes.iter().take(300) {
            for lane in 0..8 {
                if node.child[lane] == EMPTY {
                    continue;
                }
                let lo = Vec3::new(node.bounds[0][lane], node.bounds[1][lane], node.bounds[2][lane]);
                let hi = Vec3::new(node.bounds[3][lane], node.bounds[4][lane], node.bounds[5][lane]);
                let o = hi + (hi - lo) * Vec3::new(1.3, 0.7, 2.1) + Vec3::splat(0.01);
                rays.push(Ray::new(o, Vec3::new(hi.x, lo.y, hi.z) - o));
                rays.push(Ray::new(o, hi - o));
            }
        }
        let (mut boxes, mut groups) = (0, 0);
        for (k, r) in rays.iter().enumerate().filter(|(_, r)| r.is_valid()) {
            let slab = Slab::new(r);
            let rt = RayTransform::new(r.origin, r.dir);
            let shear = Shear::new(&rt);
            let tmax = if k % 3 == 0 { r.tmax } else { 2.0 };
            for node in bvh.nodes.iter().skip(k % 7).step_by(7) {
                let mut want = [0.0f32; 8];
                let m = slab.test_scalar(node, r.tmin, tmax, &mut want);
                let mut got = [0.0f32; 8];
                assert_eq!(slab.test::<8, false>(node, r.tmin, tmax, &mut got), m);
                assert_eq!(got.map(f32::to_bits), want.map(f32::to_bits), "SSE2 entry distances");
                #[cfg(target_arch = "x86_64")]
                if is_x86_feature_detected!("avx2") {
                    // SAFETY: checked just above.
                    let (am, an) = unsafe { avx_box_test(&slab, node, r.tmin, tmax) };
                    assert_eq!(am, m);
                    assert_eq!(an.map(f32::to_bits), want.map(f32::to_bits), "AVX2 entry distances");
                }
                boxes += 1;
            }
            for g in bvh.groups.iter() {
                let (mut a, mut b) = ([LaneHit::default(); LANES], [LaneHit::default(); LANES]);
                let ma = intersect_group(g, &rt, &shear, r.tmin, tmax, &mut a);
                let mb = intersect_group_scalar(g, &rt, r.tmin, tmax, &mut b);
                assert_eq!(ma, mb);
                for lane in 0..LANES {
                    if ma & (1 << lane) != 0 {
                        assert_eq!([a[lane].t, a[lane].u, a[lane].v].map(f32::to_bits), [b[lane].t, b[lane].u, b[lane].v].map(f32::to_bits));
                        groups += 1;
                    }
                }
            }
        }
        assert!(boxes > 100_000 && groups > 1_000, "too few cases: {boxes} box tests, {groups} group hits");
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn avx_box_test(slab: &Slab, node: &Node<8>, tmin: f32, tmax: f32) -> (u32, [f32; 8]) {
        let mut near = [0.0f32; 8];
        let m = slab.test::<8, true>(node, tmin, tmax, &mut near);
        (m, near)
    }

    #[test]
    fn frustum_accepts_coherent_packets() {
        let rays = tight_packets(100, 4);
        let accepted = rays.chunks(frustum::PACKET).filter(|p| frustum::Frustum::new(p, false).is_some()).count();
        // The tight three quarters all share signs unless a direction
        // component is within 1e-3 of zero.
        assert!(accepted >= 70, "only {accepted} of 100 packets traced as frusta");
        let mut mixed = rays[..16].to_vec();
        mixed[3].dir.x = -mixed[0].dir.x;
        assert!(frustum::Frustum::new(&mixed, false).is_none(), "mixed direction signs must fall back to single rays");
        mixed[3] = Ray::new(mixed[0].origin, Vec3::new(0.0, 1.0, 1.0));
        assert!(frustum::Frustum::new(&mixed, false).is_none(), "a zero direction component must fall back");
        // A fanned-out packet (shadow rays near their light) is traced as a
        // frustum only when the caller does not limit the spread.
        let o = Vec3::new(0.5, 0.5, 0.5);
        let fan: Vec<Ray> = (0..16).map(|i| Ray::new(o, Vec3::new(1.0, 0.3 + 0.05 * i as f32, 0.5))).collect();
        assert!(frustum::Frustum::new(&fan, false).is_some());
        assert!(frustum::Frustum::new(&fan, true).is_none(), "a packet fanned out over 0.75 rad must be traced ray by ray");
        assert!(frustum::Frustum::new(&fan[..2], true).is_some(), "two rays 0.05 apart stay a frustum");
    }
}
