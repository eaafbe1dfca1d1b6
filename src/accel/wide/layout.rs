//! Building the W-wide arrays traversal reads, straight from SAH splits:
//! nodes depth first, triangle groups in leaf order. Large subtrees are built
//! in parallel as pieces of their own, which `flatten` then copies, in
//! parallel too, into one set of arrays: each piece is copied once, and
//! since where a subtree becomes a piece depends only on its size, the
//! layout never depends on the thread count.

use super::{Leaf, Node, TriGroup, EMPTY, INLINE_BIT, INLINE_GROUP_LIMIT, LANES, LEAF_BIT};
use crate::accel::bvh::{BuildSet, MAX_LEAF};
use crate::accel::prims::{Prim, PrimTable};
use crate::geometry::Aabb;
use rayon::prelude::*;

/// The arrays of a tree being laid out.
pub(super) struct Arrays<const W: usize> {
    pub(super) nodes: Vec<Node<W>>,
    pub(super) leaves: Vec<Leaf>,
    pub(super) groups: Vec<TriGroup>,
    pub(super) ids: Vec<[u32; 2]>,
    pub(super) spheres: Vec<Prim>,
    /// Subtrees built in parallel; a child code `PIECE_BIT | k` here stands
    /// for the root of `pieces[k]`, until `flatten` places it.
    pieces: Vec<Piece<W>>,
}

/// A subtree built on its own: its arrays and its root's code in them.
pub(super) struct Piece<const W: usize> {
    pub(super) arrays: Arrays<W>,
    pub(super) root: u32,
}

/// See `Arrays::pieces`. Node indices stay below it (asserted in `flatten`).
const PIECE_BIT: u32 = 1 << 30;

impl<const W: usize> Default for Arrays<W> {
    fn default() -> Self {
        Arrays { nodes: Vec::new(), leaves: Vec::new(), groups: Vec::new(), ids: Vec::new(), spheres: Vec::new(), pieces: Vec::new() }
    }
}

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

/// The children of a wide node whose set split into `l` and `r`: split the
/// child with the largest box again until `W` children (or only leaves)
/// remain, keeping them in order, as collapsing the binary SAH tree would.
fn gather<'a, const W: usize>(l: BuildSet<'a>, r: BuildSet<'a>) -> Vec<Kid<'a>> {
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
        match kids.remove(i).set.split() {
            Ok((a, b)) => {
                kids.insert(i, Kid { set: b, leaf: false });
                kids.insert(i, Kid { set: a, leaf: false });
            }
            Err(set) => kids.insert(i, Kid { set, leaf: true }),
        }
    }
    kids
}

impl<const W: usize> Arrays<W> {
    /// Empty arrays with room for a subtree of `prims` triangles: the
    /// block-counted SAH fills groups of 4 to about 3.8 triangles, and the
    /// 8-wide tree of the 1M mesh has a node per 13 triangles. A subtree
    /// large enough to be built in pieces holds only its top here, so it
    /// gets no room in advance.
    pub(super) fn with_room_for(prims: usize) -> Self {
        if prims > PARALLEL_BUILD {
            return Arrays::default();
        }
        let groups = prims / 3 + 8;
        Arrays {
            nodes: Vec::with_capacity(prims / (W + 4) + 8),
            leaves: Vec::new(),
            groups: Vec::with_capacity(groups),
            ids: Vec::with_capacity(groups * LANES),
            spheres: Vec::new(),
            pieces: Vec::new(),
        }
    }

