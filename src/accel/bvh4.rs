//! The native backend's fast layout: the binned-SAH binary tree collapsed
//! into a 4-wide BVH, traversed with SSE (4 boxes per test) and leaves of
//! triangles packed 4 to a group and tested together.
//!
//! Every lane performs exactly the scalar operations of `intersect_triangle`
//! and of a scalar slab test, in the same order, so answers are
//! bit-identical to the scalar code (and so to the brute-force oracle). The
//! SIMD code is SSE2, part of every x86-64 CPU; other targets run the scalar
//! lane loop, which gives the same answers.

use super::bvh::{build_tree, BuildNode, ROBUST_SCALE};
use super::prims::{self, closer, Prim};
use super::{Hit, Traversal};
use crate::geometry::{intersect_triangle, Aabb, RayTransform};
use crate::ray::Ray;
use crate::scene::Shape;
use glam::Vec3;

const WIDTH: usize = 4;
const EMPTY: u32 = u32::MAX;
const LEAF_BIT: u32 = 1 << 31;
/// A leaf of triangles only, up to three groups, described by the child code
/// itself: `LEAF_BIT | INLINE_BIT | n_groups << 28 | first group`. Traversal
/// then goes from the node straight to the triangle data: the profile of
/// random rays on a 1M-triangle mesh spent 12 % of its samples waiting for
/// the separate leaf record.
const INLINE_BIT: u32 = 1 << 30;
const INLINE_GROUP_LIMIT: u32 = (1 << 28) - 1;
const STACK: usize = 256;

/// Four children's boxes in SoA form, and what each child is: a node index,
/// a leaf (`LEAF_BIT | leaf record index`, or an inline leaf, see
/// `INLINE_BIT`) or `EMPTY`. 128 bytes, two cache lines.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Node4 {
    /// `bounds[0..3]` = min x, y, z; `bounds[3..6]` = max x, y, z.
    bounds: [[f32; WIDTH]; 6],
    child: [u32; WIDTH],
    _pad: [u32; 4],
}

/// Four triangles, SoA: `v[k][axis][lane]` is vertex k's coordinate.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct TriGroup {
    v: [[[f32; WIDTH]; 3]; 3],
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

pub struct Bvh4 {
    nodes: Vec<Node4>,
    leaves: Vec<Leaf>,
    groups: Vec<TriGroup>,
    /// Per group lane: (geometry id, primitive id), geometry `EMPTY` for padding.
    ids: Vec<[u32; 2]>,
    spheres: Vec<Prim>,
    /// The root: a node, or a leaf when the scene is tiny.
    root: u32,
    /// SAH cost of the built tree, as Embree's BVH statistics (`verbose=2`)
    /// count it: expected node visits and expected 4-triangle group (or
    /// sphere) tests for a ray through the root's box, traversal and
    /// intersection costs both 1.
    sah: SahCost,
}

/// The two halves of the SAH cost: the node part depends on the width (an
/// 8-wide tree has about half the nodes of a 4-wide one), the leaf part on how
/// well the build grouped the primitives.
#[derive(Clone, Copy, Debug, Default)]
struct SahCost {
    nodes: f64,
    leaves: f64,
}

impl Bvh4 {
    pub fn build(shapes: &[Shape]) -> Self {
        let prims = prims::collect(shapes);
        let mut b = Bvh4 { nodes: Vec::new(), leaves: Vec::new(), groups: Vec::new(), ids: Vec::new(), spheres: Vec::new(), root: EMPTY, sah: SahCost::default() };
        let Some((tree, order)) = build_tree(&prims) else { return b };
        let ordered: Vec<Prim> = order.iter().map(|&i| prims[i as usize]).collect();
        b.root = b.emit(&tree, &ordered);
        b.sah = b.sah_cost(b.root, tree.bounds().half_area() as f64);
        b
    }

