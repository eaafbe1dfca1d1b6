//! How a wide BVH is traversed: the instruction sets its kernels run, the
//! way each kind of batch goes and the child order of any-hit rays. All of
//! it is fixed when the tree is built ([`Policy::choose`]), from the build
//! options, the CPU and the tree itself, and never changes afterwards: the
//! same batch always takes the same way, whatever ran before it. Only the
//! way a closest-hit batch goes may depend on the batch (`ClosestBatches`'
//! `StreamsWhereShared` and `StreamsElseInterleaved`), and then on
//! nothing but the batch's own rays.
//! No choice changes an answer (every way gives the scalar code's bits).

use super::interleave::InterleaveReach;
use super::stack::ChildOrder;
use super::WideBvh;
use crate::accel::{BatchWay, NativeIsa, NativeOptions, ShadowWay, Traversal};

/// The instruction set of the box and triangle tests.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum BoxIsa {
    /// 4 boxes per instruction (two instructions for 8): part of every
    /// x86-64 CPU, and the scalar lane loops elsewhere.
    Sse2,
    /// 8 boxes per instruction: `W` = 8 on a CPU that has AVX2, unless the
    /// options ask for SSE2.
    Avx2,
    /// `Avx2`'s kernels, and single rays' walks compiled with AVX-512VL as
    /// well: the same 256-bit vectors and operations, with 32 vector
    /// registers and compares into mask registers; on a CPU that has
    /// AVX-512F, VL, BW and DQ, unless the options ask for AVX2. No 512-bit
    /// register is used, so no clock is lowered for it. Single rays, 1
    /// thread, one process alternating the two (a 2-vCPU Intel Xeon with
    /// AVX-512, 2026-12-02), this ÷ AVX2, random / diffuse: 1.005–1.036 / 1.003–1.027
    /// on the nine bench scenes, never below; the interleaved walkers and
    /// closest-hit streams compiled so read 0.985–1.025, and stay AVX2
    /// (`docs/notes/2026-12-02-avx512vl-walks.md`).
    Avx512Vl,
}

/// The kernels of coherent packets (`frustum`, `leaf_rays`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum PacketIsa {
    Avx2,
    /// 16 rays per leaf box test, 4 rays per triangle group test; only when
    /// asked for (see `avx512_available`).
    Avx512,
}

/// How incoherent closest-hit batches (`intersect_batch`) go.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ClosestBatches {
    /// One ray at a time.
    Single,
    /// Several rays at a time (`interleave`): the tree is too large for
    /// the caches, so traversal waits on memory.
    Interleaved,
    /// In streams (`hit_stream`).
    Streams,
    /// In streams where the batch's first full stream shows its rays
    /// sharing the nodes (`closest_streams_where_shared`), else the way
    /// `Unshared` says.
    StreamsWhereShared(Unshared),
    /// In streams where the batch's own rays start close together, else
    /// interleaved: a tree of middling size whose incoherent rays miss
    /// the nearer caches (`interleave_reach`).
    StreamsElseInterleaved,
}

/// How a closest-hit batch goes whose first stream's rays did not share
/// its nodes (`ClosestBatches::StreamsWhereShared`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Unshared {
    /// One ray at a time: the tree stays in the caches. A batch whose rays
    /// start far apart tries a first stream only as `Scattered` says; one
    /// whose rays do not, as `Gathered` says.
    Single(Scattered, Gathered),
    /// Interleaved: the tree is too large for the caches
    /// (`InterleaveReach::All`).
    Interleaved,
}

/// Whether a closest-hit batch whose rays start far apart from one another
/// (`WideBvh::origins_scattered`) tries a first stream, on a tree that
/// stays in the caches; chosen when the tree is built
/// (`WideBvh::scattered_batches`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Scattered {
    /// It does: streams of rays from anywhere in the tree's box came near
    /// to paying there.
    TryStream,
    /// It goes one ray at a time: such streams fell well short, and the
    /// first stream would be refused after costing its rays twice over.
    Single,
}

