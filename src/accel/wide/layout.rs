//! Building the W-wide arrays traversal reads, straight from SAH splits,
//! in two passes. The build records nodes (depth first) and leaves (as
//! runs of the build references), large subtrees in parallel as pieces of
//! their own; `flatten` then gives every piece its place in the final
//! arrays and, in parallel, copies its nodes there and writes its leaves'
//! triangle groups straight into place. Triangle data is written once, and
//! since where a subtree becomes a piece depends only on its size, the
//! layout never depends on the thread count.

use super::{Leaf, Node, TriGroup, EMPTY, INLINE_BIT, INLINE_GROUP_LIMIT, LANES, LEAF_BIT};
use crate::accel::bvh::{BuildSet, PrimRef, SplitRole};
use crate::accel::prims::{Prim, PrimTable};
use crate::geometry::Aabb;
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// The arrays traversal reads.
#[derive(Default)]
pub(super) struct Arrays<const W: usize> {
    pub(super) nodes: Vec<Node<W>>,
    pub(super) leaves: Vec<Leaf>,
    pub(super) groups: Vec<TriGroup>,
    pub(super) spheres: Vec<Prim>,
}

/// A leaf as the build records it: build references
/// `refs[first..first + count]`, `tris` of them triangles, the rest spheres.
#[derive(Clone, Copy)]
struct Pending {
    first: u32,
    count: u8,
    tris: u8,
}

impl Pending {
    fn groups(&self) -> u32 {
        (self.tris as u32).div_ceil(LANES as u32)
    }

    fn spheres(&self) -> u32 {
        (self.count - self.tris) as u32
    }

    /// Triangles only, at most three groups: described by the child code
    /// itself (`INLINE_BIT`), else by a leaf record.
    fn inline(&self) -> bool {
        self.spheres() == 0 && self.groups() <= 3
    }
}

/// A subtree being built: its nodes, whose leaf child codes
/// `LEAF_BIT | k` stand for `leaves[k]`, and its pieces, built in parallel,
/// whose roots child codes `PIECE_BIT | k` stand for; `flatten` replaces
/// both with final codes.
#[derive(Default)]
pub(super) struct Part<const W: usize> {
    nodes: Vec<Node<W>>,
    leaves: Vec<Pending>,
    pieces: Vec<Piece<W>>,
    /// Totals over `leaves`: triangle groups, leaf records, spheres.
    groups: u32,
    records: u32,
    spheres: u32,
}

/// A subtree built on its own: its part and its root's code in it.
pub(super) struct Piece<const W: usize> {
    pub(super) part: Part<W>,
    pub(super) root: u32,
}

/// See `Part`. Node indices stay below it (asserted in `flatten`).
const PIECE_BIT: u32 = 1 << 30;

/// The interior children of wide nodes over more primitives than this are
/// built in parallel, as pieces. At 2^15 the CBbunny (28k triangles) was
/// built on one thread, 7.1 ms against Embree's 4.0 on two; at 2^12 it
/// takes 4.2-4.4 ms, and the 1M-triangle build is unchanged.
const PARALLEL_BUILD: usize = 1 << 12;

/// A child gathered for a wide node: its primitives, and whether `split`
/// already refused to split them (a leaf).
struct Kid<'a> {
    set: BuildSet<'a>,
    leaf: bool,
}

/// The children of a wide node (half-area `node_area`) whose set split into
/// `l` and `r`: split the child with the largest box again until `W`
/// children (or only leaves) remain, keeping them in order, as collapsing
/// the binary SAH tree would; which children stay leaves is
/// `SplitRole::Lane`'s.
fn gather<'a, const W: usize>(l: BuildSet<'a>, r: BuildSet<'a>, node_area: f32, prims: &PrimTable) -> Vec<Kid<'a>> {
    let mut kids = Vec::with_capacity(W);
    kids.push(Kid { set: l, leaf: false });
    kids.push(Kid { set: r, leaf: false });
    while kids.len() < W {
        let mut best: Option<(usize, f32)> = None;
        for (i, k) in kids.iter().enumerate() {
            let a = k.set.half_area();
            if !k.leaf && best.map_or(true, |(_, b)| a > b) {
                best = Some((i, a));
            }
        }
        let Some((i, _)) = best else { break };
        match kids.remove(i).set.split(prims, SplitRole::Lane { node_area }) {
            Ok((a, b)) => {
                kids.insert(i, Kid { set: b, leaf: false });
                kids.insert(i, Kid { set: a, leaf: false });
            }
            Err(set) => kids.insert(i, Kid { set, leaf: true }),
        }
    }
    kids
}