    /// Flatten `node` depth-first; returns its child code.
    fn emit(&mut self, node: &BuildNode, prims: &[Prim]) -> u32 {
        match node {
            BuildNode::Leaf { first, count, .. } => self.emit_leaf(&prims[*first..*first + *count]),
            BuildNode::Interior { .. } => {
                // Open the largest child until four children (or only leaves) remain.
                let mut kids: Vec<&BuildNode> = vec![node];
                while kids.len() < WIDTH {
                    let best = kids
                        .iter()
                        .enumerate()
                        .filter(|(_, k)| matches!(k, BuildNode::Interior { .. }))
                        .max_by(|a, b| a.1.bounds().half_area().total_cmp(&b.1.bounds().half_area()))
                        .map(|(i, _)| i);
                    let Some(i) = best else { break };
                    let BuildNode::Interior { children, .. } = kids.remove(i) else { unreachable!() };
                    kids.insert(i, &children.1);
                    kids.insert(i, &children.0);
                }
                let idx = self.nodes.len();
                self.nodes.push(Node4 { bounds: [[f32::INFINITY; WIDTH], [f32::INFINITY; WIDTH], [f32::INFINITY; WIDTH], [f32::NEG_INFINITY; WIDTH], [f32::NEG_INFINITY; WIDTH], [f32::NEG_INFINITY; WIDTH]], child: [EMPTY; WIDTH], _pad: [0; 4] });
                for (lane, k) in kids.iter().enumerate() {
                    let code = self.emit(k, prims);
                    let b: &Aabb = k.bounds();
                    let n = &mut self.nodes[idx];
                    for a in 0..3 {
                        n.bounds[a][lane] = b.min[a];
                        n.bounds[3 + a][lane] = b.max[a];
                    }
                    n.child[lane] = code;
                }
                idx as u32
            }
        }
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
            cost.nodes += area / root; // one visit tests all four child boxes
            let n = &self.nodes[c as usize];
            for lane in 0..WIDTH {
                if n.child[lane] != EMPTY {
                    let e = [0, 1, 2].map(|a| (n.bounds[3 + a][lane] - n.bounds[a][lane]).max(0.0) as f64);
                    stack.push((n.child[lane], e[0] * e[1] + e[1] * e[2] + e[2] * e[0]));
                }
            }
        }
        cost
    }

    fn emit_leaf(&mut self, prims: &[Prim]) -> u32 {
        let group = self.groups.len() as u32;
        let sphere = self.spheres.len() as u32;
        let tris: Vec<&Prim> = prims.iter().filter(|p| !p.is_sphere()).collect();
        self.spheres.extend(prims.iter().filter(|p| p.is_sphere()).copied());
        for chunk in tris.chunks(WIDTH) {
            let mut g = TriGroup { v: [[[0.0; WIDTH]; 3]; 3] };
            for lane in 0..WIDTH {
                // Padding lanes repeat the first triangle; `ids` marks them empty.
                let p = chunk[lane.min(chunk.len() - 1)];
                for k in 0..3 {
                    for a in 0..3 {
                        g.v[k][a][lane] = p.v[k][a];
                    }
                }
                self.ids.push(if lane < chunk.len() { [p.geom_id(), p.prim_id] } else { [EMPTY, EMPTY] });
            }
            self.groups.push(g);
        }
        let leaf = Leaf { group, n_groups: self.groups.len() as u32 - group, sphere, n_spheres: self.spheres.len() as u32 - sphere };
        if leaf.n_spheres == 0 && leaf.n_groups <= 3 && group < INLINE_GROUP_LIMIT {
            return LEAF_BIT | INLINE_BIT | leaf.n_groups << 28 | group;
        }
        self.leaves.push(leaf);
        assert!(self.leaves.len() < INLINE_BIT as usize, "too many leaf records");
        LEAF_BIT | (self.leaves.len() as u32 - 1)
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
            let ids = &self.ids[gi as usize * WIDTH..gi as usize * WIDTH + WIDTH];
            let mut out = [LaneHit::default(); WIDTH];
            let mask = intersect_group(g, rt, shear, ray.tmin, tmax, &mut out);
            for lane in 0..WIDTH {
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

    /// Front-to-back traversal; `visit` may lower `tmax` and returns true to stop.
    #[inline]
    fn walk<F: FnMut(Hit, &mut f32) -> bool>(&self, ray: &Ray, mut visit: F) {
        if self.root == EMPTY {
            return;
        }
        let rt = RayTransform::new(ray.origin, ray.dir);
        let shear = Shear::new(&rt);
        let slab = Slab4::new(ray);
        let mut tmax = ray.tmax;
        // Stack of (child code, entry distance).
        let mut stack = [(0u32, 0.0f32); STACK];
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
                let mut near = [0.0f32; WIDTH];
                let mask = slab.test(node, ray.tmin, tmax, &mut near);
                // Push hit children far to near, then continue with the nearest.
                let mut hits: [(u32, f32); WIDTH] = [(0, 0.0); WIDTH];
                let mut n = 0;
                for lane in 0..WIDTH {
                    if mask & (1 << lane) != 0 {
                        hits[n] = (node.child[lane], near[lane]);
                        n += 1;
                    }
                }
                if n > 0 {
                    let h = &mut hits[..n];
                    sort_far_first(h, |e| e.1);
                    for &e in &h[..n - 1] {
                        stack[sp] = e;
                        sp += 1;
                    }
                    cur = h[n - 1].0;
                    continue;
                }
            }
            // Pop, skipping subtrees that start beyond the current closest hit.
            loop {
                if sp == 0 {
                    return;
                }
                sp -= 1;
                let (code, dist) = stack[sp];
                if dist <= tmax {
                    cur = code;
                    break;
                }
            }
        }
    }
}

