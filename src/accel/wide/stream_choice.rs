//! Which incoherent closest-hit batches go in streams (`hit_stream`), and
//! which go one ray at a time or interleaved, decided from the tree (when it
//! is built) and from the batch's own rays, never from a timer, so the same
//! batch always takes the same way:
//!
//! * on trees that stay in the caches and are smaller than 16 MiB, a batch
//!   whose rays do not start far apart streams without a trial
//!   (`Gathered::Streams`);
//! * a batch traces its first full stream (64 rays of one octant) and goes
//!   on in streams where those rays shared the nodes they fetched
//!   (`closest_streams_where_shared`), else one ray at a time, or
//!   interleaved on trees too large for the caches, where the stream must
//!   share more to pay;
//! * on trees too large for the caches, only a batch whose origins lie
//!   close together tries that first stream (`streams_pay`); on trees of
//!   middling size whose rays miss the nearer caches, such a batch streams
//!   without trying, the rest interleave;
//! * on trees that stay in the caches, a batch whose rays start far apart
//!   (`origins_scattered`) tries no first stream where streams of rays
//!   from anywhere in the tree's box fell well short when it was built
//!   (`scattered_batches`), or where the tree is large
//!   (`SCATTERED_ALONE_BYTES`).
//!
//! No way changes an answer (each gives the single-ray walk's hits).

use super::hit_stream::StreamWork;
use super::policy::{Gathered, Scattered, Unshared};
use super::stream::{octant_streams_until, FirstStream, STREAM};
use super::{WideBvh, EMPTY, LEAF_BIT};
use crate::accel::Hit;
use crate::ray::Ray;

/// Batches of fewer rays never stream: a stream of one octant's few rays
/// shares little.
pub(super) const STREAM_MIN_RAYS: usize = 128;

/// A batch streams when the mean distance between consecutive rays'
/// origins is under this share of the tree's diagonal: its rays start
/// close together, so streams of them share their nodes.
pub(super) const COHERENT_STEP: f32 = 1.0 / 32.0;

/// A batch goes on in streams where its first full stream made at least
/// `SHARED.0 / SHARED.1` ray-node tests per node fetched: its rays shared
/// the nodes, where a stream pays for its bookkeeping. Measured on a Zen 3
/// EPYC (tests per fetch: streams ÷ one ray at a time, 1 thread), random
/// rays: CBbunny 5.70: 1.13, arch:2M 5.78: 1.11, beetle 2.78: 1.02, cow
/// 2.68: 0.88, maxplanck 2.06: 0.89; diffuse rays in 32x32 tiles: arch:2M
/// 3.87: 0.89, CBbunny 8.08: 1.13, stadium:2M 11.9: 1.22, maxplanck 12.7:
/// 1.32, beetle 13.8: 1.25, cow 23.7: 1.26.
const SHARED: (u64, u64) = (9, 2);

/// Where the batch's other way is interleaving (trees too large for the
/// caches), which already overlaps the misses a stream would share, the
/// first stream must make at least 6 tests per fetch. Diffuse rays in
/// 32x32 tiles, 1 thread, native ÷ Embree 4 (Zen 3 EPYC), interleaved /
/// this rule at 4.5, 6 and 8 tests per fetch: sphere 1M 0.92 / 1.17 /
/// 1.15 / 1.09 (its first streams made 3-19 tests per fetch), sphere 5M
/// 1.21 / 1.12 / 1.18 / 1.18 (2-6), subdivided bunny 1.5M 1.05 / 1.14 /
/// 1.12 / 1.13 (2-52); grass 2M's diffuse streams (3-4) and every random
/// stream (1.1-2.2) go interleaved at any of these. Random batches do not
/// try a stream there (`streams_pay`): tried on each, the first stream
/// cost sphere 5M's random rays 5-11 %.
const SHARED_OVER_INTERLEAVED: (u64, u64) = (6, 1);

