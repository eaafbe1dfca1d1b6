//! The native backend's fast layout: the binned-SAH binary tree collapsed
//! into a `W`-wide BVH (`W` = 4 or 8), whose child boxes are tested all at
//! once (AVX2 for 8 boxes where the CPU has it, chosen at run time; SSE2,
//! part of every x86-64 CPU, 4 boxes at a time otherwise), and leaves of
//! triangles packed 4 to a group and tested together.
//!
//! Traversal modes: single rays front to back, any-hit rays in the child
//! order a sample of their batch favours (`single`); coherent batches as
//! 16-ray frusta (`frustum`), their leaves tested for several rays at once
//! (`leaf_rays`); incoherent batches over large structures whose rays are
//! expected to miss the caches (`cost`) with 4 rays interleaved
//! (`interleave`).
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
//! whatever the instruction set. Other targets run the scalar lane loops,
//! which give the same answers.

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
mod single;
mod stream;
mod triangle;

use single::{pop_within, ChildOrder};

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
    /// Length of the root box's diagonal: the scale against which a
    /// batch's coherence is judged (`streams_pay`).
    root_diagonal: f32,
    /// Box tests with AVX2 (8 boxes per instruction): `W` = 8 on a CPU that
    /// has it, unless `PATHTRACER_NATIVE_ISA=sse` asks for the SSE2 path.
    avx: bool,
    /// Coherent packets with AVX-512 (16 rays per leaf box test, 4 rays per
    /// triangle group test); see `avx512_available`.
    avx512: bool,
    /// Trace incoherent batches several rays at a time (`interleave`): the
    /// structure is too large for the caches, so traversal waits on memory.
    interleave: bool,
    /// Packets prefetch the leaves (and masked packets the nodes) they are
    /// about to enter (`PACKET_PREFETCH_BYTES`).
    prefetch_packets: bool,
    /// Coherent occlusion batches go in streams (`stream`) rather than
    /// packets: the tree is large and its rays miss the caches (see
    /// `stream`), or the build options ask for streams (`ShadowWay`).
    stream_shadows: bool,
    /// How incoherent closest-hit batches go (`BatchWay`; `Auto` decides
    /// per batch).
    batch: super::BatchWay,
    /// The any-hit child order last chosen (`any_order`): 0 none yet, 1
    /// farthest first, 2 nearest first; and the batches that asked.
    any_order: std::sync::atomic::AtomicU8,
    order_calls: std::sync::atomic::AtomicU32,
    /// The work of the samples so far, farthest first and nearest first,
    /// each older sample's share decaying by `ORDER_DECAY`.
    order_work: [std::sync::atomic::AtomicU32; 2],
}

/// The SIMD level native traversal runs at on this CPU with `isa`: "AVX2",
/// "AVX2, AVX-512 packets" or "SSE2".
pub fn simd_level(isa: super::NativeIsa) -> &'static str {
    if avx512_available(isa) {
        "AVX2, AVX-512 packets"
    } else if avx_available_for(isa) {
        "AVX2"
    } else {
        "SSE2"
    }
}

/// Whether this CPU runs the AVX2 box test.
fn avx_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Whether a tree built with `isa` runs the AVX2 kernels.
fn avx_available_for(isa: super::NativeIsa) -> bool {
    isa != super::NativeIsa::Sse2 && avx_available()
}

/// A traversal's stack frame holder: a local of this type makes the
/// function realign its stack frame to a cache line, so where the compiler
/// spills the ray's broadcast slab vectors (32-byte AVX loads on every node
/// visit) does not depend on the callers' frames. Without it, the same
/// machine code ran random rays 20 % slower in one build than in another
/// (CBbunny 12.5 against 15.5 Mrays/s, 1 thread): its spills straddled
/// cache lines.
#[repr(C, align(64))]
pub(super) struct CacheAligned<T>(pub(super) T);

/// Structures at least this large have packets prefetch what they enter;
/// smaller ones stay in the caches, where the prefetches only cost issue
/// slots and fill buffers. Measured (1 thread, Mrays/s, camera / shadow,
/// prefetching against none, the same binary): on a 16-core Xeon
/// (Emerald Rapids) CBbunny (1.8 MiB) 32.8-33.1 / 16.5-16.8 against 34.2 /
/// 17.5, beetle 42.4-43.9 / 11.7 against 45.0 / 12.3, maxplanck (3.5 MiB)
/// 22.0-22.4 / 6.0-6.1 against 23.3 / 5.9; on this project's EPYC within
/// 2 % either way. But the 1M-triangle sphere (65 MiB) 18.1-18.7 / 3.5
/// against 14.7 / 2.6 and subdivided bunny (121 MiB) 18.5-18.9 / 3.3-3.5
/// against 16.8 / 3.1 need them. Single rays keep prefetching everywhere:
/// on small trees it is worth 3-6 % of random rays on the EPYC and on the
/// Xeon's maxplanck (CBbunny there: 3 % the other way).
const PACKET_PREFETCH_BYTES: usize = 16 << 20;

/// Whether to run the AVX-512 packet kernels: only when asked for
/// (`NativeIsa::Avx512Packets`, `PATHTRACER_NATIVE_ISA=avx512` on the
/// command line) and the CPU has AVX-512F. Not the
/// default, by measurement (1 thread, Mrays/s, AVX2 against AVX-512, three
/// runs each, medians): on this project's 2-core AMD EPYC (Zen 5) within
/// noise on every scene (cow camera 65.8/65.4, CBbunny shadow 22.3/23.0,
/// 1M sphere camera 29.1/29.0); on a 16-vCPU Intel Xeon the 1M
/// camera rays lost 30 % (18.9 against 13.2), likely the lower clock Intel
/// CPUs run AVX-512 code at.
fn avx512_available(isa: super::NativeIsa) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        isa == super::NativeIsa::Avx512Packets && avx_available() && is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

