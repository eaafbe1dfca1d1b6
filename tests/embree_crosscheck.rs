//! Embree 3 and Embree 4 against the native BVH: every shipped scene, camera
//! and random rays, closest hits, occlusion, every batch call, and
//! normal-shading images; and the ABI canary of each library.
//!
//! A major that cannot be used here is skipped with the reason on stderr
//! (CI sets PATHTRACER_REQUIRE_EMBREE=3,4, which turns a missing one into a
//! failure instead); without any Embree in the build the tests are ignored.

mod common;

use pathtracer::accel::agreement::{self, Agreement};
use pathtracer::accel::{BackendKind, Hit, Traversal};
use pathtracer::accel::workloads::{camera_rays, random_rays};
use pathtracer::camera::Camera;
use pathtracer::ray::Ray;
use pathtracer::render::{self, normals::NormalShading, RenderSettings};
use pathtracer::scene::Scene;
use rayon::prelude::*;

/// The Embree backends to check; loud when there is none.
fn embrees() -> Vec<BackendKind> {
    let v = common::embree_backends();
    if v.is_empty() {
        eprintln!("SKIPPED: no Embree can be used here; the cross-check did not run");
    }
    v
}

#[derive(Default, Debug)]
struct Tally {
    rays: usize,
    hits: usize,
    ties: usize,
    /// Same primitive, t or u/v apart by more than 1e-5 but within the f32 bound.
    widened: usize,
    errors: Vec<String>,
}

/// 1e-5 relative (`accel::agreement::REL`).
fn close(a: f32, b: f32) -> bool {
    (a - b).abs() <= agreement::REL * a.abs().max(b.abs()).max(1e-30)
}

/// Compare one ray (`accel::agreement`); whether it was a tie, a widened
/// agreement, or why it differs.
fn compare(scene: &Scene, i: usize, r: &Ray, n: Option<Hit>, e: Option<Hit>, occ_n: bool, occ_e: bool) -> (bool, bool, Option<String>) {
    let (tie, widened, err) = match agreement::compare(scene, r, n, e) {
        Agreement::Same => (false, false, None),
        Agreement::Tie => (true, false, None),
        Agreement::Widened => (false, true, None),
        Agreement::Crack => (false, false, Some(format!("ray {i} {r:?}: a vertex crack"))),
        Agreement::OpenEdge => (false, false, Some(format!("ray {i} {r:?}: at an open edge"))),
        Agreement::Differ(why) => (false, false, Some(format!("ray {i} {r:?}: native against embree: {why}"))),
    };
    let err = err.or_else(|| (occ_n != occ_e).then(|| format!("ray {i} {r:?}: occluded native {occ_n} embree {occ_e}")));
    (tie, widened, err)
}

fn cross_check(scene: &Scene, native: &dyn Traversal, embree: &dyn Traversal, rays: &[Ray]) -> Tally {
    let per: Vec<(bool, bool, bool, Option<String>)> = rays
        .par_iter()
        .enumerate()
        .map(|(i, r)| {
            let (n, e) = (native.intersect(r), embree.intersect(r));
            let (tie, widened, err) = compare(scene, i, r, n, e, native.occluded(r), embree.occluded(r));
            // Occlusion on a segment ending before the closest hit, every
            // disagreement counted (no occluder ties on the shipped scenes).
            let err = err.or_else(|| agreement::compare_occlusion(scene, r, n, native, embree, agreement::OccluderTies::Refused).map(|e| format!("ray {i} {r:?} (closest {n:?}): {e}")));
            (n.is_some(), tie, widened, err)
        })
        .collect();
    Tally {
        rays: rays.len(),
        hits: per.iter().filter(|p| p.0).count(),
        ties: per.iter().filter(|p| p.1).count(),
        widened: per.iter().filter(|p| p.2).count(),
        errors: per.into_iter().filter_map(|p| p.3).collect(),
    }
}

#[test]
#[cfg_attr(not(has_embree), ignore = "Embree is not in this build")]
fn embree_agrees_with_native_on_every_shipped_scene() {
    let mut report = Vec::new();
    for (path, kind) in common::shipped_scenes().into_iter().flat_map(|p| embrees().into_iter().map(move |k| (p.clone(), k))) {
        let scene = common::load(&path);
        let native = common::build(BackendKind::Native, &scene.shapes);
        let embree = common::build(kind, &scene.shapes);
        let camera = Camera::from_scene(&scene);
        let mut rays = camera_rays(&camera, 320, 240);
        rays.extend(random_rays(&scene, 76_800, 11));
        let t = cross_check(&scene, native.as_ref(), embree.as_ref(), &rays);
        assert!(t.errors.is_empty(), "{kind} {}: {} disagreements, first: {}", path.display(), t.errors.len(), t.errors[0]);
        // Ties are equal-distance coincidences (rays through a shared edge);
        // pixel-centre camera rays can line up with an edge of a simple mesh
        // (the cube's face diagonals: 0.11 %), so allow up to 0.5 %.
        assert!(t.ties * 200 <= t.hits.max(1), "{kind} {}: {} ties in {} hits", path.display(), t.ties, t.hits);
        report.push(format!("{kind} {}: {} rays, {} hits, {} ties, {} t/u/v beyond 1e-5 (within the f32 bound)", scene.name, t.rays, t.hits, t.ties, t.widened));
    }
    eprintln!("{}", report.join("\n"));
}

