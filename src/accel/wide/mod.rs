//! The native backend: a `W`-wide BVH (`W` = 4 or 8) built straight from
//! binned-SAH splits (`layout`), whose child boxes are tested all at once
//! (AVX2 for 8 boxes where the CPU has it; SSE2, part of every x86-64 CPU,
//! 4 boxes at a time otherwise), and leaves of triangles packed 4 to a group
//! and tested together.
//!
//! Two types: the tree's data (`Tree`: nodes, leaves, triangle groups) and
//! how it is traversed (`policy::Policy`: instruction sets, the way each
//! kind of batch goes, the any-hit child order), both fixed when the tree is
//! built. Every traversal walks the tree with one stack and its two steps,
//! push the entered children and cull on pop (`stack`):
//!
//! * single rays front to back (`single`), the walk the others fall back on;
//! * coherent batches as 16-ray frusta (`frustum`), their leaves tested for
//!   several rays at once (`leaf_rays`); shadow packets as swept boxes
//!   (`sweep`) or with a ray mask per node (`masked`), after the occluder
//!   cache (`occluders`);
//! * incoherent batches over trees too large for the caches (`cost`) with 12
//!   rays interleaved (`interleave`), or in streams with a ray mask per node
//!   where a batch's rays share their nodes (`hit_stream`, chosen by
//!   `stream_choice`; shadow rays: `stream`).
//!
//! The kernels are written once over the lane width (`lanes`: 4, 8 or 16
//! f32 lanes behind one trait): the slab test of a node's boxes
//! (`kernels`) and the watertight triangle test (`triangle`). The packet
//! traversals share their ray set-up and packet size from `packet`, which
//! imports none of them.
//!
//! Every lane performs exactly the scalar operations of `intersect_triangle`
//! and of a scalar slab test, in the same order, so answers are
//! bit-identical to the scalar code (and so to the brute-force oracle)
//! whatever the instruction set or way. Other targets run the scalar lane
//! loops, which give the same answers. Where the CPU has AVX-512VL, single
//! rays' walks run compiled with it as well (`avx_twins!`,
//! `policy::BoxIsa::Avx512Vl`).