impl<const W: usize> Part<W> {
    /// An empty part with room for a subtree of `prims` primitives: the
    /// 8-wide tree of the 1M mesh has a node per 16 triangles and a leaf
    /// per 3.6. A subtree large enough to be built in pieces holds only its
    /// top here, so it gets no room in advance.
    pub(super) fn with_room_for(prims: usize) -> Self {
        if prims > PARALLEL_BUILD {
            return Part::default();
        }
        Part { nodes: Vec::with_capacity(prims / (W + 4) + 8), leaves: Vec::with_capacity(prims / 3 + 8), ..Part::default() }
    }

    /// Build the subtree over `set` (primitives indexing `prims`), nodes
    /// depth first, leaves recorded in order; returns its child code.
    pub(super) fn build(&mut self, set: BuildSet, prims: &PrimTable) -> u32 {
        let n = set.len();
        let node_area = set.half_area();
        let (l, r) = match set.split(prims, SplitRole::Node) {
            Ok(sides) => sides,
            Err(set) => return self.leaf(prims, &set),
        };
        let kids = gather::<W>(l, r, node_area, prims);
        let idx = self.push_node();
        if n > PARALLEL_BUILD {
            // Leaves here, interior children as pieces, in parallel.
            let mut interior = Vec::with_capacity(W);
            for (lane, k) in kids.into_iter().enumerate() {
                self.set_child(idx, lane, &k.set.bounds(), EMPTY);
                if k.leaf {
                    let code = self.leaf(prims, &k.set);
                    self.nodes[idx].child[lane] = code;
                } else {
                    interior.push((lane, k.set));
                }
            }
            let built: Vec<(usize, Piece<W>)> = interior
                .into_par_iter()
                .map(|(lane, set)| {
                    let mut part = Part::with_room_for(set.len());
                    let root = part.build(set, prims);
                    (lane, Piece { part, root })
                })
                .collect();
            for (lane, piece) in built {
                self.nodes[idx].child[lane] = PIECE_BIT | self.pieces.len() as u32;
                self.pieces.push(piece);
            }
        } else {
            for (lane, k) in kids.into_iter().enumerate() {
                let bounds = k.set.bounds();
                let code = self.child(k, prims);
                self.set_child(idx, lane, &bounds, code);
            }
        }
        idx as u32
    }

    fn child(&mut self, k: Kid, prims: &PrimTable) -> u32 {
        if k.leaf {
            self.leaf(prims, &k.set)
        } else {
            self.build(k.set, prims)
        }
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

    /// Record `set` as a leaf; `flatten` writes it.
    fn leaf(&mut self, prims: &PrimTable, set: &BuildSet) -> u32 {
        let tris = set.indices().filter(|&i| !prims.is_sphere(i)).count();
        let p = Pending { first: set.offset() as u32, count: set.len() as u8, tris: tris as u8 };
        self.groups += p.groups();
        self.spheres += p.spheres();
        self.records += !p.inline() as u32;
        self.leaves.push(p);
        assert!(self.leaves.len() < PIECE_BIT as usize, "too many leaves");
        LEAF_BIT | (self.leaves.len() as u32 - 1)
    }
}

/// Where a piece's data go in the final arrays.
#[derive(Clone, Copy, Default)]
struct Base {
    nodes: u32,
    records: u32,
    groups: u32,
    spheres: u32,
}

/// One piece's share of the flattening: its part, where it goes, and the
/// final codes of its own pieces' roots.
struct Placed<'a, const W: usize> {
    part: &'a Part<W>,
    base: Base,
    pieces: Vec<u32>,
}