    /// Build the subtree over `set` (primitives indexing `prims`), nodes
    /// depth first, triangle groups in leaf order; returns its child code.
    /// The layout does not depend on the thread count.
    pub(super) fn build(&mut self, set: BuildSet, prims: &PrimTable) -> u32 {
        let n = set.len();
        let (l, r) = match set.split() {
            Ok(sides) => sides,
            Err(set) => return self.emit_leaf(prims, &set),
        };
        let kids = gather::<W>(l, r);
        let idx = self.push_node();
        if n > PARALLEL_BUILD {
            // Leaves here, interior children as pieces, in parallel.
            let mut interior = Vec::with_capacity(W);
            for (lane, k) in kids.into_iter().enumerate() {
                self.set_child(idx, lane, &k.set.bounds(), EMPTY);
                if k.leaf {
                    let code = self.emit_leaf(prims, &k.set);
                    self.nodes[idx].child[lane] = code;
                } else {
                    interior.push((lane, k.set));
                }
            }
            let built: Vec<(usize, Piece<W>)> = interior
                .into_par_iter()
                .map(|(lane, set)| {
                    let mut arrays = Arrays::with_room_for(set.len());
                    let root = arrays.build(set, prims);
                    (lane, Piece { arrays, root })
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
            self.emit_leaf(prims, &k.set)
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

    fn emit_leaf(&mut self, prims: &PrimTable, set: &BuildSet) -> u32 {
        let mut buf = [0; MAX_LEAF];
        let order = set.indices(&mut buf);
        let group = self.groups.len() as u32;
        let sphere = self.spheres.len() as u32;
        let mut tris = order.iter().map(|&i| prims.get(i)).filter(|p| !p.is_sphere()).peekable();
        while tris.peek().is_some() {
            let mut g = TriGroup { v: [[[0.0; LANES]; 3]; 3] };
            let mut first: Option<Prim> = None;
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
        self.spheres.extend(order.iter().map(|&i| prims.get(i)).filter(|p| p.is_sphere()));
        let leaf = Leaf { group, n_groups: self.groups.len() as u32 - group, sphere, n_spheres: self.spheres.len() as u32 - sphere };
        if leaf.n_spheres == 0 && leaf.n_groups <= 3 && group < INLINE_GROUP_LIMIT {
            return LEAF_BIT | INLINE_BIT | leaf.n_groups << 28 | group;
        }
        self.leaves.push(leaf);
        assert!(self.leaves.len() < INLINE_BIT as usize, "too many leaf records");
        LEAF_BIT | (self.leaves.len() as u32 - 1)
    }
}

/// Where a piece's arrays go in the flattened ones.
#[derive(Clone, Copy, Default)]
struct Base {
    nodes: u32,
    leaves: u32,
    groups: u32,
    spheres: u32,
}

impl Base {
    /// `code`, a child code of a piece placed at `self`, in the flattened
    /// arrays; `pieces` are the final codes of the piece's own pieces.
    fn fix(&self, code: u32, pieces: &[u32]) -> u32 {
        if code == EMPTY {
            code
        } else if code & LEAF_BIT == 0 {
            if code & PIECE_BIT != 0 {
                pieces[(code & !PIECE_BIT) as usize]
            } else {
                code + self.nodes
            }
        } else if code & INLINE_BIT == 0 {
            LEAF_BIT | ((code & !LEAF_BIT) + self.leaves)
        } else {
            code + self.groups
        }
    }
}

/// One piece's share of the flattening: its arrays, where they go, and
/// the final codes of its own pieces.
struct Placed<'a, const W: usize> {
    arrays: &'a Arrays<W>,
    base: Base,
    pieces: Vec<u32>,
}

/// Lay `pieces` (and theirs) out after `next`, depth first, each piece
/// before its own pieces; returns their final root codes.
fn place<'a, const W: usize>(pieces: &'a [Piece<W>], next: &mut Base, out: &mut Vec<Placed<'a, W>>) -> Vec<u32> {
    pieces
        .iter()
        .map(|p| {
            let base = *next;
            let a = &p.arrays;
            next.nodes += a.nodes.len() as u32;
            next.leaves += a.leaves.len() as u32;
            next.groups += a.groups.len() as u32;
            next.spheres += a.spheres.len() as u32;
            let slot = out.len();
            out.push(Placed { arrays: a, base, pieces: Vec::new() });
            out[slot].pieces = place(&a.pieces, next, out);
            base.fix(p.root, &out[slot].pieces)
        })
        .collect()
}

/// The tree `root` (a piece of arrays and their pieces) as one set of
/// arrays, every piece copied to its place in parallel.
pub(super) fn flatten<const W: usize>(root: Piece<W>) -> (Arrays<W>, u32) {
    if root.arrays.pieces.is_empty() {
        return (root.arrays, root.root);
    }
    let mut total = Base::default();
    let mut placed = Vec::new();
    let code = place(std::slice::from_ref(&root), &mut total, &mut placed)[0];
    assert!(total.nodes < PIECE_BIT, "too many BVH nodes ({})", total.nodes);
    // Inline leaves hold their first group in 28 bits; 2^28 groups of 4
    // would be a billion triangles, far past what fits in memory here.
    assert!(total.groups < INLINE_GROUP_LIMIT, "too many triangle groups ({})", total.groups);
    assert!(total.leaves < INLINE_BIT, "too many leaf records ({})", total.leaves);
    let mut out = Arrays::<W> {
        nodes: crate::accel::huge::vec_with_capacity(total.nodes as usize),
        leaves: Vec::with_capacity(total.leaves as usize),
        groups: crate::accel::huge::vec_with_capacity(total.groups as usize),
        ids: crate::accel::huge::vec_with_capacity(total.groups as usize * LANES),
        spheres: Vec::with_capacity(total.spheres as usize),
        pieces: Vec::new(),
    };
    {
        // Each piece's destination, cut from the arrays' spare room in order.
        let (mut nodes, mut leaves, mut groups, mut ids, mut spheres) = (
            &mut out.nodes.spare_capacity_mut()[..total.nodes as usize],
            &mut out.leaves.spare_capacity_mut()[..total.leaves as usize],
            &mut out.groups.spare_capacity_mut()[..total.groups as usize],
            &mut out.ids.spare_capacity_mut()[..total.groups as usize * LANES],
            &mut out.spheres.spare_capacity_mut()[..total.spheres as usize],
        );
        let mut jobs = Vec::with_capacity(placed.len());
        for p in &placed {
            let a = p.arrays;
            let n;
            let l;
            let g;
            let i;
            let sp;
            (n, nodes) = std::mem::take(&mut nodes).split_at_mut(a.nodes.len());
            (l, leaves) = std::mem::take(&mut leaves).split_at_mut(a.leaves.len());
            (g, groups) = std::mem::take(&mut groups).split_at_mut(a.groups.len());
            (i, ids) = std::mem::take(&mut ids).split_at_mut(a.ids.len());
            (sp, spheres) = std::mem::take(&mut spheres).split_at_mut(a.spheres.len());
            jobs.push((p, n, l, g, i, sp));
        }
        jobs.into_par_iter().for_each(|(p, n, l, g, i, sp)| {
            let (a, base) = (p.arrays, p.base);
            for (dst, src) in n.iter_mut().zip(&a.nodes) {
                let mut node = *src;
                for c in node.child.iter_mut() {
                    *c = base.fix(*c, &p.pieces);
                }
                dst.write(node);
            }
            for (dst, src) in l.iter_mut().zip(&a.leaves) {
                dst.write(Leaf { group: src.group + base.groups, sphere: src.sphere + base.spheres, ..*src });
            }
            for (dst, src) in g.iter_mut().zip(&a.groups) {
                dst.write(*src);
            }
            for (dst, src) in i.iter_mut().zip(&a.ids) {
                dst.write(*src);
            }
            for (dst, src) in sp.iter_mut().zip(&a.spheres) {
                dst.write(*src);
            }
        });
    }
    // SAFETY: the jobs above wrote every element up to these lengths: the
    // pieces' slices tile `0..total` of each array exactly.
    unsafe {
        out.nodes.set_len(total.nodes as usize);
        out.leaves.set_len(total.leaves as usize);
        out.groups.set_len(total.groups as usize);
        out.ids.set_len(total.groups as usize * LANES);
        out.spheres.set_len(total.spheres as usize);
    }
    (out, code)
}