/// Whether a closest-hit batch whose rays do not start far apart (a
/// tile's bounce rays) streams without trying a first stream, on a tree
/// that stays in the caches; chosen when the tree is built
/// (`WideBvh::gathered_batches`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Gathered {
    /// It streams untried: the tree is small, and such streams almost
    /// always shared there.
    Streams,
    /// It tries a first stream: the tree is large, and a third of a tile's
    /// streams shared too little to pay.
    TryStream,
}

/// How coherent occlusion batches (`occluded_coherent`) go.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ShadowBatches {
    /// 16-ray packets (`frustum`, `sweep`, `masked`).
    Packets,
    /// Streams (`stream`): the tree is large and its rays miss the caches,
    /// or the options ask for streams.
    Streams,
}

/// Whether packets prefetch the leaves (and masked packets the nodes) they
/// are about to enter, and single rays the one child they enter alone.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum EnteredPrefetch {
    Off,
    /// Trees of at least `ENTERED_PREFETCH_BYTES`.
    On,
}

/// A tree's traversal choices; see the module's documentation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Policy {
    pub(super) boxes: BoxIsa,
    pub(super) packets: PacketIsa,
    pub(super) closest: ClosestBatches,
    pub(super) shadows: ShadowBatches,
    pub(super) prefetch: EnteredPrefetch,
    /// The child order of any-hit traversals (`ChildOrder`), chosen from a
    /// sample of shadow-like rays over the tree's own triangles
    /// (`single::any_order_of`).
    pub(super) any_order: ChildOrder,
}

/// Structures at least this large have packets prefetch what they enter;
/// smaller ones stay in the caches, where the prefetches only cost issue
/// slots and fill buffers. Measured (1 thread, Mrays/s, camera / shadow,
/// prefetching against none, the same binary): on a 16-core Xeon
/// (Emerald Rapids) CBbunny (1.8 MiB) 32.8-33.1 / 16.5-16.8 against 34.2 /
/// 17.5, beetle 42.4-43.9 / 11.7 against 45.0 / 12.3, maxplanck (3.5 MiB)
/// 22.0-22.4 / 6.0-6.1 against 23.3 / 5.9; on a 2-vCPU AMD EPYC within
/// 2 % either way. But the 1M-triangle sphere (65 MiB) 18.1-18.7 / 3.5
/// against 14.7 / 2.6 and subdivided bunny (121 MiB) 18.5-18.9 / 3.3-3.5
/// against 16.8 / 3.1 need them. Single rays keep prefetching the children
/// they push everywhere: on small trees it is worth 3-6 % of random rays
/// on the EPYC and on the Xeon's maxplanck (CBbunny there: 3 % the other
/// way). The one child a single ray enters alone is prefetched only here:
/// single rays, native ÷ Embree 4, 1 thread, six runs each on a Zen 3
/// EPYC, without / with: sphere 5M random 0.70-0.90 / 0.87-1.01, diffuse
/// 0.94-1.07 / 1.03-1.23; sphere 1M, grass 2M, arch 2M and the
/// subdivided bunny within their spread; on cow (everywhere) the random
/// batch lost up to a sixth.
const ENTERED_PREFETCH_BYTES: usize = 16 << 20;

impl Policy {
    /// What a tree holds while its policy is being chosen: the scalar
    /// traversals only, which is all `choose` runs.
    pub(super) const PROVISIONAL: Policy = Policy {
        boxes: BoxIsa::Sse2,
        packets: PacketIsa::Avx2,
        closest: ClosestBatches::Single,
        shadows: ShadowBatches::Packets,
        prefetch: EnteredPrefetch::Off,
        any_order: ChildOrder::FarthestFirst,
    };