/// Four coherent rays traversed together: one node fetch and one 4-ray box
/// test per child serve the whole packet; leaves are intersected ray by ray
/// with the same group test as single rays. The tie rule makes the closest
/// hit independent of the visiting order, so answers equal single-ray ones.
struct Packet {
    o: [[f32; WIDTH]; 3],
    inv: [[f32; WIDTH]; 3],
    /// Per axis, lanes whose direction has the sign bit set (all ones) or not.
    neg: [[u32; WIDTH]; 3],
    tmin: [f32; WIDTH],
    tmax: [f32; WIDTH],
    active: u32,
}

impl Packet {
    fn new(rays: &[Ray]) -> Self {
        let mut p = Packet { o: [[0.0; WIDTH]; 3], inv: [[1.0; WIDTH]; 3], neg: [[0; WIDTH]; 3], tmin: [0.0; WIDTH], tmax: [f32::NEG_INFINITY; WIDTH], active: 0 };
        for (l, r) in rays.iter().enumerate() {
            if !r.is_valid() {
                continue;
            }
            p.active |= 1 << l;
            for a in 0..3 {
                p.o[a][l] = r.origin[a];
                p.inv[a][l] = 1.0 / r.dir[a];
                p.neg[a][l] = if r.dir[a].is_sign_negative() { u32::MAX } else { 0 };
            }
            p.tmin[l] = r.tmin;
            p.tmax[l] = r.tmax;
        }
        p
    }