#[test]
#[cfg_attr(not(has_embree), ignore = "Embree is not in this build")]
fn embree_batches_match_single_rays() {
    for kind in embrees() {
        batches_match_single_rays(kind);
    }
}

/// Every batch call of one Embree (each mode, coherent and not) against its
/// single-ray calls, with invalid rays inside the batches.
fn batches_match_single_rays(kind: BackendKind) {
    use pathtracer::accel::embree::{BatchMode, EmbreeBackend, Quality};
    let scene = common::load(&common::scene_path("sky", "CBbunny"));
    let (major, _) = kind.embree().unwrap().unwrap();
    let mut embree = EmbreeBackend::build(major, &scene.shapes, 0, Quality::Medium).unwrap();
    let mut rays = camera_rays(&Camera::from_scene(&scene), 64, 48);
    rays.extend(random_rays(&scene, 3000, 5));
    // The benchmark's shadow rays: from camera hits towards one point.
    let shadows = pathtracer::accel::workloads::shadow_rays(&scene, &embree, &camera_rays(&Camera::from_scene(&scene), 64, 48));
    rays.extend(shadows);
    // Invalid rays inside a batch must not disturb their neighbours.
    rays[7].dir = glam::Vec3::ZERO;
    rays[100].origin.x = f32::NAN;
    // Also past the first of the 256-ray chunks the shim's stream mode hands
    // to Embree, and in the last, partial one.
    let last = rays.len() - 1;
    rays[300].dir = glam::Vec3::ZERO;
    rays[last].origin.y = f32::NAN;
    assert!(rays.len() % 256 != 0);
    let single: Vec<Option<Hit>> = rays.iter().map(|r| embree.intersect(r)).collect();
    let single_occ: Vec<bool> = rays.iter().map(|r| embree.occluded(r)).collect();
    for &mode in BatchMode::all(major) {
        embree.set_batch_modes(mode, mode);
        let mut hits = vec![None; rays.len()];
        let mut occ = vec![false; rays.len()];
        for coherent in [false, true] {
            if coherent {
                embree.intersect_coherent(&rays, &mut hits);
                embree.occluded_coherent(&rays, &mut occ);
            } else {
                embree.intersect_batch(&rays, &mut hits);
                embree.occluded_batch(&rays, &mut occ);
            }
            assert_eq!(occ, single_occ, "{kind} {mode:?} coherent={coherent}");
            for (i, (a, b)) in hits.iter().zip(&single).enumerate() {
                let ok = match (a, b) {
                    (None, None) => true,
                    (Some(a), Some(b)) => close(a.t, b.t) && (a.prim_id == b.prim_id || close(a.t, b.t)),
                    _ => false,
                };
                assert!(ok, "{kind} {mode:?} coherent={coherent} ray {i}: batch {a:?} single {b:?}");
            }
        }
        assert!(hits[7].is_none() && hits[100].is_none() && hits[300].is_none() && hits[last].is_none(), "{kind} {mode:?}");
    }
}

