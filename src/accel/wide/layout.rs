//! Laying the binary SAH tree out as the W-wide arrays traversal reads:
//! nodes depth first, triangle groups in leaf order, large subtrees in
//! parallel and appended in order, so the layout never depends on threads.

use super::{Leaf, Node, TriGroup, EMPTY, INLINE_BIT, INLINE_GROUP_LIMIT, LANES, LEAF_BIT};
use crate::accel::bvh::BuildNode;
use crate::accel::prims::Prim;
use crate::geometry::Aabb;
use rayon::prelude::*;

/// The arrays of a tree being laid out.
pub(super) struct Arrays<const W: usize> {
    pub(super) nodes: Vec<Node<W>>,
    pub(super) leaves: Vec<Leaf>,
    pub(super) groups: Vec<TriGroup>,
    pub(super) ids: Vec<[u32; 2]>,
    pub(super) spheres: Vec<Prim>,
}

impl<const W: usize> Default for Arrays<W> {
    fn default() -> Self {
        Arrays { nodes: Vec::new(), leaves: Vec::new(), groups: Vec::new(), ids: Vec::new(), spheres: Vec::new() }
    }
}

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
    pub(super) fn with_room_for(prims: usize) -> Self {
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
    pub(super) fn emit_parallel(&mut self, node: &BuildNode, prims: &[Prim], order: &[u32]) -> u32 {
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