    /// Which active lanes enter child `c` of `n`, and the smallest entry distance among them.
    #[inline(always)]
    fn test_child(&self, n: &Node4, c: usize) -> (u32, f32) {
        #[cfg(target_arch = "x86_64")]
        unsafe {
            use std::arch::x86_64::*;
            let mut t0 = _mm_loadu_ps(self.tmin.as_ptr());
            let mut t1 = _mm_loadu_ps(self.tmax.as_ptr());
            let scale = _mm_set1_ps(ROBUST_SCALE);
            for a in 0..3 {
                let bmin = _mm_set1_ps(n.bounds[a][c]);
                let bmax = _mm_set1_ps(n.bounds[3 + a][c]);
                let neg = _mm_castsi128_ps(_mm_loadu_si128(self.neg[a].as_ptr() as *const __m128i));
                // Per lane: near plane = max for negative directions, else min.
                let lo = _mm_or_ps(_mm_and_ps(neg, bmax), _mm_andnot_ps(neg, bmin));
                let hi = _mm_or_ps(_mm_and_ps(neg, bmin), _mm_andnot_ps(neg, bmax));
                let o = _mm_loadu_ps(self.o[a].as_ptr());
                let inv = _mm_loadu_ps(self.inv[a].as_ptr());
                let tn = _mm_mul_ps(_mm_sub_ps(lo, o), inv);
                let tf = _mm_mul_ps(_mm_mul_ps(_mm_sub_ps(hi, o), inv), scale);
                t0 = _mm_max_ps(tn, t0);
                t1 = _mm_min_ps(tf, t1);
            }
            let mask = _mm_movemask_ps(_mm_cmple_ps(t0, t1)) as u32 & self.active;
            let mut t = [0.0f32; WIDTH];
            _mm_storeu_ps(t.as_mut_ptr(), t0);
            let mut near = f32::INFINITY;
            for (l, &tl) in t.iter().enumerate() {
                if mask & (1 << l) != 0 && tl < near {
                    near = tl;
                }
            }
            (mask, near)
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let (mut mask, mut near) = (0, f32::INFINITY);
            for l in 0..WIDTH {
                if self.active & (1 << l) == 0 {
                    continue;
                }
                let (mut t0, mut t1) = (self.tmin[l], self.tmax[l]);
                for a in 0..3 {
                    let neg = self.neg[a][l] != 0;
                    let (lo, hi) = if neg { (n.bounds[3 + a][c], n.bounds[a][c]) } else { (n.bounds[a][c], n.bounds[3 + a][c]) };
                    let tn = (lo - self.o[a][l]) * self.inv[a][l];
                    let tf = (hi - self.o[a][l]) * self.inv[a][l] * ROBUST_SCALE;
                    if tn > t0 {
                        t0 = tn;
                    }
                    if tf < t1 {
                        t1 = tf;
                    }
                }
                if t0 <= t1 {
                    mask |= 1 << l;
                    near = near.min(t0);
                }
            }
            (mask, near)
        }
    }
}