/// A traversal entry point compiled twice over one body, for AVX2 and for
/// AVX2 with AVX-512VL (`BoxIsa::Avx512Vl`), and the function that calls
/// the one the policy chose: the kernels' intrinsics inline only into
/// functions built with their features, so each twin is the always-inlined
/// walk compiled for its instruction set. The documentation given goes on
/// the chooser, the attributes after the parameters on both twins; a
/// return type is written in brackets (`-> [Option<Hit>]`), which lets
/// the attributes follow it.
macro_rules! avx_twins {
    (
        $(#[$doc:meta])*
        fn $name:ident / $avx2:ident / $avx512vl:ident (&$self:ident $(, $a:ident: $t:ty)*) $(-> [$ret:ty])?
        $(#[$twin:meta])*
        $body:block
    ) => {
        $(#[$doc])*
        ///
        /// # Safety
        /// The policy must run the AVX2 kernels (`self.policy.avx()`).
        #[cfg(target_arch = "x86_64")]
        pub(super) unsafe fn $name(&$self $(, $a: $t)*) $(-> $ret)? {
            if $self.policy.avx512vl() {
                $self.$avx512vl($($a),*)
            } else {
                $self.$avx2($($a),*)
            }
        }

        #[doc = concat!("`", stringify!($name), "` compiled for AVX2, which the CPU must have.")]
        $(#[$twin])*
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2")]
        unsafe fn $avx2(&$self $(, $a: $t)*) $(-> $ret)? $body

        #[doc = concat!("`", stringify!($name), "` compiled for AVX2 and AVX-512VL: the CPU must have AVX-512F, VL, BW and DQ (`Policy::avx512vl`).")]
        $(#[$twin])*
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,avx512f,avx512vl,avx512bw,avx512dq")]
        unsafe fn $avx512vl(&$self $(, $a: $t)*) $(-> $ret)? $body
    };
}

mod cost;
mod frustum;
mod hit_stream;
mod interleave;
mod leaf_rays;
mod kernels;
#[cfg(target_arch = "x86_64")]
mod lanes;
mod layout;
mod masked;
mod occluders;
mod sweep;
mod packet;
mod policy;
mod sample;
mod single;
mod split_choice;
mod stack;
mod stream;
mod stream_choice;
mod triangle;

#[cfg(test)]
use policy::avx_available;
use policy::{ClosestBatches, EnteredPrefetch, Policy};
pub use policy::simd_level;
use stack::ChildOrder;
pub use split_choice::SplitOutcome;

use kernels::Slab;
use triangle::{intersect_group, LaneHit, Shear};
use stream::STREAM_MIN_BYTES;
use layout::Arrays;

use super::bvh::{prim_refs, BuildSet};
use super::prims::{self, Prim};
use super::{Hit, Traversal};
use crate::geometry::RayTransform;
use crate::ray::Ray;
use crate::scene::Shape;

/// Triangles per group: one SSE register.
const LANES: usize = 4;
/// The spatial-split budget `Splits::Auto` tries (extra references per
/// primitive): the one the measurements in `bvh::spatial` and
/// `split_choice` were made with.
const AUTO_SPLIT_BUDGET: f64 = 0.3;
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

/// Four triangles, SoA: `v[k][axis][lane]` is vertex k's coordinate, and
/// `ids[lane]` its triangle's (geometry id, primitive id), geometry `EMPTY`
/// for padding. The ids follow the vertices, as in Embree's `Triangle4v`:
/// a leaf's prefetch brings them with the vertices (see `prefetch`).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct TriGroup {
    v: [[[f32; LANES]; 3]; 3],
    ids: [[u32; 2]; LANES],
}

#[derive(Clone, Copy, Debug)]
struct Leaf {
    /// Triangle groups `groups[group..group+n_groups]`.
    group: u32,
    n_groups: u32,
    /// Spheres: `spheres[sphere..sphere+n_spheres]`.
    sphere: u32,
    n_spheres: u32,
}

/// The tree's data: what the build makes, and nothing of how it is
/// traversed (`policy`).
pub(super) struct Tree<const W: usize> {
    nodes: Vec<Node<W>>,
    leaves: Vec<Leaf>,
    groups: Vec<TriGroup>,
    spheres: Vec<Prim>,
    /// The root: a node, or a leaf when the scene is tiny.
    root: u32,
    /// The root's box.
    bounds: crate::geometry::Aabb,
    /// Half area of the root's box, for the SAH cost (computed on demand,
    /// see `sah`: it is a report, not part of the build).
    root_area: f64,
    /// Length of the root box's diagonal: the scale against which a
    /// batch's coherence is judged (`streams_pay`).
    root_diagonal: f32,
}

/// The native backend's tree and the way it is traversed (`policy`), both
/// fixed when it is built.
pub struct WideBvh<const W: usize> {
    tree: Tree<W>,
    policy: Policy,
    /// What the build did about spatial splits, and why.
    splits: SplitOutcome,
}

impl<const W: usize> WideBvh<W> {
    /// The tree over `shapes` with the default choices.
    pub fn build(shapes: &[Shape]) -> Self {
        Self::build_with(shapes, &super::NativeOptions::default())
    }

    /// The tree over `shapes` with spatial splits allowed to add up to
    /// `budget` references per primitive (0: object splits only).
    pub fn build_with_splits(shapes: &[Shape], budget: f64) -> Self {
        Self::build_with(shapes, &super::NativeOptions { splits: super::Splits::Budget(budget), ..Default::default() })
    }

    /// The tree over `shapes` with `options`' choices (instruction set,
    /// spatial splits, batch ways), fixed for its lifetime. With
    /// `Splits::Auto` the tree without spatial splits is built first and
    /// the one with them only where they could pay (`split_choice`).
    pub fn build_with(shapes: &[Shape], options: &super::NativeOptions) -> Self {
        assert!(W == 4 || W == 8, "WideBvh supports widths 4 and 8");
        let prims = prims::PrimTable::new(shapes);
        let budget = match options.splits {
            super::Splits::Budget(b) => {
                let b = b.clamp(0.0, 4.0);
                return Self::with_policy(Self::tree(&prims, b), &prims, options, SplitOutcome::Asked { budget: b });
            }
            super::Splits::Auto => AUTO_SPLIT_BUDGET,
        };
        let plain = Self::with_policy(Self::tree(&prims, 0.0), &prims, options, SplitOutcome::NotTried { expected_rays: 0, needed_rays: 0 });
        if options.expected_rays == 0 {
            return plain;
        }
        let sah = plain.sah();
        if let Some(needed_rays) = split_choice::beyond_reach(sah.nodes + sah.leaves, prims.len(), options.expected_rays) {
            return WideBvh { splits: SplitOutcome::NotTried { expected_rays: options.expected_rays, needed_rays }, ..plain };
        }
        let sample = plain.sample(&prims, sample::SAMPLE_RAYS, sample::Within::Uniform);
        let plain_work = plain.work(&sample);
        let needed_rays = split_choice::rays_to_repay(&plain_work, prims.len());
        if options.expected_rays < needed_rays {
            return WideBvh { splits: SplitOutcome::NotTried { expected_rays: options.expected_rays, needed_rays }, ..plain };
        }
        let split = Self::with_policy(Self::tree(&prims, budget), &prims, options, SplitOutcome::Asked { budget });
        let outcome = split_choice::judge(&plain_work, &split.work(&sample));
        if outcome.split() {
            WideBvh { splits: outcome, ..split }
        } else {
            WideBvh { splits: outcome, ..plain }
        }
    }

    /// The tree's data over `prims`, spatial splits adding up to `budget`
    /// references per primitive.
    fn tree(prims: &prims::PrimTable, budget: f64) -> Tree<W> {
        let spare = (prims.len() as f64 * budget) as usize;
        let mut refs = prim_refs(prims, spare);
        let mut out = Arrays::<W>::default();
        let (mut root, mut bounds) = (EMPTY, crate::geometry::Aabb::EMPTY);
        if let Some(set) = BuildSet::root(&mut refs, prims.len()) {
            bounds = set.bounds();
            let mut part = layout::Part::with_room_for(prims.len());
            let code = part.build(set, prims);
            (out, root) = layout::flatten(layout::Piece { part, root: code }, &refs, prims);
        }
        let root_area = if root == EMPTY { 0.0 } else { bounds.half_area() as f64 };
        Tree { nodes: out.nodes, leaves: out.leaves, groups: out.groups, spheres: out.spheres, root, bounds, root_area, root_diagonal: bounds.extent().length() }
    }

    /// `tree` with its policy under `options`, chosen from the tree through
    /// the traversals that need no policy of their own (scalar box tests).
    fn with_policy(tree: Tree<W>, prims: &prims::PrimTable, options: &super::NativeOptions, splits: SplitOutcome) -> Self {
        let mut b = WideBvh { tree, policy: Policy::PROVISIONAL, splits };
        b.policy = Policy::choose(&b, prims, options);
        b
    }

    /// The leaf a child code (with `LEAF_BIT`) stands for.
    #[inline(always)]
    fn leaf_of(&self, code: u32) -> Leaf {
        if code & INLINE_BIT != 0 {
            Leaf { group: code & INLINE_GROUP_LIMIT, n_groups: (code >> 28) & 3, sphere: 0, n_spheres: 0 }
        } else {
            self.tree.leaves[(code & !LEAF_BIT) as usize]
        }
    }

    /// Intersect a leaf; `visit(hit)` returns true to stop. Always inlined:
    /// out of line (the compiler's choice with `#[inline]`) it was compiled
    /// without AVX and cost a call per leaf. Inlined, 1 thread, random rays,
    /// three alternating runs: CBbunny 11.34-11.49 -> 11.84-12.23 Mrays/s
    /// (its leaves were 38 % of the profile), cow 9.62-9.72 -> 9.78-9.91,
    /// maxplanck and beetle within noise; camera and shadow rays unchanged.
    #[inline(always)]
    fn leaf<F: FnMut(Hit) -> bool>(&self, leaf: &Leaf, ray: &Ray, rt: &RayTransform, shear: &Shear, tmax: f32, visit: &mut F) -> bool {
        for gi in leaf.group..leaf.group + leaf.n_groups {
            let g = &self.tree.groups[gi as usize];
            let ids = &g.ids;
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
        for p in &self.tree.spheres[leaf.sphere as usize..(leaf.sphere + leaf.n_spheres) as usize] {
            if let Some((t, u, v)) = p.intersect(rt, ray.dir, ray.tmin, tmax) {
                if visit(p.hit(t, u, v)) {
                    return true;
                }
            }
        }
        false
    }

    /// Start loading child `code`'s node (all its cache lines) or an inline
    /// leaf's triangle groups (their ids with them) before the traversal
    /// needs them.
    #[inline(always)]
    fn prefetch(&self, code: u32) {
        #[cfg(target_arch = "x86_64")]
        unsafe {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            // A node's lines in straight-line code (its size is known); a
            // leaf's as many as its groups' size spans from their first
            // byte. Groups start 16-byte aligned, so a leaf's last line
            // (the tail of its last group's ids, read only on a hit) may be
            // left to load on demand: fetching it too cost the interleaved
            // batches 3-5 % (sphere 1M diffuse, grass).
            if code & LEAF_BIT == 0 {
                let ptr = self.tree.nodes.as_ptr().add(code as usize) as *const i8;
                for off in (0..std::mem::size_of::<Node<W>>()).step_by(64) {
                    _mm_prefetch::<_MM_HINT_T0>(ptr.add(off));
                }
            } else if code & INLINE_BIT != 0 {
                // An inline code decodes without a memory read (`leaf_of`).
                let leaf = self.leaf_of(code);
                let (first, n) = (leaf.group as usize, leaf.n_groups as usize);
                let ptr = self.tree.groups.as_ptr().add(first) as *const i8;
                let bytes = n * std::mem::size_of::<TriGroup>();
                let mut off = 0;
                while off < bytes {
                    _mm_prefetch::<_MM_HINT_T0>(ptr.add(off));
                    off += 64;
                }
            }
        }
    }

    /// `prefetch` of the children of `node` in `mask`, about to be entered
    /// (by a packet or stream, or by a single ray that enters one child
    /// alone): only in trees large enough to miss the caches
    /// (`Policy::prefetch`). The children's lines then arrive together,
    /// where each row would otherwise be loaded only once a box test needs it.
    #[inline(always)]
    fn prefetch_entered(&self, node: &Node<W>, mask: u32) {
        if self.policy.prefetch == EnteredPrefetch::Off {
            return;
        }
        let mut m = mask;
        while m != 0 {
            self.prefetch(node.child[m.trailing_zeros() as usize]);
            m &= m - 1;
        }
    }
}

impl<const W: usize> Traversal for WideBvh<W> {
    fn name(&self) -> &'static str {
        "native"
    }

    /// The SIMD kernels give `intersect_triangle`'s bits (unit-tested).
    fn exact_barycentrics(&self) -> bool {
        true
    }

    fn sah_cost(&self) -> Option<(f64, f64)> {
        let sah = self.sah();
        Some((sah.nodes, sah.leaves))
    }

    fn choices(&self) -> Option<String> {
        Some(format!("{}, {}", self.policy.describe(), self.splits.describe()))
    }

    fn describe(&self) -> String {
        let sah = self.sah();
        format!(
            "native ({W}-wide BVH, binned SAH, {}, {}, {} nodes, {} triangle groups of 4, {} leaf records, SAH cost {:.2} = nodes {:.2} + leaves {:.2})",
            self.policy.describe(),
            self.splits.describe(),
            self.tree.nodes.len(),
            self.tree.groups.len(),
            self.tree.leaves.len(),
            sah.nodes + sah.leaves,
            sah.nodes,
            sah.leaves
        )
    }

    fn memory_bytes(&self) -> usize {
        self.tree.nodes.len() * std::mem::size_of::<Node<W>>()
            + self.tree.leaves.len() * std::mem::size_of::<Leaf>()
            + self.tree.groups.len() * std::mem::size_of::<TriGroup>()
            + self.tree.spheres.len() * std::mem::size_of::<Prim>()
    }

    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        // Not through `intersect_batch`: one ray gains nothing from the
        // interleaved walkers and would pay for setting them up.
        self.closest_one_simd(ray)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.any_one_simd(ray)
    }

    fn intersect_batch(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), hits.len());
        #[cfg(target_arch = "x86_64")]
        if self.policy.avx() {
            // SAFETY: the policy has AVX2 box tests only where the CPU has AVX2.
            return unsafe {
                match self.policy.closest {
                    ClosestBatches::Streams => self.closest_streams(rays, hits),
                    ClosestBatches::StreamsWhereShared(otherwise) => self.closest_streams_where_shared(rays, hits, otherwise),
                    ClosestBatches::StreamsElseInterleaved if self.streams_pay(rays) => self.closest_streams(rays, hits),
                    ClosestBatches::Interleaved | ClosestBatches::StreamsElseInterleaved => self.closest_interleaved_avx(rays, hits),
                    ClosestBatches::Single => self.closest_batch_except(rays, hits, None),
                }
            };
        }
        self.closest_all::<false>(rays, hits)
    }

    fn occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len());
        // Where the tree streams its shadow rays (large trees whose rays miss
        // the caches), scattered ones stream too: one ray at a time, the
        // subdivided CBbunny's later-bounce shadow rays rendered 3 % slower.
        #[cfg(target_arch = "x86_64")]
        if self.policy.avx() && W == 8 && self.policy.shadows == policy::ShadowBatches::Streams {
            // SAFETY: the policy has AVX2 box tests only where the CPU has AVX2.
            return unsafe { self.any_streams(rays, out, self.policy.any_order) };
        }
        self.any_all_simd(rays, out)
    }

    fn intersect_coherent(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), hits.len());
        #[cfg(target_arch = "x86_64")]
        if self.policy.avx512() {
            // SAFETY: the policy has AVX-512 packets only where the CPU has AVX2 and AVX-512F.
            return unsafe { self.closest_coherent_avx512(rays, hits) };
        }
        #[cfg(target_arch = "x86_64")]
        if self.policy.avx() && W == 8 {
            // SAFETY: the policy has AVX2 box tests only where the CPU has AVX2.
            return unsafe { self.closest_coherent_avx(rays, hits) };
        }
        self.closest_all::<false>(rays, hits)
    }

    fn occluded_coherent(&self, rays: &[Ray], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len());
        #[cfg(target_arch = "x86_64")]
        if self.policy.avx512() {
            // SAFETY: as above.
            return unsafe { self.any_coherent_avx512(rays, out) };
        }
        #[cfg(target_arch = "x86_64")]
        if self.policy.avx() && W == 8 {
            // SAFETY: as above.
            return unsafe { self.any_coherent_avx(rays, out) };
        }
        self.any_all::<false>(rays, out)
    }
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod choice_tests;