#[test]
#[cfg_attr(not(has_embree), ignore = "Embree is not in this build")]
fn normal_images_of_cornell_boxes_are_identical_but_for_ties() {
    let kinds = embrees();
    for (path, kind) in common::shipped_scenes().into_iter().filter(|p| p.file_stem().unwrap().to_string_lossy().starts_with("CB")).flat_map(|p| kinds.iter().map(move |&k| (p.clone(), k))) {
        let scene = common::load(&path);
        let native = common::build(BackendKind::Native, &scene.shapes);
        let embree = common::build(kind, &scene.shapes);
        let mut camera = Camera::from_scene(&scene);
        camera.set_screen_size(320, 240);
        let settings = RenderSettings::new(320, 240, 1, 0);
        let a = render::render(&camera, native.as_ref(), &NormalShading { scene: &scene }, &settings).image;
        let b = render::render(&camera, embree.as_ref(), &NormalShading { scene: &scene }, &settings).image;
        let (mut ties, mut last_bits, mut png_bytes) = (0, 0, 0);
        for y in 0..240u32 {
            for x in 0..320u32 {
                let (pa, pb) = (a.get(x, y), b.get(x, y));
                if pa == pb {
                    continue;
                }
                // The pixel's ray (1 spp: the pixel centre; image row 0 is the top).
                let r = camera.generate_ray((x as f32 + 0.5) / 320.0, ((239 - y) as f32 + 0.5) / 240.0);
                let (hn, he) = (native.intersect(&r), embree.intersect(&r));
                let tie = matches!((hn, he), (Some(p), Some(q)) if (p.geom_id, p.prim_id) != (q.geom_id, q.prim_id) && close(p.t, q.t));
                // Same primitive: only the barycentrics' last bits may differ.
                let same = matches!((hn, he), (Some(p), Some(q)) if (p.geom_id, p.prim_id) == (q.geom_id, q.prim_id))
                    && (pa - pb).abs().max_element() <= 1e-4;
                assert!(tie || same, "{}: pixel {x},{y} differs: {pa} vs {pb} ({hn:?} vs {he:?})", path.display());
                ties += tie as usize;
                last_bits += same as usize;
                let tone = |c: glam::Vec3| [c.x, c.y, c.z].map(pathtracer::image_io::tone_byte);
                png_bytes += (same && tone(pa) != tone(pb)) as usize;
            }
        }
        assert!(ties <= 320 * 240 / 1000, "{kind} {}: {ties} tie pixels", path.display());
        // Floats differ in the last bits wherever the barycentrics do; the
        // 8-bit images a user sees must be identical but for rare rounding.
        assert!(png_bytes <= 320 * 240 / 1000, "{}: {png_bytes} pixels differ in the PNG", path.display());
        eprintln!("{kind} {}: {ties} tie pixels, {last_bits} pixels differing in the last bits of the barycentrics, {png_bytes} of them visible in the 8-bit PNG", scene.name);
    }
}

/// The ABI canary: a library newer than the headers its shim was compiled
/// against may write past the hit structures those headers describe (Embree
/// 4.4.0 writes the instPrimID field 4.2.0's headers lack). Every buffer
/// the shim hands to Embree is padded; this keeps what each library writes,
/// for single rays and packets of 4, 8 and 16, within that padding.
#[test]
#[cfg_attr(not(has_embree), ignore = "Embree is not in this build")]
fn each_embree_writes_within_the_shims_padding() {
    for kind in embrees() {
        let (major, _) = kind.embree().unwrap().unwrap();
        let lib = pathtracer::accel::embree::library(major).unwrap();
        let mut report = Vec::new();
        for width in [1, 4, 8, 16] {
            let (written, padding) = pathtracer::accel::embree::abi_probe(major, width).unwrap();
            assert!(written <= padding, "{kind}: the library wrote {written} bytes past the {width}-ray hit structure; the shim pads {padding}");
            report.push(format!("{width} rays: {written} bytes"));
        }
        // Where headers and library agree, nothing is written past them.
        if lib.version / 100 == lib.header_version / 100 {
            assert!(report.iter().all(|r| r.ends_with(": 0 bytes")), "{kind}: headers and library are the same minor, yet {report:?}");
        }
        eprintln!("{kind} ({}, headers {}): written past the headers' hit structures: {}", lib.version_string(), lib.header_version, report.join(", "));
    }
}

/// Both libraries in one process, each resolving its own symbols: building
/// and tracing with one, then the other, then the first again gives the
/// same hits (with both bound to one library's code, the second would fail
/// or answer with the other's).
#[test]
#[cfg_attr(not(has_embree), ignore = "Embree is not in this build")]
fn both_embrees_live_in_one_process() {
    let kinds = embrees();
    if kinds.len() < 2 {
        eprintln!("SKIPPED: needs both Embree 3 and Embree 4 ({} here)", kinds.len());
        return;
    }
    let scene = common::load(&common::scene_path("sky", "CBspheres"));
    let rays = camera_rays(&Camera::from_scene(&scene), 32, 24);
    let trace = |kind: BackendKind| -> Vec<Option<(u32, u32)>> {
        let b = common::build(kind, &scene.shapes);
        rays.iter().map(|r| b.intersect(r).map(|h| (h.geom_id, h.prim_id))).collect()
    };
    let a = trace(kinds[0]);
    let b = trace(kinds[1]);
    let c = trace(kinds[0]);
    assert_eq!(a, c);
    assert_eq!(a, b);
    let versions: Vec<String> = pathtracer::accel::embree::Major::ALL.iter().map(|&m| pathtracer::accel::embree::version_string(m)).collect();
    assert!(versions[0].starts_with("Embree 3.") && versions[1].starts_with("Embree 4."), "{versions:?}");
}