    /// The policy for a freshly built `tree` (whose own policy is not read)
    /// over the scene's `prims` under `options` on this CPU.
    pub(super) fn choose<const W: usize>(tree: &WideBvh<W>, prims: &crate::accel::prims::PrimTable, options: &NativeOptions) -> Policy {
        let avx = W == 8 && avx_available_for(options.isa);
        let boxes = match (avx, avx512vl_available(options.isa)) {
            (true, true) => BoxIsa::Avx512Vl,
            (true, false) => BoxIsa::Avx2,
            (false, _) => BoxIsa::Sse2,
        };
        let packets = if W == 8 && avx512_available(options.isa) { PacketIsa::Avx512 } else { PacketIsa::Avx2 };
        let reach = if avx { tree.interleave_reach() } else { InterleaveReach::None };
        let interleave = reach == InterleaveReach::All;
        // `avx` implies `W` = 8, which streams need.
        let streams = avx;
        let closest = match options.batch {
            // Where the tree is large enough to interleave, a batch streams
            // only where its first stream shares more than elsewhere
            // (`stream_choice::SHARED_OVER_INTERLEAVED`): twelve interleaved
            // walkers, each prefetching the node it enters next, overlap
            // the misses a stream would share.
            BatchWay::Auto if interleave => ClosestBatches::StreamsWhereShared(Unshared::Interleaved),
            BatchWay::Auto if reach == InterleaveReach::Incoherent => ClosestBatches::StreamsElseInterleaved,
            // SAFETY: `streams` implies AVX2.
            BatchWay::Auto if streams => ClosestBatches::StreamsWhereShared(Unshared::Single(unsafe { tree.scattered_batches() }, tree.gathered_batches())),
            BatchWay::Streams if streams => ClosestBatches::Streams,
            BatchWay::Interleaved if avx => ClosestBatches::Interleaved,
            _ => ClosestBatches::Single,
        };
        let stream_shadows = avx
            && match options.shadow {
                ShadowWay::Auto => interleave && tree.memory_bytes() >= super::STREAM_MIN_BYTES,
                ShadowWay::Streams => true,
                ShadowWay::Packets => false,
            };
        Policy {
            boxes,
            packets,
            closest,
            shadows: if stream_shadows { ShadowBatches::Streams } else { ShadowBatches::Packets },
            prefetch: if tree.memory_bytes() >= ENTERED_PREFETCH_BYTES { EnteredPrefetch::On } else { EnteredPrefetch::Off },
            any_order: tree.any_order_of(prims),
        }
    }

    /// Whether the AVX2 kernels run (the CPU has AVX2: `unsafe` AVX2 code
    /// may be called when this is true).
    #[inline(always)]
    pub(super) fn avx(&self) -> bool {
        matches!(self.boxes, BoxIsa::Avx2 | BoxIsa::Avx512Vl)
    }

    /// Whether single rays' walks run compiled with AVX-512VL (the CPU has
    /// AVX2 and AVX-512F, VL, BW and DQ).
    #[inline(always)]
    pub(super) fn avx512vl(&self) -> bool {
        self.boxes == BoxIsa::Avx512Vl
    }

    /// Whether the AVX-512 packet kernels run (the CPU has AVX-512F).
    #[inline(always)]
    pub(super) fn avx512(&self) -> bool {
        self.avx() && self.packets == PacketIsa::Avx512
    }