impl Bvh4 {
    /// Closest hits (`occlusion == false`) or any hits for up to 4 rays. Each
    /// stack entry carries the lanes that entered it, so a leaf or subtree is
    /// only tested for the rays that reach it.
    fn packet(&self, rays: &[Ray], hits: &mut [Option<Hit>], occluded: &mut [bool], occlusion: bool) {
        let mut p = Packet::new(rays);
        if self.root == EMPTY || p.active == 0 {
            return;
        }
        let rts: Vec<RayTransform> = rays.iter().map(|r| RayTransform::new(r.origin, r.dir)).collect();
        let shears: Vec<Shear> = rts.iter().map(Shear::new).collect();
        let mut stack = [(0u32, 0.0f32, 0u32); STACK];
        let mut sp = 0;
        let (mut cur, mut lanes_in) = (self.root, p.active);
        loop {
            let lanes_here = lanes_in & p.active;
            if lanes_here != 0 && cur & LEAF_BIT != 0 {
                let leaf = &self.leaf_of(cur);
                let mut lanes = lanes_here;
                while lanes != 0 {
                    let l = lanes.trailing_zeros() as usize;
                    lanes &= lanes - 1;
                    let mut best = hits[l];
                    let mut tmax = p.tmax[l];
                    let mut found = false;
                    self.leaf(leaf, &rays[l], &rts[l], &shears[l], tmax, &mut |h| {
                        found = true;
                        if occlusion {
                            return true;
                        }
                        if closer(h, &best) {
                            tmax = h.t;
                            best = Some(h);
                        }
                        false
                    });
                    if occlusion {
                        if found {
                            occluded[l] = true;
                            p.active &= !(1 << l);
                        }
                    } else {
                        hits[l] = best;
                        p.tmax[l] = tmax;
                    }
                }
                if p.active == 0 {
                    return;
                }
            } else if lanes_here != 0 {
                let node = &self.nodes[cur as usize];
                let mut next: [(u32, f32, u32); WIDTH] = [(0, 0.0, 0); WIDTH];
                let mut n = 0;
                let saved = p.active;
                p.active = lanes_here;
                for c in 0..WIDTH {
                    if node.child[c] == EMPTY {
                        continue;
                    }
                    let (mask, near) = p.test_child(node, c);
                    if mask != 0 {
                        next[n] = (node.child[c], near, mask);
                        n += 1;
                    }
                }
                p.active = saved;
                if n > 0 {
                    let h = &mut next[..n];
                    sort_far_first(h, |e| e.1);
                    for &e in &h[..n - 1] {
                        stack[sp] = e;
                        sp += 1;
                    }
                    (cur, lanes_in) = (h[n - 1].0, h[n - 1].2);
                    continue;
                }
            }
            // Pop, skipping subtrees every one of their rays has already passed.
            loop {
                if sp == 0 {
                    return;
                }
                sp -= 1;
                let (code, dist, mask) = stack[sp];
                let live = mask & p.active;
                let far = (0..WIDTH).filter(|l| live & (1 << l) != 0).map(|l| p.tmax[l]).fold(f32::NEG_INFINITY, f32::max);
                if live != 0 && dist <= far {
                    (cur, lanes_in) = (code, live);
                    break;
                }
            }
        }
    }
}

impl Traversal for Bvh4 {
    fn name(&self) -> &'static str {
        "native"
    }

    fn sah_cost(&self) -> Option<(f64, f64)> {
        Some((self.sah.nodes, self.sah.leaves))
    }

    fn describe(&self) -> String {
        format!(
            "native (4-wide BVH, binned SAH, SSE, {} nodes, {} leaves, SAH cost {:.2} = nodes {:.2} + leaves {:.2})",
            self.nodes.len(),
            self.leaves.len(),
            self.sah.nodes + self.sah.leaves,
            self.sah.nodes,
            self.sah.leaves
        )
    }

    fn memory_bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<Node4>()
            + self.leaves.len() * std::mem::size_of::<Leaf>()
            + self.groups.len() * std::mem::size_of::<TriGroup>()
            + self.ids.len() * 8
            + self.spheres.len() * std::mem::size_of::<Prim>()
    }

    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        let mut best: Option<Hit> = None;
        self.walk(ray, |h, tmax| {
            if closer(h, &best) {
                *tmax = h.t;
                best = Some(h);
            }
            false
        });
        best
    }

    fn occluded(&self, ray: &Ray) -> bool {
        if !ray.is_valid() {
            return false;
        }
        let mut hit = false;
        self.walk(ray, |_, _| {
            hit = true;
            true
        });
        hit
    }

    fn intersect_coherent(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), hits.len());
        let mut unused = [false; WIDTH];
        for (r, h) in rays.chunks(WIDTH).zip(hits.chunks_mut(WIDTH)) {
            h.fill(None);
            self.packet(r, h, &mut unused[..r.len()], false);
        }
    }

    fn occluded_coherent(&self, rays: &[Ray], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len());
        let mut unused = [None; WIDTH];
        for (r, o) in rays.chunks(WIDTH).zip(out.chunks_mut(WIDTH)) {
            o.fill(false);
            self.packet(r, &mut unused[..r.len()], o, true);
        }
    }
}