/// A batch's rays start far apart when the mean distance between
/// consecutive origins, over its first `SCATTER_STEPS` steps, is at least
/// this share of the tree's diagonal. Rays from anywhere in a box step
/// about 0.4 of its diagonal; a tile's bounce rays a small fraction.
const SCATTERED_STEP: f32 = 1.0 / 8.0;

/// Steps between origins read to judge a batch scattered: a pass over the
/// whole batch cost 3 % of cow's random batches.
const SCATTER_STEPS: usize = 64;

/// Rays of the tree's sample that decides whether scattered batches try a
/// first stream (`scattered_batches`).
const SCATTER_SAMPLE: usize = 2048;

/// Scattered batches try a first stream on trees where streams of rays
/// from anywhere in the box made at least 3/4 of `SHARED`'s tests per
/// fetch. Measured from 2048 such rays (tests per fetch): CBbunny 5.79,
/// arch:2M 5.76, where random batches stream for 11-13 %; beetle 2.81, cow
/// 2.66, stadium:2M 2.50, maxplanck 2.06, whose random batches' first
/// streams are always refused (the probe cost cow's random batches 2.6 %
/// against one ray at a time, in one process). The same rays' streams read
/// within 5 % at 512 and 8192 rays but on arch (6.82 at 512).
const SCATTERED_MAY_SHARE: (u64, u64) = (27, 8);

/// Trees from this size on whose rays stay in the caches (else they would
/// interleave: `interleave_reach`) trace scattered batches one ray at a
/// time: a stream's shared fetches hit the caches there too, and buy less
/// than its bookkeeping costs. The architecture scene's streams of random
/// rays share as CBbunny's do (5.8 tests per fetch), yet in the bench
/// (`pathtracer bench arch:2M arch:10M stadium:2M --backends
/// native,embree4 --no-peers --no-render --throughput-only --threads 1`,
/// 2-vCPU AMD EPYC, Zen 3, two runs of each binary, native ÷ Embree 4)
/// its random batches read 0.97-0.99 (2M) and 0.97-0.98 (10M) trying a
/// first stream, 1.04-1.05 and 1.03-1.04 one ray at a time; diffuse
/// batches and the stadium (whose sample already said one at a time)
/// unchanged.
const SCATTERED_ALONE_BYTES: usize = super::interleave::INTERLEAVE_BYTES;

/// How a closest-hit batch starts (`WideBvh::batch_start`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum BatchStart {
    /// All of it in streams, untried.
    Streams,
    /// Its first full stream (the rays, their octant) is traced, and
    /// decides how the rest go.
    TryFirst([u32; STREAM], usize),
    /// No stream: the whole batch goes the way `Unshared` says.
    Unshared,
}

impl StreamWork {
    /// Whether the stream's rays shared its nodes enough to go on in
    /// streams rather than the way `otherwise` says (`SHARED`,
    /// `SHARED_OVER_INTERLEAVED`).
    pub(super) fn shared(&self, otherwise: Unshared) -> bool {
        self.tests_per_fetch_at_least(match otherwise {
            Unshared::Single(..) => SHARED,
            Unshared::Interleaved => SHARED_OVER_INTERLEAVED,
        })
    }

    /// Whether the stream made at least `num / den` ray-node tests per
    /// node fetched.
    fn tests_per_fetch_at_least(&self, (num, den): (u64, u64)) -> bool {
        self.tests * den >= self.nodes * num
    }
}

/// The batch's first stream to fill (`STREAM` valid rays of one octant, in
/// batch order), as `octant_streams` would trace it first, and its octant.
fn first_full_stream(rays: &[Ray]) -> Option<([u32; STREAM], usize)> {
    // Full streams are traced before any octant's rest: a first stream
    // shorter than `STREAM` means the batch has none.
    let mut first = None;
    octant_streams_until(rays, |_, _| false, |which, oct| {
        first = which.try_into().ok().map(|w: [u32; STREAM]| (w, oct));
        false
    });
    first
}