    /// The policy's words for a tree's summary line: "AVX2, closest hits
    /// interleaved, shadow packets, any hit farthest first".
    pub(super) fn describe(&self) -> String {
        let isa = isa_words(self.avx(), self.avx512vl(), self.avx512());
        let closest = match self.closest {
            ClosestBatches::Single => "closest hits one by one",
            ClosestBatches::Interleaved => "closest hits interleaved",
            ClosestBatches::Streams => "closest-hit streams",
            ClosestBatches::StreamsWhereShared(Unshared::Single(Scattered::TryStream, Gathered::Streams)) => "closest-hit streams, scattered batches where shared",
            ClosestBatches::StreamsWhereShared(Unshared::Single(Scattered::Single, Gathered::Streams)) => "closest-hit streams, scattered batches one by one",
            ClosestBatches::StreamsWhereShared(Unshared::Single(Scattered::TryStream, Gathered::TryStream)) => "closest-hit streams where shared",
            ClosestBatches::StreamsWhereShared(Unshared::Single(Scattered::Single, Gathered::TryStream)) => "closest-hit streams where shared, scattered batches one by one",
            ClosestBatches::StreamsWhereShared(Unshared::Interleaved) => "closest-hit streams where shared, else interleaved",
            ClosestBatches::StreamsElseInterleaved => "closest-hit streams where coherent, else interleaved",
        };
        let shadows = match self.shadows {
            ShadowBatches::Packets => "shadow packets",
            ShadowBatches::Streams => "shadow streams",
        };
        let order = match self.any_order {
            ChildOrder::FarthestFirst => "any hit farthest first",
            ChildOrder::NearestFirst => "any hit nearest first",
        };
        format!("{isa}, {closest}, {shadows}, {order}")
    }
}

/// The SIMD level native traversal runs at on this CPU with `isa`: "AVX2",
/// "AVX2, AVX-512VL single rays", "AVX2, AVX-512VL single rays, AVX-512
/// packets" or "SSE2".
pub fn simd_level(isa: NativeIsa) -> &'static str {
    isa_words(avx_available_for(isa), avx512vl_available(isa), avx512_available(isa))
}

/// The words for the kernels in use, as `simd_level` and the summary line say them.
fn isa_words(avx: bool, avx512vl: bool, avx512: bool) -> &'static str {
    match (avx, avx512vl, avx512) {
        (true, true, true) => "AVX2, AVX-512VL single rays, AVX-512 packets",
        (true, false, true) => "AVX2, AVX-512 packets",
        (true, true, false) => "AVX2, AVX-512VL single rays",
        (true, false, false) => "AVX2",
        (false, _, _) => "SSE2",
    }
}

/// Whether this CPU runs the AVX2 box test.
pub(super) fn avx_available() -> bool {
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
fn avx_available_for(isa: NativeIsa) -> bool {
    isa != NativeIsa::Sse2 && avx_available()
}

/// Whether a tree built with `isa` compiles single rays' walks with
/// AVX-512VL (`BoxIsa::Avx512Vl`): unless AVX2 or SSE2 is asked for, where
/// the CPU has AVX-512F, VL, BW and DQ (every AVX-512 CPU since Skylake-SP,
/// and AMD's Zen 4 and 5).
fn avx512vl_available(isa: NativeIsa) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        isa != NativeIsa::Avx2
            && avx_available_for(isa)
            && is_x86_feature_detected!("avx512f")
            && is_x86_feature_detected!("avx512vl")
            && is_x86_feature_detected!("avx512bw")
            && is_x86_feature_detected!("avx512dq")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = isa;
        false
    }
}

/// Whether to run the AVX-512 packet kernels: only when asked for
/// (`NativeIsa::Avx512Packets`, `PATHTRACER_NATIVE_ISA=avx512` on the
/// command line) and the CPU has AVX-512F. Not the
/// default, by measurement (1 thread, Mrays/s, AVX2 against AVX-512, three
/// runs each, medians): on a 2-vCPU AMD EPYC (Zen 5) within
/// noise on every scene (cow camera 65.8/65.4, CBbunny shadow 22.3/23.0,
/// 1M sphere camera 29.1/29.0); on a 16-vCPU Intel Xeon the 1M
/// camera rays lost 30 % (18.9 against 13.2), likely the lower clock Intel
/// CPUs run AVX-512 code at.
fn avx512_available(isa: NativeIsa) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        isa == NativeIsa::Avx512Packets && avx_available() && is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
