//! Unit tests of the wide BVH: every width, instruction set and traversal
//! mode against brute force, and the SIMD kernels against the scalar code.

use super::triangle::intersect_group_scalar;
use super::*;
use glam::Vec3;
use crate::accel::brute::BruteForce;
use crate::accel::workloads::{camera_rays, random_rays};
use crate::scene::generated::{for_tests as load_bench_scene, sphere_scene as procedural_scene};
use crate::camera::Camera;
use crate::rng::Rng;
use crate::scene::TriangleMesh;

/// A small mesh with a sphere inside it, so leaves hold both kinds.
pub(super) fn shapes() -> Vec<Shape> {
    let mut shapes = procedural_scene(3000).shapes;
    shapes.push(Shape::Sphere { center: Vec3::new(0.1, 0.0, 0.2), radius: 0.3 });
    shapes
}

/// Packets of 16 nearly parallel rays from nearly the same point, so
/// most pass `Frustum::new`; every fourth packet spreads wider.
pub(super) fn tight_packets(n: usize, seed: u64) -> Vec<Ray> {
    let mut rng = Rng::new(seed, 1);
    let mut rays = Vec::new();
    for p in 0..n {
        let spread = if p % 4 == 3 { 0.2 } else { 1e-3 };
        let o = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 4.0 - 2.0;
        let d = (Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0 - 1.0).normalize_or(Vec3::X);
        for _ in 0..packet::PACKET {
            let jo = (Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) - 0.5) * spread;
            let jd = (Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) - 0.5) * spread;
            rays.push(Ray::new(o + jo, d + jd));
        }
    }
    rays
}

/// Whether the CPU has AVX2, which the packet paths need; says loudly
/// that `what` went untested where it has not.
pub(super) fn avx_or_skip(what: &str) -> bool {
    let ok = avx_available();
    if !ok {
        eprintln!("SKIPPED: this CPU has no AVX2; {what} were not exercised");
    }
    ok
}

pub(super) fn rays(shapes: &[Shape]) -> Vec<Ray> {
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
    let avx8_on = sse8.policy.avx();
    sse8.policy.boxes = policy::BoxIsa::Sse2;
    // Interleaved batches are only switched on for large structures;
    // force them here.
    let mut interleaved = WideBvh::<8>::build(&shapes);
    if interleaved.policy.avx() {
        interleaved.policy.closest = ClosestBatches::Interleaved;
    }
    // Shadow streams too (coherent and incoherent occlusion batches) are
    // for large trees only.
    let mut shadow_streams = WideBvh::<8>::build(&shapes);
    if shadow_streams.policy.avx() {
        shadow_streams.policy.shadows = policy::ShadowBatches::Streams;
    }
    let mut candidates: Vec<(&str, Box<dyn Traversal>)> = vec![
        ("4-wide", Box::new(WideBvh::<4>::build(&shapes))),
        ("8-wide SSE2", Box::new(sse8)),
        ("8-wide default", Box::new(WideBvh::<8>::build(&shapes))),
        ("8-wide interleaved", Box::new(interleaved)),
        ("8-wide shadow streams", Box::new(shadow_streams)),
    ];
    if avx512_on() {
        let mut wide = WideBvh::<8>::build(&shapes);
        wide.policy.packets = policy::PacketIsa::Avx512;
        candidates.push(("8-wide AVX-512 packets", Box::new(wide)));
    } else {
        eprintln!("note: this CPU has no AVX-512F; the AVX-512 packet kernels were not exercised");
    }
    // The default runs single rays' walks compiled with AVX-512VL where the
    // CPU has it; the plain AVX2 twins must give the same answers.
    let mut avx2 = WideBvh::<8>::build(&shapes);
    if avx2.policy.avx512vl() {
        avx2.policy.boxes = policy::BoxIsa::Avx2;
        candidates.push(("8-wide AVX2 without AVX-512VL", Box::new(avx2)));
    } else if avx8_on {
        eprintln!("note: this CPU has no AVX-512VL; the single-ray walks compiled with it were not exercised");
    }
    if !avx8_on {
        eprintln!("note: this CPU has no AVX2; the AVX2 paths were not exercised");
    }
    for (name, b) in &candidates {
        assert_batches_match(name, b.as_ref(), &rays, &want, &want_occ);
        let bad = rays.iter().zip(&want).filter(|(r, w)| b.intersect(r) != **w).count();
        let bad_occ = rays.iter().zip(&want_occ).filter(|(r, w)| b.occluded(r) != **w).count();
        assert_eq!((bad, bad_occ), (0, 0), "{name} one ray a call: closest-hit and occlusion mismatches against brute force");
    }
}