/// The distances between consecutive valid rays' origins in `rays`, summed,
/// and how many were summed, stopping as soon as `enough(sum, steps)`.
fn origin_steps(rays: &[Ray], mut enough: impl FnMut(f32, usize) -> bool) -> (f32, usize) {
    let (mut sum, mut steps) = (0.0f32, 0usize);
    let mut prev: Option<glam::Vec3> = None;
    for r in rays.iter().filter(|r| r.is_valid()) {
        if let Some(p) = prev {
            sum += (r.origin - p).length();
            steps += 1;
            if enough(sum, steps) {
                break;
            }
        }
        prev = Some(r.origin);
    }
    (sum, steps)
}

impl<const W: usize> WideBvh<W> {
    /// Whether `rays` go in streams (`closest_streams`) rather than one at
    /// a time: decided from the batch alone (so the same batch always
    /// takes the same way), by how far apart consecutive rays start.
    pub(super) fn streams_pay(&self, rays: &[Ray]) -> bool {
        if rays.len() < STREAM_MIN_RAYS {
            return false;
        }
        // A batch of n rays has at most n - 1 steps: once the sum reaches
        // what they may add up to, no rest of the batch can bring the mean
        // under the bar (a scattered batch stops after about 1/16 of it).
        let limit = (rays.len() - 1) as f32 * COHERENT_STEP * self.tree.root_diagonal;
        let (sum, steps) = origin_steps(rays, |sum, _| sum >= limit);
        steps >= STREAM_MIN_RAYS && sum < steps as f32 * COHERENT_STEP * self.tree.root_diagonal
    }

    /// Whether the rays of a batch start far apart (`SCATTERED_STEP`),
    /// judged from its first valid rays alone.
    pub(super) fn origins_scattered(&self, rays: &[Ray]) -> bool {
        let (sum, steps) = origin_steps(rays, |_, steps| steps == SCATTER_STEPS);
        steps > 0 && sum >= steps as f32 * SCATTERED_STEP * self.tree.root_diagonal
    }

