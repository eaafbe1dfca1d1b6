//! What a built tree costs a ray, read from its boxes' areas (the
//! probability that a ray through the root's box enters a box is the ratio
//! of their surface areas): the SAH cost, a report comparable with
//! Embree's statistics; and the cache lines a ray is expected to fetch
//! from outside the tree's most likely part, which decides whether
//! incoherent batches are traced interleaved (`interleave`).

use super::{Node, TriGroup, WideBvh, EMPTY, LEAF_BIT};

/// The two halves of the SAH cost: the node part depends on the width (an
/// 8-wide tree has about half the nodes of a 4-wide one), the leaf part on how
/// well the build grouped the primitives.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct SahCost {
    pub(super) nodes: f64,
    pub(super) leaves: f64,
}

/// Nodes per parallel chunk of `sah`'s sum.
const SAH_CHUNK: usize = 1 << 13;

impl<const W: usize> WideBvh<W> {
    /// SAH cost of the built tree, as Embree's BVH statistics (`verbose=2`)
    /// count it: expected node visits and expected 4-triangle group (or
    /// sphere) tests for a ray through the root's box, traversal and
    /// intersection costs both 1.
    ///
    /// Every node of the arrays is in the tree once, so the sum runs over
    /// the arrays in order, in parallel over fixed chunks (the same sum at
    /// any thread count), rather than down the tree: 11 ms of the 1.8M
    /// subdivided bunny's build walking it, 1.3 ms this way (2 threads).
    pub(super) fn sah(&self) -> SahCost {
        use rayon::prelude::*;
        let t = &self.tree;
        if t.root == EMPTY {
            return SahCost::default();
        }
        let root = t.root_area.max(f64::MIN_POSITIVE);
        if t.root & LEAF_BIT != 0 {
            let l = self.leaf_of(t.root);
            return SahCost { nodes: 0.0, leaves: (l.n_groups + l.n_spheres) as f64 };
        }
        let n = t.nodes.len();
        let parts: Vec<SahCost> = (0..n.div_ceil(SAH_CHUNK))
            .into_par_iter()
            .map(|k| {
                let mut cost = SahCost::default();
                for i in k * SAH_CHUNK..n.min((k + 1) * SAH_CHUNK) {
                    for (c, area) in self.child_areas(i as u32) {
                        if c & LEAF_BIT != 0 {
                            let l = self.leaf_of(c);
                            cost.leaves += area / root * (l.n_groups + l.n_spheres) as f64;
                        } else {
                            cost.nodes += area / root;
                        }
                    }
                }
                cost
            })
            .collect();
        // The root's own visit, then the chunks in order.
        parts.iter().fold(SahCost { nodes: 1.0, leaves: 0.0 }, |a, b| SahCost { nodes: a.nodes + b.nodes, leaves: a.leaves + b.leaves })
    }

    /// The children of node `code`: (child code, half area of its box).
    pub(super) fn child_areas(&self, code: u32) -> impl Iterator<Item = (u32, f64)> + '_ {
        let n = &self.tree.nodes[code as usize];
        (0..W).filter(move |&lane| n.child[lane] != EMPTY).map(move |lane| {
            let e = [0, 1, 2].map(|a| (n.bounds[3 + a][lane] - n.bounds[a][lane]).max(0.0) as f64);
            (n.child[lane], e[0] * e[1] + e[1] * e[2] + e[2] * e[0])
        })
    }

    /// Cache lines of a node or leaf `code` (a leaf's triangle groups).
    pub(super) fn cache_lines(&self, code: u32) -> usize {
        let bytes = if code & LEAF_BIT != 0 { self.leaf_of(code).n_groups as usize * std::mem::size_of::<TriGroup>() } else { std::mem::size_of::<Node<W>>() };
        bytes.div_ceil(64)
    }

    /// Expected cache lines a ray through the root box fetches (SAH
    /// probabilities: a box's area over the root's) from the nodes and
    /// leaves outside the `hot` most likely ones, which stay in the caches
    /// from ray to ray; and the estimate's standard error. An estimate,
    /// cheap next to the build: the `hot` most likely are found best first
    /// (a child is never likelier than its parent), which gives the
    /// probability below which an item is cold; the cold lines are then
    /// estimated from `DESCENTS` random root-to-leaf paths (a child picked
    /// in proportion to its probability, fixed seed). 1-3 ms on the 1M+
    /// bench scenes; walking the whole tree took 13 ms of arch 2M's 350 ms
    /// build and 29 ms of sphere 5M's 830 (and sorting every item, 35-60).
    pub(super) fn cold_lines(&self, hot: usize) -> (f64, f64) {
        const DESCENTS: usize = 2048;
        if self.tree.root == EMPTY || self.tree.root & LEAF_BIT != 0 {
            return (0.0, 0.0);
        }
        let root = self.tree.root_area.max(f64::MIN_POSITIVE);
        // A node's children: (code, probability).
        let children = |code: u32| self.child_areas(code).map(move |(c, area)| (c, area / root));
        // Best first: the probability of the `hot`-th most likely item.
        // Heap entries pack the probability (as f32, whose bits order as
        // the non-negative values do) above the child code.
        let key = |p: f64, code: u32| ((p as f32).to_bits() as u64) << 32 | code as u64;
        let mut heap = std::collections::BinaryHeap::from([key(1.0, self.tree.root)]);
        let mut p_hot = f64::INFINITY;
        for _ in 0..hot {
            let Some(top) = heap.pop() else {
                return (0.0, 0.0); // everything fits
            };
            let code = top as u32;
            p_hot = f32::from_bits((top >> 32) as u32) as f64;
            if code & LEAF_BIT == 0 {
                heap.extend(children(code).map(|(c, p)| key(p, c)));
            }
        }
        // Random descents: at each node the path goes on into child c with
        // chance p_c / Σ p, so Σ p times the chosen child's term is an
        // unbiased estimate of the children's terms together.
        let mut rng = crate::rng::Rng::new(0xC01D, 0);
        let (mut total, mut squares) = (0.0, 0.0);
        for _ in 0..DESCENTS {
            let (mut code, mut weight, mut p, mut path) = (self.tree.root, 1.0f64, 1.0f64, 0.0);
            loop {
                if (p as f32 as f64) < p_hot {
                    path += weight * self.cache_lines(code) as f64;
                }
                if code & LEAF_BIT != 0 {
                    break;
                }
                let mut kids = [(EMPTY, 0.0); W];
                let mut count = 0;
                for kid in children(code) {
                    kids[count] = kid;
                    count += 1;
                }
                let sum: f64 = kids[..count].iter().map(|&(_, p)| p).sum();
                if sum <= 0.0 || p <= 0.0 {
                    break;
                }
                let mut pick = rng.uniform() as f64 * sum;
                let (mut next, mut next_p) = (EMPTY, 0.0);
                for &(c, pc) in &kids[..count] {
                    (next, next_p) = (c, pc);
                    if pick < pc {
                        break;
                    }
                    pick -= pc;
                }
                // A child's term is p_c times its lines; divided by the
                // chance p_c / Σ p of picking it, Σ p times its lines. The
                // weight carries that factor relative to the parent's own
                // probability down the path.
                weight *= sum / p;
                (code, p) = (next, next_p);
            }
            total += path;
            squares += path * path;
        }
        let n = DESCENTS as f64;
        let mean = total / n;
        (mean, ((squares / n - mean * mean).max(0.0) / (n - 1.0)).sqrt())
    }
}