impl<const W: usize> WideBvh<W> {
    /// The tree over `shapes` with the default choices.
    pub fn build(shapes: &[Shape]) -> Self {
        Self::build_with(shapes, &super::NativeOptions::default())
    }

    /// The tree over `shapes` with spatial splits allowed to add up to
    /// `budget` references per primitive (0: object splits only).
    pub fn build_with_splits(shapes: &[Shape], budget: f64) -> Self {
        Self::build_with(shapes, &super::NativeOptions { split_budget: budget, ..Default::default() })
    }

    /// The tree over `shapes` with `options`' choices (instruction set,
    /// spatial-split budget, shadow-batch way), fixed for its lifetime.
    pub fn build_with(shapes: &[Shape], options: &super::NativeOptions) -> Self {
        let budget = options.split_budget.clamp(0.0, 4.0);
        assert!(W == 4 || W == 8, "WideBvh supports widths 4 and 8");
        let prims = prims::PrimTable::new(shapes);
        let spare = (prims.len() as f64 * budget) as usize;
        let mut refs = prim_refs(&prims, spare);
        let mut out = Arrays::<W>::default();
        let (mut root, mut root_area, mut root_diagonal) = (EMPTY, 0.0, 0.0);
        if let Some(set) = BuildSet::root(&mut refs, prims.len()) {
            root_area = set.half_area() as f64;
            root_diagonal = set.bounds().extent().length();
            let mut part = layout::Part::with_room_for(prims.len());
            let code = part.build(set, &prims);
            (out, root) = layout::flatten(layout::Piece { part, root: code }, &refs, &prims);
        }
        let mut b = WideBvh { nodes: out.nodes, leaves: out.leaves, groups: out.groups, ids: out.ids, spheres: out.spheres, root, root_area, root_diagonal, avx: W == 8 && avx_available_for(options.isa), avx512: W == 8 && avx512_available(options.isa), interleave: false, prefetch_packets: false, stream_shadows: false, batch: options.batch, any_order: Default::default(), order_calls: Default::default(), order_work: Default::default() };
        b.interleave = b.avx && b.interleave_pays();
        b.prefetch_packets = b.memory_bytes() >= PACKET_PREFETCH_BYTES;
        b.stream_shadows = b.avx
            && match options.shadow {
                super::ShadowWay::Auto => b.interleave && b.memory_bytes() >= STREAM_MIN_BYTES,
                super::ShadowWay::Streams => true,
                super::ShadowWay::Packets => false,
            };
        b
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

    /// Intersect a leaf; `visit(hit)` returns true to stop. Always inlined:
    /// out of line (the compiler's choice with `#[inline]`) it was compiled
    /// without AVX and cost a call per leaf. Inlined, 1 thread, random rays,
    /// three alternating runs: CBbunny 11.34-11.49 -> 11.84-12.23 Mrays/s
    /// (its leaves were 38 % of the profile), cow 9.62-9.72 -> 9.78-9.91,
    /// maxplanck and beetle within noise; camera and shadow rays unchanged.
    #[inline(always)]
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

    /// `prefetch` of the children of `node` in `mask`, for a packet about to
    /// enter them: only in trees large enough to miss the caches
    /// (`PACKET_PREFETCH_BYTES`).
    #[inline(always)]
    fn prefetch_for_packet(&self, node: &Node<W>, mask: u32) {
        if !self.prefetch_packets {
            return;
        }
        let mut m = mask;
        while m != 0 {
            self.prefetch(node.child[m.trailing_zeros() as usize]);
            m &= m - 1;
        }
    }
}

/// A running sum that keeps `decay.0 / decay.1` of what it held and adds
/// `sample`; returns the new sum. For the counted choice of any-hit child
/// order (`any_order`): concurrent samples may lose one
/// another's update, and only the speed depends on these sums, never an
/// answer.
#[inline(always)]
fn decayed_sum(w: &std::sync::atomic::AtomicU32, sample: u32, decay: (u32, u32)) -> u32 {
    use std::sync::atomic::Ordering::Relaxed;
    let v = (w.load(Relaxed) / decay.1 * decay.0).saturating_add(sample);
    w.store(v, Relaxed);
    v
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

    fn describe(&self) -> String {
        let sah = self.sah();
        format!(
            "native ({W}-wide BVH, binned SAH, {}, {} nodes, {} triangle groups of 4, {} leaf records, SAH cost {:.2} = nodes {:.2} + leaves {:.2})",
            if self.avx512 { "AVX2, AVX-512 packets" } else if self.avx { "AVX2" } else { "SSE2" },
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
        // Not through `intersect_batch`: one ray gains nothing from the
        // interleaved walkers and would pay for setting them up.
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
            use super::BatchWay;
            return unsafe {
                match self.batch {
                    BatchWay::Streams if W == 8 => self.closest_streams(rays, hits),
                    BatchWay::Auto if W == 8 && self.streams_pay(rays) => self.closest_streams(rays, hits),
                    BatchWay::Auto if self.interleave => self.closest_interleaved_avx(rays, hits),
                    BatchWay::Interleaved => self.closest_interleaved_avx(rays, hits),
                    _ => self.closest_all_avx(rays, hits),
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
        if self.avx512 {
            // SAFETY: `avx512` is only set when the CPU has AVX2 and AVX-512F.
            return unsafe { self.closest_coherent_avx512(rays, hits) };
        }
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
        if self.avx512 {
            // SAFETY: as above.
            return unsafe { self.any_coherent_avx512(rays, out) };
        }
        #[cfg(target_arch = "x86_64")]
        if self.avx && W == 8 {
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