    /// Whether scattered batches try a first stream on this tree
    /// (`SCATTERED_MAY_SHARE`): counted over streams of `SCATTER_SAMPLE`
    /// rays from anywhere in the tree's box (as the benchmark's random
    /// rays), fixed seed, so the same tree always decides the same. Not on
    /// a tree of `SCATTERED_ALONE_BYTES` or more, whatever its sample says.
    ///
    /// # Safety
    /// The CPU must have AVX2; `W` must be 8.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn scattered_batches(&self) -> Scattered {
        use super::Traversal;
        if self.tree.root & LEAF_BIT != 0 || self.tree.root == EMPTY || self.memory_bytes() >= SCATTERED_ALONE_BYTES {
            return Scattered::Single;
        }
        let rays = crate::accel::workloads::random_rays_in(&self.tree.bounds, SCATTER_SAMPLE, 0x5CA7);
        let mut hits = vec![None; rays.len()];
        let mut work = StreamWork::default();
        octant_streams_until(&rays, |_, _| false, |which, oct| {
            if which.len() == STREAM {
                self.closest_stream(&rays, which, oct, &mut hits, &mut work);
            }
            true
        });
        if work.tests_per_fetch_at_least(SCATTERED_MAY_SHARE) {
            Scattered::TryStream
        } else {
            Scattered::Single
        }
    }

    /// `hits[i]` = the closest hit of `rays[i]`: as `batch_start` says, all
    /// in streams, or the batch's first full stream is traced as a stream
    /// and the rest go in streams too where that stream's rays shared its
    /// nodes (`StreamWork::shared`), else as `otherwise` says. The way
    /// depends on the batch alone.
    ///
    /// # Safety
    /// As `closest_streams`.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn closest_streams_where_shared(&self, rays: &[Ray], hits: &mut [Option<Hit>], otherwise: Unshared) {
        debug_assert!(W == 8);
        let (which, oct) = match self.batch_start(rays, otherwise) {
            BatchStart::Streams => return self.closest_streams(rays, hits),
            BatchStart::Unshared => return self.closest_unshared(rays, hits, otherwise, None),
            BatchStart::TryFirst(which, oct) => (which, oct),
        };
        hits.fill(None);
        let mut work = StreamWork::default();
        self.closest_stream(rays, &which, oct, hits, &mut work);
        // The first stream: the valid rays of octant `oct` up to `last`.
        let first = FirstStream { last: which[STREAM - 1] as usize, oct };
        let traced = |i: usize, o: usize| o == first.oct && i <= first.last;
        if work.shared(otherwise) {
            octant_streams_until(rays, traced, |which, oct| {
                self.closest_stream(rays, which, oct, hits, &mut work);
                true
            });
        } else {
            self.closest_unshared(rays, hits, otherwise, Some(first));
        }
    }

    /// Whether batches whose rays do not start far apart stream untried on
    /// this tree (`Gathered`): on trees smaller than
    /// `SCATTERED_ALONE_BYTES`, whose rays stay in the caches. There a
    /// tile's first stream almost always shared, and where it did not,
    /// streams still beat one ray at a time: the bench's diffuse batches,
    /// native ÷ Embree 4, 1 thread (2-vCPU AMD EPYC, Zen 3, two runs),
    /// tried / untried: CBbunny 1.18 / 1.25-1.26, cow 1.48-1.50 / 1.56,
    /// beetle 1.46 / 1.53; CBbunny's path-traced render 1.3 % faster. Not
    /// on the large trees: the architecture scene's tiles that share
    /// little (a third) are faster one ray at a time (0.90-0.94 tried,
    /// 0.88-0.89 untried; the stadium 1.37 / 1.42). Scattered batches
    /// still try theirs, or go one ray at a time (`Scattered`): streamed
    /// untried, cow's random batches read 0.88 against 1.05.
    pub(super) fn gathered_batches(&self) -> Gathered {
        use super::Traversal;
        if self.memory_bytes() < SCATTERED_ALONE_BYTES {
            Gathered::Streams
        } else {
            Gathered::TryStream
        }
    }

    /// How `closest_streams_where_shared` starts a batch. On trees too
    /// large for the caches the first stream itself costs (its fetches
    /// miss, one after another, where interleaved rays overlap theirs), so
    /// it is tried there only where the batch's rays start close together
    /// and could share (`streams_pay`). On trees that stay in the caches
    /// the batch's origins decide once (`origins_scattered`): rays that
    /// start far apart try a first stream as `Scattered` says, the others
    /// as `Gathered` says.
    pub(super) fn batch_start(&self, rays: &[Ray], otherwise: Unshared) -> BatchStart {
        // The constant-time checks first; the origin rules are passes over the batch.
        if rays.len() < STREAM_MIN_RAYS || self.tree.root & LEAF_BIT != 0 || self.tree.root == EMPTY {
            return BatchStart::Unshared;
        }
        let try_first = match otherwise {
            Unshared::Interleaved => self.streams_pay(rays),
            Unshared::Single(scattered, _) if self.origins_scattered(rays) => scattered == Scattered::TryStream,
            Unshared::Single(_, Gathered::Streams) => return BatchStart::Streams,
            Unshared::Single(_, Gathered::TryStream) => true,
        };
        if !try_first {
            return BatchStart::Unshared;
        }
        match first_full_stream(rays) {
            Some((which, oct)) => BatchStart::TryFirst(which, oct),
            None => BatchStart::Unshared,
        }
    }

    /// The rays of a batch but those its first stream traced, the way
    /// `otherwise` says.
    ///
    /// # Safety
    /// As `closest_streams`.
    #[inline(always)]
    unsafe fn closest_unshared(&self, rays: &[Ray], hits: &mut [Option<Hit>], otherwise: Unshared, first: Option<FirstStream>) {
        match otherwise {
            Unshared::Single(..) => self.closest_batch_except(rays, hits, first),
            Unshared::Interleaved => self.closest_interleaved_except(rays, hits, first),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::hit_stream::tests::streams;
    use super::super::tests::{avx_or_skip, rays, shapes};
    use super::*;
    use crate::accel::brute::BruteForce;
    use crate::accel::Traversal;
    use crate::accel::workloads::{camera_rays, diffuse_rays, tile_order};
    use super::super::policy::ClosestBatches;
    use crate::scene::generated::for_tests as load_bench_scene;
    use crate::camera::Camera;

    /// Streams find brute force's closest hits: meshes and a sphere in one
    /// tree, camera, random and tight rays of every octant, short rays,
    /// rays starting inside boxes, invalid rays among them; batches of
    /// every size from one ray to all of them; all in streams, and in
    /// streams where the first stream's rays share their nodes, else one
    /// ray at a time or interleaved (both ways taken; the first stream's
    /// rays neither traced again nor left out).
    #[test]
    fn closest_streams_match_brute_force() {
        if !avx_or_skip("the closest-hit streams") {
            return;
        }
        let shapes = shapes();
        let rays = rays(&shapes);
        let brute = BruteForce::new(&shapes);
        let want: Vec<Option<Hit>> = rays.iter().map(|r| brute.intersect(r)).collect();
        assert!(want.iter().filter(|h| h.is_some()).count() > 1000 && want.iter().filter(|h| h.is_none()).count() > 1000);
        let bvh = WideBvh::<8>::build(&shapes);
        // Batches of 777 take both ways (the test rays come in runs of
        // coherent and random rays; where the other way is interleaving,
        // random runs try no stream).
        for (otherwise, unshared) in [(Unshared::Single(Scattered::TryStream, Gathered::TryStream), Some(false)), (Unshared::Single(Scattered::Single, Gathered::TryStream), None), (Unshared::Interleaved, None)] {
            let ways: Vec<Option<bool>> = rays.chunks(777).map(|r| first_shared(&bvh, r, otherwise)).collect();
            assert!(ways.contains(&Some(true)) && ways.contains(&unshared), "{otherwise:?}: batches of 777 take one way only: {ways:?}");
        }
        type Way = fn(&WideBvh<8>, &[Ray], &mut [Option<Hit>]);
        let ways = [
            ("streams", streams as Way),
            ("streams where shared, else single", where_shared as Way),
            ("streams where shared, else and where scattered single", where_shared_unless_scattered as Way),
            ("streams untried where gathered, else where shared", gathered_untried as Way),
            ("streams where shared, else interleaved", where_shared_else_interleaved as Way),
        ];
        for (name, way) in ways {
            for chunk in [rays.len(), 4096, 777, 128, 127, 65, 64, 3, 1] {
                let mut got = vec![None; rays.len()];
                for (r, h) in rays.chunks(chunk).zip(got.chunks_mut(chunk)) {
                    way(&bvh, r, h);
                }
                let bad = (0..rays.len()).filter(|&i| got[i] != want[i]).count();
                assert_eq!(bad, 0, "{name}, batches of {chunk}: {bad} hits differ from brute force");
            }
        }
    }


    /// `closest_streams_where_shared` as its callers run it, unshared
    /// batches one ray at a time.
    fn where_shared(bvh: &WideBvh<8>, rays: &[Ray], hits: &mut [Option<Hit>]) {
        // SAFETY: the tests call this only after `avx_or_skip`.
        unsafe { bvh.closest_streams_where_shared(rays, hits, Unshared::Single(Scattered::TryStream, Gathered::TryStream)) }
    }


    /// `where_shared`, batches whose rays start far apart one ray at a
    /// time without a first stream.
    fn where_shared_unless_scattered(bvh: &WideBvh<8>, rays: &[Ray], hits: &mut [Option<Hit>]) {
        // SAFETY: as above.
        unsafe { bvh.closest_streams_where_shared(rays, hits, Unshared::Single(Scattered::Single, Gathered::TryStream)) }
    }


    /// `where_shared`, batches whose rays start close together all in
    /// streams without a first stream.
    fn gathered_untried(bvh: &WideBvh<8>, rays: &[Ray], hits: &mut [Option<Hit>]) {
        // SAFETY: as above.
        unsafe { bvh.closest_streams_where_shared(rays, hits, Unshared::Single(Scattered::TryStream, Gathered::Streams)) }
    }


    /// `where_shared`, unshared batches interleaved.
    fn where_shared_else_interleaved(bvh: &WideBvh<8>, rays: &[Ray], hits: &mut [Option<Hit>]) {
        // SAFETY: as above.
        unsafe { bvh.closest_streams_where_shared(rays, hits, Unshared::Interleaved) }
    }


    /// Whether the first full stream of `rays` shares its nodes enough to
    /// stream rather than go the way `otherwise` says (`None`: the batch
    /// tries no stream).
    fn first_shared(bvh: &WideBvh<8>, rays: &[Ray], otherwise: Unshared) -> Option<bool> {
        let BatchStart::TryFirst(which, oct) = bvh.batch_start(rays, otherwise) else { return None };
        let mut hits = vec![None; rays.len()];
        let mut work = StreamWork::default();
        // SAFETY: as above.
        unsafe { bvh.closest_stream(rays, &which, oct, &mut hits, &mut work) };
        Some(work.shared(otherwise))
    }


    /// A tile's diffuse rays: the bounce rays of 256x192 camera rays' hits
    /// in 32x32 tiles.
    fn tile_rays(scene: &crate::scene::Scene, bvh: &WideBvh<8>) -> Vec<Ray> {
        let cam = camera_rays(&Camera::from_scene(scene), 256, 192);
        diffuse_rays(scene, bvh, &tile_order(&cam, 256, 192, 32), 3)
    }


    /// Each batch, traced the tree's default way, finds the single-ray hits.
    fn assert_batches_find_single_hits<'r>(bvh: &WideBvh<8>, batches: impl Iterator<Item = &'r [Ray]>, what: &str) {
        for rays in batches {
            let want: Vec<Option<Hit>> = rays.iter().map(|r| bvh.intersect(r)).collect();
            let mut got = vec![None; rays.len()];
            bvh.intersect_batch(rays, &mut got);
            assert!(got == want, "{what}: hits differ from single rays");
        }
    }


    /// On a bench scene, a tile's diffuse rays share their nodes and random
    /// rays do not, or where the other way is interleaving do not try a
    /// stream (the ways the rule takes), and either way the batch finds the
    /// single-ray hits.
    #[test]
    fn the_first_stream_chooses_the_way() {
        if !avx_or_skip("the closest-hit streams") {
            return;
        }
        let scene = load_bench_scene("subdiv:CBbunny:100k");
        let bvh = WideBvh::<8>::build(&scene.shapes);
        let cam = camera_rays(&Camera::from_scene(&scene), 256, 192);
        let diffuse = diffuse_rays(&scene, &bvh, &tile_order(&cam, 256, 192, 32), 3);
        let random = crate::accel::workloads::random_rays(&scene, 8192, 2);
        let (d, r) = (&diffuse[..1024], &random[..1024]);
        let (try_stream, single) = (Unshared::Single(Scattered::TryStream, Gathered::TryStream), Unshared::Single(Scattered::Single, Gathered::TryStream));
        for otherwise in [try_stream, single, Unshared::Interleaved] {
            assert_eq!(first_shared(&bvh, d, otherwise), Some(true), "{otherwise:?}: a tile's diffuse rays do not share their nodes");
        }
        assert!(!bvh.origins_scattered(d) && bvh.origins_scattered(r), "a tile's diffuse rays start far apart, or random rays do not");
        assert_eq!(first_shared(&bvh, r, try_stream), Some(false), "random rays share their nodes");
        assert_eq!(first_shared(&bvh, r, single), None, "random rays try a stream where scattered batches go one by one");
        assert_eq!(first_shared(&bvh, r, Unshared::Interleaved), None, "random rays try a stream where the other way is interleaving");
        for rays in [d, r] {
            let want: Vec<Option<Hit>> = rays.iter().map(|r| bvh.intersect(r)).collect();
            for way in [where_shared, where_shared_unless_scattered, gathered_untried, where_shared_else_interleaved] {
                let mut got = vec![None; rays.len()];
                way(&bvh, rays, &mut got);
                assert!(got == want, "hits differ from single rays");
            }
        }
    }


    /// Scattered batches skip the first stream only on trees where no
    /// random batch's first stream would have shared its nodes (cow,
    /// beetle, the stadium), and try it where some do (CBbunny, the
    /// architecture scene): the choice made from the tree's own sample
    /// (`scattered_batches`) agrees with the benchmark's random batches;
    /// a tree built again chooses the same.
    #[test]
    fn scattered_batches_skip_the_first_stream_where_random_streams_do_not_share() {
        if !avx_or_skip("the closest-hit streams") {
            return;
        }
        let file = |name: &str| crate::scene::load_file(&crate::scene::generated::in_repository(name).unwrap()).unwrap();
        let scenes = [("CBbunny", file("CBbunny")), ("cow", file("cow")), ("beetle", file("beetle")), ("arch:200k", load_bench_scene("arch:200k")), ("stadium:200k", load_bench_scene("stadium:200k"))];
        for (name, scene) in scenes {
            let bvh = WideBvh::<8>::build(&scene.shapes);
            // SAFETY: after `avx_or_skip`.
            let chosen = unsafe { bvh.scattered_batches() };
            assert_eq!(bvh.policy.closest, ClosestBatches::StreamsWhereShared(Unshared::Single(chosen, bvh.gathered_batches())), "{name}");
            assert_eq!(unsafe { WideBvh::<8>::build(&scene.shapes).scattered_batches() }, chosen, "{name}: built again");
            let random = crate::accel::workloads::random_rays(&scene, 4 * 4096, 9);
            let probes: Vec<Option<bool>> = random.chunks(4096).map(|r| first_shared(&bvh, r, Unshared::Single(Scattered::TryStream, Gathered::TryStream))).collect();
            // Where they try, the first stream still decides batch by batch.
            let agrees = match chosen {
                Scattered::TryStream => probes.contains(&Some(true)),
                Scattered::Single => probes.iter().all(|p| *p == Some(false)),
            };
            assert!(agrees, "{name}: {chosen:?}, but the random batches' first streams say {probes:?}");
            let expected = if name.starts_with("CBbunny") || name.starts_with("arch") { Scattered::TryStream } else { Scattered::Single };
            assert_eq!(chosen, expected, "{name}");
        }
    }


    /// On a large tree whose rays stay in the caches (the architecture
    /// scene at 300k triangles, above `SCATTERED_ALONE_BYTES`) scattered
    /// batches go one ray at a time without a first stream, though the
    /// tree's sample of such rays shares as much as at 200k triangles,
    /// where they try one; a tile's diffuse rays still try theirs; every
    /// batch finds the single-ray hits.
    #[test]
    fn large_cached_trees_trace_scattered_batches_alone() {
        if !avx_or_skip("the closest-hit streams") {
            return;
        }
        use crate::accel::Traversal;
        let scene = load_bench_scene("arch:300k");
        let bvh = WideBvh::<8>::build(&scene.shapes);
        assert!(bvh.memory_bytes() >= SCATTERED_ALONE_BYTES, "the test needs a large tree: {} bytes", bvh.memory_bytes());
        assert_eq!(bvh.interleave_reach(), super::super::interleave::InterleaveReach::None, "the test needs a tree whose rays stay cached");
        // SAFETY: after `avx_or_skip`.
        assert_eq!(unsafe { bvh.scattered_batches() }, Scattered::Single);
        let way = Unshared::Single(Scattered::Single, Gathered::TryStream);
        assert_eq!(bvh.policy.closest, ClosestBatches::StreamsWhereShared(way));
        let random = crate::accel::workloads::random_rays(&scene, 4096, 2);
        let probes: Vec<Option<bool>> = random.chunks(1024).map(|r| first_shared(&bvh, r, Unshared::Single(Scattered::TryStream, Gathered::TryStream))).collect();
        assert!(probes.contains(&Some(true)), "the random batches' first streams would not have streamed: {probes:?}");
        assert!(random.chunks(1024).all(|r| first_shared(&bvh, r, way).is_none()), "a random batch tries a stream");
        let diffuse = tile_rays(&scene, &bvh);
        assert!(diffuse.chunks(1024).any(|d| first_shared(&bvh, d, way).is_some()), "no tile tries a stream");
        assert_batches_find_single_hits(&bvh, diffuse.chunks(1024).chain(random.chunks(1024)), "arch:300k");
    }


    /// On a small tree that stays in the caches a tile's diffuse rays
    /// stream without trying a first stream, random rays do not; on the
    /// large architecture scene tiles try theirs; streams untried find
    /// the single-ray hits.
    #[test]
    fn tiles_stream_untried_on_small_cached_trees() {
        if !avx_or_skip("the closest-hit streams") {
            return;
        }
        for (spec, small) in [("subdiv:CBbunny:30k", true), ("arch:300k", false)] {
            let scene = load_bench_scene(spec);
            let bvh = WideBvh::<8>::build(&scene.shapes);
            let ClosestBatches::StreamsWhereShared(way) = bvh.policy.closest else { panic!("{spec}: {:?}", bvh.policy.closest) };
            let diffuse = tile_rays(&scene, &bvh);
            let random = crate::accel::workloads::random_rays(&scene, 4096, 2);
            let untried = |rays: &[Ray]| bvh.batch_start(rays, way) == BatchStart::Streams;
            assert_eq!(bvh.gathered_batches() == Gathered::Streams, small, "{spec}");
            assert!(diffuse.chunks(1024).all(|d| untried(d) == small), "{spec}: tiles");
            assert!(random.chunks(1024).all(|r| !untried(r)), "{spec}: random rays stream untried");
            assert!(!untried(&diffuse[..STREAM_MIN_RAYS - 1]), "{spec}: a small batch streams");
            assert_batches_find_single_hits(&bvh, diffuse.chunks(1024), spec);
        }
    }


    /// The origin rule's pass stops early (`streams_pay`) yet decides as a
    /// pass over the whole batch does: batches of a tile's diffuse rays
    /// with ever more random rays mixed in, at either end or spread
    /// through, with invalid rays among them, cross the bar both ways.
    #[test]
    fn the_origin_rule_stopping_early_decides_as_the_whole_pass() {
        let scene = load_bench_scene("arch:50k");
        let bvh = WideBvh::<8>::build(&scene.shapes);
        let cam = camera_rays(&Camera::from_scene(&scene), 256, 192);
        let diffuse = diffuse_rays(&scene, &bvh, &tile_order(&cam, 256, 192, 32), 3);
        let random = crate::accel::workloads::random_rays(&scene, 4096, 2);
        let whole_pass = |rays: &[Ray]| {
            let valid: Vec<&Ray> = rays.iter().filter(|r| r.is_valid()).collect();
            let sum: f32 = valid.windows(2).map(|w| (w[1].origin - w[0].origin).length()).sum();
            let steps = valid.len().saturating_sub(1);
            rays.len() >= STREAM_MIN_RAYS && steps >= STREAM_MIN_RAYS && sum < steps as f32 * COHERENT_STEP * bvh.tree.root_diagonal
        };
        let (mut yes, mut no) = (0, 0);
        for mixed in (0..=64).step_by(2) {
            for layout in 0..3 {
                let mut batch: Vec<Ray> = diffuse[..512].to_vec();
                for k in 0..mixed {
                    let at = match layout {
                        0 => batch.len(),
                        1 => 0,
                        _ => (k * 37) % batch.len(),
                    };
                    batch.insert(at, random[k]);
                }
                batch[100].tmax = f32::NAN;
                let want = whole_pass(&batch);
                assert_eq!(bvh.streams_pay(&batch), want, "{mixed} random rays mixed in, layout {layout}");
                if want { yes += 1 } else { no += 1 }
            }
        }
        assert!(yes > 10 && no > 10, "the batches cross the bar one way only: {yes} stream, {no} do not");
    }
}