/// Insertion sort of at most 4 hit children by entry distance, farthest
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
struct Slab4 {
    o: [f32; 3],
    inv: [f32; 3],
    /// Index into `Node4::bounds` of the near plane per axis (min or max).
    near_plane: [usize; 3],
}

impl Slab4 {
    fn new(ray: &Ray) -> Self {
        let d = ray.dir;
        let neg = [d.x.is_sign_negative(), d.y.is_sign_negative(), d.z.is_sign_negative()];
        Slab4 {
            o: ray.origin.to_array(),
            inv: [1.0 / d.x, 1.0 / d.y, 1.0 / d.z],
            near_plane: [if neg[0] { 3 } else { 0 }, if neg[1] { 4 } else { 1 }, if neg[2] { 5 } else { 2 }],
        }
    }

    /// Bit i set when child i's box is entered in [tmin, tmax]; `near` gets entry distances.
    #[inline(always)]
    fn test(&self, n: &Node4, tmin: f32, tmax: f32, near: &mut [f32; WIDTH]) -> u32 {
        #[cfg(target_arch = "x86_64")]
        unsafe {
            use std::arch::x86_64::*;
            let mut t0 = _mm_set1_ps(tmin);
            let mut t1 = _mm_set1_ps(tmax);
            let scale = _mm_set1_ps(ROBUST_SCALE);
            for a in 0..3 {
                let o = _mm_set1_ps(self.o[a]);
                let inv = _mm_set1_ps(self.inv[a]);
                let lo = _mm_load_ps(n.bounds[self.near_plane[a]].as_ptr());
                let hi = _mm_load_ps(n.bounds[(self.near_plane[a] + 3) % 6].as_ptr());
                let tn = _mm_mul_ps(_mm_sub_ps(lo, o), inv);
                let tf = _mm_mul_ps(_mm_mul_ps(_mm_sub_ps(hi, o), inv), scale);
                // maxps(a, b) = a > b ? a : b, so a NaN in tn leaves t0 as it is.
                t0 = _mm_max_ps(tn, t0);
                t1 = _mm_min_ps(tf, t1);
            }
            _mm_storeu_ps(near.as_mut_ptr(), t0);
            _mm_movemask_ps(_mm_cmple_ps(t0, t1)) as u32
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let mut mask = 0;
            for lane in 0..WIDTH {
                let (mut t0, mut t1) = (tmin, tmax);
                for a in 0..3 {
                    let lo = n.bounds[self.near_plane[a]][lane];
                    let hi = n.bounds[(self.near_plane[a] + 3) % 6][lane];
                    let tn = (lo - self.o[a]) * self.inv[a];
                    let tf = (hi - self.o[a]) * self.inv[a] * ROBUST_SCALE;
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
fn intersect_group(g: &TriGroup, rt: &RayTransform, sh: &Shear, tmin: f32, tmax: f32, out: &mut [LaneHit; WIDTH]) -> u32 {
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
            let (mut tt, mut uu, mut vv) = ([0.0f32; WIDTH], [0.0f32; WIDTH], [0.0f32; WIDTH]);
            _mm_storeu_ps(tt.as_mut_ptr(), t);
            _mm_storeu_ps(uu.as_mut_ptr(), _mm_mul_ps(e1, inv));
            _mm_storeu_ps(vv.as_mut_ptr(), _mm_mul_ps(e2, inv));
            for lane in 0..WIDTH {
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
        let mut mask = 0;
        for lane in 0..WIDTH {
            if let Some((t, u, v)) = scalar_lane(g, lane, rt, tmin, tmax) {
                out[lane] = LaneHit { t, u, v };
                mask |= 1 << lane;
            }
        }
        mask
    }
}

#[inline]
fn scalar_lane(g: &TriGroup, lane: usize, rt: &RayTransform, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
    let p = |k: usize| Vec3::new(g.v[k][0][lane], g.v[k][1][lane], g.v[k][2][lane]);
    intersect_triangle(rt, p(0), p(1), p(2), tmin, tmax)
}