/// The final code of a piece's root `code`, placed at `base`: a node, or
/// the piece's first (and only) leaf.
fn root_code<const W: usize>(part: &Part<W>, code: u32, base: &Base, pieces: &[u32]) -> u32 {
    if code & LEAF_BIT != 0 {
        debug_assert_eq!(code & !LEAF_BIT, 0, "a piece whose root is a leaf has one leaf");
        let p = part.leaves[0];
        return if p.inline() { LEAF_BIT | INLINE_BIT | p.groups() << 28 | base.groups } else { LEAF_BIT | base.records };
    }
    if code & PIECE_BIT != 0 {
        return pieces[(code & !PIECE_BIT) as usize];
    }
    code + base.nodes
}

/// Lay `pieces` (and theirs) out after `next`, depth first, each piece
/// before its own pieces; returns their final root codes.
fn place<'a, const W: usize>(pieces: &'a [Piece<W>], next: &mut Base, out: &mut Vec<Placed<'a, W>>) -> Vec<u32> {
    pieces
        .iter()
        .map(|p| {
            let base = *next;
            let a = &p.part;
            next.nodes += a.nodes.len() as u32;
            next.records += a.records;
            next.groups += a.groups;
            next.spheres += a.spheres;
            let slot = out.len();
            out.push(Placed { part: a, base, pieces: Vec::new() });
            out[slot].pieces = place(&a.pieces, next, out);
            root_code(a, p.root, &base, &out[slot].pieces)
        })
        .collect()
}

/// Cut `n` elements off the front of `rest`.
fn take<'a, T>(rest: &mut &'a mut [MaybeUninit<T>], n: usize) -> &'a mut [MaybeUninit<T>] {
    let (head, tail) = std::mem::take(rest).split_at_mut(n);
    *rest = tail;
    head
}

/// The tree `root` as the final arrays: every piece placed depth first, its
/// nodes copied and its leaves written, in parallel; returns them and the
/// root's code. `refs` are the build's references, which the recorded
/// leaves index.
pub(super) fn flatten<const W: usize>(root: Piece<W>, refs: &[PrimRef], prims: &PrimTable) -> (Arrays<W>, u32) {
    let mut total = Base::default();
    let mut placed = Vec::new();
    let code = place(std::slice::from_ref(&root), &mut total, &mut placed)[0];
    assert!(total.nodes < PIECE_BIT, "too many BVH nodes ({})", total.nodes);
    // Inline leaves hold their first group in 28 bits; 2^28 groups of 4
    // would be a billion triangles, far past what fits in memory here.
    assert!(total.groups < INLINE_GROUP_LIMIT, "too many triangle groups ({})", total.groups);
    assert!(total.records < INLINE_BIT, "too many leaf records ({})", total.records);
    use crate::accel::huge::vec_with_capacity as huge;
    let mut out = Arrays::<W> {
        nodes: huge(total.nodes as usize),
        leaves: Vec::with_capacity(total.records as usize),
        groups: huge(total.groups as usize),
        spheres: Vec::with_capacity(total.spheres as usize),
    };
    {
        // Each piece's destination, cut from the arrays' spare room in order.
        let mut nodes = &mut out.nodes.spare_capacity_mut()[..total.nodes as usize];
        let mut records = &mut out.leaves.spare_capacity_mut()[..total.records as usize];
        let mut groups = &mut out.groups.spare_capacity_mut()[..total.groups as usize];
        let mut spheres = &mut out.spheres.spare_capacity_mut()[..total.spheres as usize];
        let jobs: Vec<_> = placed
            .iter()
            .map(|p| {
                let a = p.part;
                let g = a.groups as usize;
                (p, take(&mut nodes, a.nodes.len()), take(&mut records, a.records as usize), take(&mut groups, g), take(&mut spheres, a.spheres as usize))
            })
            .collect();
        jobs.into_par_iter().for_each(|(p, nodes, records, groups, spheres)| {
            let codes = write_leaves(p, refs, prims, records, groups, spheres);
            let base = p.base;
            for (dst, src) in nodes.iter_mut().zip(&p.part.nodes) {
                let mut node = *src;
                for c in node.child.iter_mut() {
                    *c = if *c == EMPTY {
                        EMPTY
                    } else if *c & LEAF_BIT != 0 {
                        codes[(*c & !LEAF_BIT) as usize]
                    } else if *c & PIECE_BIT != 0 {
                        p.pieces[(*c & !PIECE_BIT) as usize]
                    } else {
                        *c + base.nodes
                    };
                }
                dst.write(node);
            }
        });
    }
    // SAFETY: the jobs above wrote every element up to these lengths: the
    // pieces' slices tile `0..total` of each array exactly, and each piece
    // writes all of its nodes, records, groups (with their ids) and spheres.
    unsafe {
        out.nodes.set_len(total.nodes as usize);
        out.leaves.set_len(total.records as usize);
        out.groups.set_len(total.groups as usize);
        out.spheres.set_len(total.spheres as usize);
    }
    (out, code)
}