/// `b`'s batch and coherent calls give exactly the hits and occlusion
/// answers `want` and `want_occ` (brute force's).
fn assert_batches_match(name: &str, b: &dyn Traversal, rays: &[Ray], want: &[Option<Hit>], want_occ: &[bool]) {
    let mut hits = vec![None; rays.len()];
    let mut occ = vec![false; rays.len()];
    for (what, f) in [("batch", false), ("coherent", true)] {
        if f {
            b.intersect_coherent(rays, &mut hits);
            b.occluded_coherent(rays, &mut occ);
        } else {
            b.intersect_batch(rays, &mut hits);
            b.occluded_batch(rays, &mut occ);
        }
        let bad = hits.iter().zip(want).filter(|(a, b)| a != b).count();
        let bad_occ = occ.iter().zip(want_occ).filter(|(a, b)| a != b).count();
        assert_eq!((bad, bad_occ), (0, 0), "{name} {what}: closest-hit and occlusion mismatches against brute force");
    }
}

/// With spatial splits the tree references some triangles from several
/// leaves, each leaf's box bounding only its piece; every traversal must
/// still find exactly brute force's hits. The scene adds what spatial
/// splits are for: two large triangles under (and a long sliver through)
/// the small ones.
#[test]
fn spatial_split_trees_match_brute_force() {
    let mut shapes = shapes();
    let big = TriangleMesh {
        positions: vec![Vec3::new(-5.0, -1.2, -5.0), Vec3::new(5.0, -1.2, -5.0), Vec3::new(5.0, -1.2, 5.0), Vec3::new(-5.0, -1.2, 5.0), Vec3::new(-3.0, -2.0, 0.0), Vec3::new(3.0, 2.0, 0.1), Vec3::new(3.0, 2.01, 0.12)],
        triangles: vec![[0, 1, 2], [0, 2, 3], [4, 5, 6]],
        normals: Vec::new(),
    };
    shapes.push(Shape::Mesh(big));
    let rays = rays(&shapes);
    let brute = BruteForce::new(&shapes);
    let want: Vec<Option<Hit>> = rays.iter().map(|r| brute.intersect(r)).collect();
    let want_occ: Vec<bool> = rays.iter().map(|r| brute.occluded(r)).collect();
    let plain = WideBvh::<8>::build_with_splits(&shapes, 0.0);
    let split = WideBvh::<8>::build_with_splits(&shapes, 0.5);
    let refs = |b: &WideBvh<8>| b.tree.groups.iter().flat_map(|g| g.ids).filter(|id| id[0] != EMPTY).count() + b.tree.spheres.len();
    assert!(refs(&split) > refs(&plain), "no spatial split was made ({} references)", refs(&split));
    assert!(refs(&split) as f64 <= 1.5 * refs(&plain) as f64, "past the budget: {} references for {}", refs(&split), refs(&plain));
    let mut candidates: Vec<(&str, WideBvh<8>)> = vec![("default", split)];
    let mut sse = WideBvh::<8>::build_with_splits(&shapes, 0.5);
    sse.policy.boxes = policy::BoxIsa::Sse2;
    candidates.push(("SSE2", sse));
    let mut interleaved = WideBvh::<8>::build_with_splits(&shapes, 0.5);
    if interleaved.policy.avx() {
        interleaved.policy.closest = ClosestBatches::Interleaved;
        interleaved.policy.shadows = policy::ShadowBatches::Streams;
    }
    candidates.push(("interleaved, shadow streams", interleaved));
    for (name, b) in &candidates {
        assert_batches_match(name, b, &rays, &want, &want_occ);
        let singles = rays.iter().zip(&want).filter(|(r, w)| b.intersect(r) != **w).count();
        assert_eq!(singles, 0, "{name}: single-ray mismatches");
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
    for node in bvh.tree.nodes.iter().take(300) {
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
        for node in bvh.tree.nodes.iter().skip(k % 7).step_by(7) {
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
        for g in bvh.tree.groups.iter() {
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

/// Whether this CPU has what the AVX-512 packet kernels need.
fn avx512_on() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx2") && is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// The packet's leaf box test (`RaysSoA::test`, 8 rays per instruction;
/// `test512`, 16, where the CPU has AVX-512F)
/// decides exactly as each ray's own scalar slab test, rays that end short
/// and box corners included.
#[cfg(target_arch = "x86_64")]
#[test]
fn packet_box_test_equals_the_single_ray_test() {
    if !is_x86_feature_detected!("avx2") {
        eprintln!("note: this CPU has no AVX2; the packet box test is not used here and was not exercised");
        return;
    }
    let shapes = shapes();
    let bvh = WideBvh::<8>::build(&shapes);
    let mut packets = tight_packets(150, 21);
    // Packets aimed at box corners, where the far plane's rounding
    // allowance decides.
    for node in bvh.tree.nodes.iter().take(40) {
        let hi = Vec3::new(node.bounds[3][0], node.bounds[4][0], node.bounds[5][0]);
        let o = hi + Vec3::new(0.31, 0.27, 0.43);
        packets.extend((0..packet::PACKET).map(|i| Ray::new(o, hi - o + Vec3::splat(1e-4 * i as f32))));
    }
    let mut cases = 0;
    for p in packets.chunks(packet::PACKET) {
        let Some(f) = frustum::Frustum::new(p, false) else { continue };
        // SAFETY: AVX2 checked above.
        let soa = unsafe { super::packet::RaysSoA::new(p) };
        let mut tmax = [0.0f32; packet::PACKET];
        for (i, r) in p.iter().enumerate() {
            tmax[i] = if i % 3 == 0 { r.tmax } else { 0.5 + i as f32 * 0.2 };
        }
        for node in &bvh.tree.nodes {
            for lane in (0..8).filter(|&l| node.child[l] != EMPTY) {
                // SAFETY: AVX2 checked above.
                let got = unsafe { soa.test(&f.near_plane, node, lane, &tmax) } & ((1 << p.len()) - 1);
                if avx512_on() {
                    // SAFETY: checked by `avx512_on`.
                    assert_eq!(unsafe { avx512_box_test(&soa, &f, node, lane, &tmax) } & ((1 << p.len()) - 1), got, "AVX-512 packet box test");
                }
                let mut want = 0u64;
                for (i, r) in p.iter().enumerate() {
                    let mut near = [0.0f32; 8];
                    want |= ((Slab::new(r).test_scalar(node, r.tmin, tmax[i], &mut near) >> lane & 1) as u64) << i;
                }
                assert_eq!(got, want, "packet box test differs from the rays' own tests");
                cases += 1;
            }
        }
    }
    assert!(cases > 100_000, "too few cases: {cases}");
}

/// The two- and four-ray triangle tests (`intersect_group_x2`, AVX2, and
/// `intersect_group_x4`, AVX-512, where the CPU has it) give each ray
/// exactly the mask and hit bits of the one-ray test, exact-zero edge
/// functions (rays through vertices, handed to the f64 path) included.
#[cfg(target_arch = "x86_64")]
#[test]
fn paired_triangle_test_equals_the_single_ray_test() {
    if !is_x86_feature_detected!("avx2") {
        eprintln!("note: this CPU has no AVX2; the paired triangle test is not used here and was not exercised");
        return;
    }
    let shapes = shapes();
    let bvh = WideBvh::<8>::build(&shapes);
    let mut rays: Vec<Ray> = rays(&shapes).into_iter().filter(|r| r.is_valid()).step_by(3).collect();
    // Rays through vertices, from axis-aligned origins so some edge
    // functions are exactly zero.
    for g in bvh.tree.groups.iter().step_by(40) {
        let v = Vec3::new(g.v[0][0][0], g.v[0][1][0], g.v[0][2][0]);
        rays.push(Ray::new(v + Vec3::new(0.0, 0.0, 2.0), Vec3::new(0.0, 0.0, -1.0)));
        rays.push(Ray::new(v + Vec3::new(1.5, 0.0, 0.0), Vec3::new(-1.0, 0.0, 0.0)));
    }
    let (mut hits, mut zero_edge) = (0, 0);
    for pair in rays.chunks_exact(2) {
        let rt = [0, 1].map(|r| RayTransform::new(pair[r].origin, pair[r].dir));
        let sh = [0, 1].map(|r| Shear::new(&rt[r]));
        let tmin = [pair[0].tmin, pair[1].tmin];
        let tmax = [pair[0].tmax, 3.0];
        for g in &bvh.tree.groups {
            let mut got = [[LaneHit::default(); LANES]; 2];
            // SAFETY: AVX2 checked above.
            let m2 = unsafe { triangle::intersect_group_x2(g, [&rt[0], &rt[1]], [&sh[0], &sh[1]], tmin, tmax, &mut got) };
            let mut got4 = [[LaneHit::default(); LANES]; 4];
            // Rays 0, 1, 0, 1 in the four lanes of the AVX-512 kernel.
            // SAFETY: checked by `avx512_on`.
            let m4 = avx512_on().then(|| unsafe { avx512_group_test(g, [&rt[0], &rt[1], &rt[0], &rt[1]], [&sh[0], &sh[1], &sh[0], &sh[1]], [tmin[0], tmin[1], tmin[0], tmin[1]], [tmax[0], tmax[1], tmax[0], tmax[1]], &mut got4) });
            for r in 0..2 {
                let mut want = [LaneHit::default(); LANES];
                let m1 = intersect_group(g, &rt[r], &sh[r], tmin[r], tmax[r], &mut want);
                assert_eq!(m2[r], m1, "paired triangle test mask differs");
                if let Some(m4) = m4 {
                    assert_eq!([m4[r], m4[r + 2]], [m1, m1], "AVX-512 triangle test mask differs");
                }
                for lane in (0..LANES).filter(|l| m1 & (1 << l) != 0) {
                    let bits = |h: &LaneHit| [h.t, h.u, h.v].map(f32::to_bits);
                    assert_eq!(bits(&got[r][lane]), bits(&want[lane]));
                    if m4.is_some() {
                        assert_eq!([bits(&got4[r][lane]), bits(&got4[r + 2][lane])], [bits(&want[lane]); 2], "AVX-512 triangle test hit");
                    }
                    hits += 1;
                    zero_edge += (want[lane].u == 0.0 || want[lane].v == 0.0 || want[lane].u + want[lane].v == 1.0) as usize;
                }
            }
        }
    }
    assert!(hits > 1000 && zero_edge > 0, "too few cases: {hits} hits, {zero_edge} on an edge or vertex");
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f")]
unsafe fn avx512_box_test(soa: &super::packet::RaysSoA, f: &frustum::Frustum, node: &Node<8>, lane: usize, tmax: &[f32; packet::PACKET]) -> u64 {
    soa.test512(&f.near_plane, node, lane, tmax)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f")]
unsafe fn avx512_group_test(g: &TriGroup, rt: [&RayTransform; 4], sh: [&Shear; 4], tmin: [f32; 4], tmax: [f32; 4], out: &mut [[LaneHit; LANES]; 4]) -> [u32; 4] {
    triangle::intersect_group_x4(g, rt, sh, tmin, tmax, out)
}

#[test]
fn frustum_accepts_coherent_packets() {
    if !is_x86_feature_detected!("avx2") {
        eprintln!("SKIPPED frustum_accepts_coherent_packets: packets need AVX2, which this CPU lacks");
        return;
    }
    let rays = tight_packets(100, 4);
    let accepted = rays.chunks(packet::PACKET).filter(|p| frustum::Frustum::new(p, false).is_some()).count();
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
    assert!(frustum::Frustum::new(&fan, true).is_none(), "a packet fanned out over 0.75 rad must be traced ray by ray");
    assert!(frustum::Frustum::new(&fan[..2], true).is_some(), "two rays 0.05 apart stay a frustum");
    assert!(frustum::Frustum::new(&fan[..4], false).is_some(), "camera rays 0.15 apart stay a frustum");
    assert!(frustum::Frustum::new(&fan[..4], true).is_none());
    // Camera rays wrapping from the end of one scanline to the start of the
    // next span the frame: traced ray by ray.
    let cam = crate::camera::Camera::from_scene(&procedural_scene(100));
    let row = camera_rays(&cam, 591, 2);
    assert!(frustum::Frustum::new(&row[583..599], false).is_none(), "a packet wrapping a scanline must fall back");
    assert!(frustum::Frustum::new(&row[560..576], false).is_some(), "16 neighbours on one scanline are a frustum");
}

/// A mesh large enough that the build splits it into pieces built in
/// parallel (`layout::flatten`), with spheres scattered through it so that
/// pieces hold leaf records and spheres too: traversal still matches brute
/// force, and the flattened arrays are the same whatever the thread count.
#[test]
fn a_tree_built_in_pieces_matches_brute_force_and_ignores_thread_count() {
    // Large enough for more than one chunk of `sah`'s sum (8192 nodes).
    let mut scene = procedural_scene(180_000);
    let mut rng = Rng::new(3, 1);
    for _ in 0..40 {
        let c = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.4 - 1.2;
        scene.shapes.push(Shape::Sphere { center: c, radius: 0.02 + 0.05 * rng.uniform() });
    }
    // Small meshes far out: children of the root's wide node too small to
    // split again, so they are built as pieces that are single leaves.
    let mut targets = Vec::new();
    for (k, c) in [Vec3::new(30.0, 1.0, 0.0), Vec3::new(-2.0, 35.0, 3.0), Vec3::new(1.0, -3.0, -40.0)].into_iter().enumerate() {
        let positions = vec![c, c + Vec3::new(1.0, 0.0, 0.2), c + Vec3::new(0.0, 1.0, 0.1), c + Vec3::new(1.0, 1.0, 0.5)];
        let triangles = if k == 0 { vec![[0, 1, 2]] } else { vec![[0, 1, 2], [1, 3, 2]] };
        scene.shapes.push(Shape::Mesh(crate::scene::TriangleMesh { positions, triangles, normals: Vec::new() }));
        targets.push(c + Vec3::new(0.3, 0.3, 0.1));
    }
    let shapes = scene.shapes.clone();
    let in_pool = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| WideBvh::<8>::build(&shapes))
    };
    let (one, two) = (in_pool(1), in_pool(2));
    assert!(one.tree.nodes.len() > 1000 && !one.tree.leaves.is_empty() && one.tree.spheres.len() == 40, "{}", one.describe());
    let bits = |b: &WideBvh<8>| {
        let mut v: Vec<u32> = b.tree.nodes.iter().flat_map(|n| n.bounds.iter().flatten().map(|f| f.to_bits()).chain(n.child)).collect();
        v.extend(b.tree.groups.iter().flat_map(|g| g.v.iter().flatten().flatten().map(|f| f.to_bits())));
        v.extend(b.tree.groups.iter().flat_map(|g| g.ids).flatten());
        v.extend(b.tree.leaves.iter().flat_map(|l| [l.group, l.n_groups, l.sphere, l.n_spheres]));
        v.push(b.tree.root);
        v
    };
    assert!(bits(&one) == bits(&two), "the layout depends on the thread count");
    // The SAH cost summed over the arrays in chunks is the walk down the
    // tree's (to rounding), and the same at any thread count.
    assert!(one.tree.nodes.len() > 8192, "more than one chunk of `sah`'s sum");
    let walked = {
        let root = one.tree.root_area;
        let (mut nodes, mut leaves, mut stack) = (0.0f64, 0.0f64, vec![(one.tree.root, root)]);
        while let Some((c, area)) = stack.pop() {
            if c & LEAF_BIT != 0 {
                let l = one.leaf_of(c);
                leaves += area / root * (l.n_groups + l.n_spheres) as f64;
            } else {
                nodes += area / root;
                stack.extend(one.child_areas(c));
            }
        }
        (nodes, leaves)
    };
    let (a, b) = (rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| one.sah()), two.sah());
    assert_eq!((a.nodes.to_bits(), a.leaves.to_bits()), (b.nodes.to_bits(), b.leaves.to_bits()));
    assert!((a.nodes / walked.0 - 1.0).abs() < 1e-12 && (a.leaves / walked.1 - 1.0).abs() < 1e-12, "{a:?} against {walked:?}");
    let brute = BruteForce::new(&shapes);
    let mut rays = camera_rays(&Camera::from_scene(&scene), 40, 30);
    rays.extend(random_rays(&scene, 1500, 11));
    for t in &targets {
        let o = *t + Vec3::new(0.2, -0.1, 4.0);
        rays.extend((0..8).map(|i| Ray::new(o, *t + Vec3::new(0.02 * i as f32, 0.01 * i as f32, 0.0) - o)));
    }
    let mut hits = vec![None; rays.len()];
    two.intersect_batch(&rays, &mut hits);
    let mut occ = vec![false; rays.len()];
    two.occluded_batch(&rays, &mut occ);
    for (i, r) in rays.iter().enumerate() {
        assert_eq!(hits[i], brute.intersect(r), "ray {i}: closest hit");
        assert_eq!(occ[i], brute.occluded(r), "ray {i}: occlusion");
    }
    let far_hits = hits[hits.len() - 24..].iter().filter(|h| h.is_some_and(|h| h.geom_id as usize >= shapes.len() - 3)).count();
    assert!(far_hits >= 12, "only {far_hits} of 24 rays aimed at the far meshes hit them");
}

/// A hit at exactly `tmax` is in the range `(tmin, tmax]`: a shadow ray
/// ending on a light's flat quad must see it (or not) as brute force does.
/// Box entry distances rounded up past `tmax` once culled such hits (a
/// CBgems pixel differed between native and brute). Rays towards points on
/// flat axis-aligned quads (zero-thickness boxes), `tmax` set to the exact
/// `t` brute force finds, in every mode.
#[test]
fn a_hit_at_exactly_tmax_is_found_in_every_mode() {
    let mut mesh = TriangleMesh { positions: Vec::new(), triangles: Vec::new(), normals: Vec::new() };
    let mut rng = Rng::new(11, 2);
    for q in 0..40 {
        let c = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 6.0 - 3.0;
        let (a, b) = match q % 3 {
            0 => (Vec3::X, Vec3::Z),
            1 => (Vec3::Y, Vec3::Z),
            _ => (Vec3::X, Vec3::Y),
        };
        let s = 0.2 + rng.uniform();
        let base = mesh.positions.len() as u32;
        mesh.positions.extend([c - a * s - b * s, c + a * s - b * s, c + a * s + b * s, c - a * s + b * s]);
        mesh.triangles.extend([[base, base + 1, base + 2], [base, base + 2, base + 3]]);
    }
    mesh.compute_normals();
    let quads = mesh.positions.clone();
    let shapes = vec![Shape::Mesh(mesh)];
    let brute = BruteForce::new(&shapes);
    let mut rays = Vec::new();
    while rays.len() < 4096 {
        let o = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 10.0 - 5.0;
        let q = 4 * (rng.next_u32() as usize % 40);
        let (u, v) = rng.uniform2();
        let target = quads[q] + (quads[q + 1] - quads[q]) * u + (quads[q + 3] - quads[q]) * v;
        let mut r = Ray::with_range(o, target - o, 0.0, f32::INFINITY);
        if let Some(h) = brute.intersect(&r) {
            r.tmax = h.t;
            rays.push(r);
        }
    }
    let want: Vec<Option<Hit>> = rays.iter().map(|r| brute.intersect(r)).collect();
    assert!(want.iter().all(|h| h.is_some()));
    let mut candidates: Vec<(&str, Box<dyn Traversal>)> =
        vec![("4-wide", Box::new(WideBvh::<4>::build(&shapes))), ("8-wide", Box::new(WideBvh::<8>::build(&shapes)))];
    let mut interleaved = WideBvh::<8>::build(&shapes);
    if interleaved.policy.avx() {
        interleaved.policy.closest = ClosestBatches::Interleaved;
    }
    candidates.push(("8-wide interleaved", Box::new(interleaved)));
    if avx512_on() {
        let mut wide = WideBvh::<8>::build(&shapes);
        wide.policy.packets = policy::PacketIsa::Avx512;
        candidates.push(("8-wide AVX-512 packets", Box::new(wide)));
    }
    for (name, b) in &candidates {
        let single = rays.iter().zip(&want).filter(|(r, w)| b.intersect(r) != **w || !b.occluded(r)).count();
        let mut hits = vec![None; rays.len()];
        let mut occ = vec![false; rays.len()];
        b.intersect_coherent(&rays, &mut hits);
        b.occluded_coherent(&rays, &mut occ);
        let coherent = hits.iter().zip(&want).zip(&occ).filter(|((h, w), o)| h != w || !**o).count();
        b.intersect_batch(&rays, &mut hits);
        b.occluded_batch(&rays, &mut occ);
        let batch = hits.iter().zip(&want).zip(&occ).filter(|((h, w), o)| h != w || !**o).count();
        assert_eq!((single, coherent, batch), (0, 0, 0), "{name}: hits at exactly tmax missed (single, coherent, batch)");
    }
}

/// Packets whose interval ray turns out too loose finish ray by ray (the
/// architecture scene's camera rays skimming its facade, the dense scan's
/// shadow rays): answers stay those of single rays, bit for bit.
#[test]
fn packets_that_give_up_answer_as_single_rays() {
    use std::sync::atomic::Ordering;
    let before = frustum::BAILOUTS.load(Ordering::Relaxed);
    for spec in ["arch:300k", "subdiv:CBbunny:200k"] {
        let scene = load_bench_scene(spec);
        let bvh = WideBvh::<8>::build(&scene.shapes);
        let cam = camera_rays(&crate::camera::Camera::from_scene(&scene), 512, 384);
        let mut packed = vec![None; cam.len()];
        for (r, h) in cam.chunks(4096).zip(packed.chunks_mut(4096)) {
            bvh.intersect_coherent(r, h);
        }
        for (r, h) in cam.iter().zip(&packed) {
            assert_eq!(*h, bvh.intersect(r), "{spec}: camera ray {r:?}");
        }
        let shadow = crate::accel::workloads::shadow_rays(&scene, &bvh, &cam);
        let mut occ = vec![false; shadow.len()];
        for (r, o) in shadow.chunks(4096).zip(occ.chunks_mut(4096)) {
            bvh.occluded_coherent(r, o);
        }
        for (r, o) in shadow.iter().zip(&occ) {
            assert_eq!(*o, bvh.occluded(r), "{spec}: shadow ray {r:?}");
        }
    }
    if avx_available() {
        assert!(frustum::BAILOUTS.load(Ordering::Relaxed) > before, "no packet gave up: the fallback went untested");
    }
}

/// Shadow packets with a ray mask per node (`masked`): fanned-out, mixed-sign,
/// short and invalid rays in one packet are occluded exactly when brute force
/// says so, on the mixed mesh-and-sphere scene and on the architecture scene's
/// shadow rays.
#[test]
fn masked_shadow_packets_match_brute_force() {
    if !avx_available() {
        eprintln!("note: this CPU has no AVX2; masked shadow packets were not exercised");
        return;
    }
    #[target_feature(enable = "avx2")]
    unsafe fn masked(bvh: &WideBvh<8>, rays: &[Ray], order: ChildOrder) -> Vec<bool> {
        let mut out = vec![true; rays.len()];
        for (r, o) in rays.chunks(packet::PACKET).zip(out.chunks_mut(packet::PACKET)) {
            bvh.any_masked(&super::packet::RaysSoA::new(r), r, o, order);
        }
        out
    }
    for order in [ChildOrder::FarthestFirst, ChildOrder::NearestFirst] {
        let shapes = shapes();
        let rays = rays(&shapes);
        let brute = BruteForce::new(&shapes);
        let bvh = WideBvh::<8>::build(&shapes);
        // SAFETY: the CPU has AVX2 (checked above).
        let got = unsafe { masked(&bvh, &rays, order) };
        let bad = rays.iter().zip(&got).filter(|(r, o)| brute.occluded(r) != **o).count();
        assert_eq!(bad, 0, "masked packets: occlusion mismatches against brute force");
        assert!(got.iter().any(|o| *o) && got.iter().any(|o| !*o), "the rays must be partly occluded for the test to mean anything");
        let scene = load_bench_scene("arch:100k");
        let bvh = WideBvh::<8>::build(&scene.shapes);
        let cam = camera_rays(&crate::camera::Camera::from_scene(&scene), 256, 192);
        let shadow = crate::accel::workloads::shadow_rays(&scene, &bvh, &cam);
        // SAFETY: as above.
        let got = unsafe { masked(&bvh, &shadow, order) };
        for (r, o) in shadow.iter().zip(&got) {
            assert_eq!(*o, bvh.occluded(r), "arch:100k: shadow ray {r:?}");
        }
    }
}