/// Write the leaves of piece `p` into its slices of the final arrays;
/// returns their final child codes.
#[allow(clippy::too_many_arguments)]
fn write_leaves<const W: usize>(
    p: &Placed<W>,
    refs: &[PrimRef],
    prims: &PrimTable,
    records: &mut [MaybeUninit<Leaf>],
    groups: &mut [MaybeUninit<TriGroup>],
    spheres: &mut [MaybeUninit<Prim>],
) -> Vec<u32> {
    let base = p.base;
    let (mut g, mut r, mut s) = (0usize, 0usize, 0usize);
    let mut codes = Vec::with_capacity(p.part.leaves.len());
    let mut sorted: Vec<(f32, Prim)> = Vec::new();
    let leaves = &p.part.leaves;
    let run_of = |l: &Pending| &refs[l.first as usize..l.first as usize + l.count as usize];
    for (k, leaf) in leaves.iter().enumerate() {
        // The triangles come from the scene's meshes in build order, far
        // apart in memory: their indices are fetched 8 leaves ahead and
        // their vertices 4 ahead.
        for (ahead, vertices) in [(8, false), (4, true)] {
            if let Some(l) = leaves.get(k + ahead) {
                for r in run_of(l) {
                    prims.prefetch(r.index(), vertices);
                }
            }
        }
        let run = run_of(leaf);
        let (group, sphere) = (base.groups + g as u32, base.spheres + s as u32);
        // Largest triangles first: a shadow packet tests its rays against
        // a leaf's triangles one at a time (`leaf_rays_x8`) and stops once
        // all are occluded, and a large triangle occludes more of them.
        // Measured (1 thread, best of 7, three alternating pairs): arch:500k
        // shadow rays 32.8-33.5 -> 35.2-35.3 Mrays/s; other scenes and ray
        // kinds within noise; sphere 1M build 156-174 -> 153-166 ms (noise).
        sorted.clear();
        sorted.extend(run.iter().map(|x| prims.get(x.index())).filter(|q| !q.is_sphere()).map(|q| ((q.v[1] - q.v[0]).cross(q.v[2] - q.v[0]).length_squared(), q)));
        sorted.sort_by(|a, b| b.0.total_cmp(&a.0));
        let mut tris = sorted.iter().map(|x| x.1).peekable();
        while let Some(first) = tris.peek().copied() {
            let mut tg = TriGroup { v: [[[0.0; LANES]; 3]; 3], ids: [[EMPTY; 2]; LANES] };
            for lane in 0..LANES {
                // Padding lanes repeat the group's first triangle; `ids` marks them empty.
                let (q, real) = match tris.next() {
                    Some(q) => (q, true),
                    None => (first, false),
                };
                for k in 0..3 {
                    for a in 0..3 {
                        tg.v[k][a][lane] = q.v[k][a];
                    }
                }
                tg.ids[lane] = if real { [q.geom_id(), q.prim_id] } else { [EMPTY, EMPTY] };
            }
            groups[g].write(tg);
            g += 1;
        }
        // Most leaves hold triangles only: no second fetch of their primitives.
        if leaf.spheres() > 0 {
            for q in run.iter().map(|x| prims.get(x.index())).filter(|q| q.is_sphere()) {
                spheres[s].write(q);
                s += 1;
            }
        }
        codes.push(if leaf.inline() {
            LEAF_BIT | INLINE_BIT | leaf.groups() << 28 | group
        } else {
            records[r].write(Leaf { group, n_groups: leaf.groups(), sphere, n_spheres: leaf.spheres() });
            r += 1;
            LEAF_BIT | (base.records + r as u32 - 1)
        });
    }
    debug_assert_eq!((g, r, s), (p.part.groups as usize, p.part.records as usize, p.part.spheres as usize));
    codes
}
