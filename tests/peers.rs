//! The peer BVH libraries the benchmark times (`--features peers`) answer
//! the same queries as our backends, so their Mrays/s are for the same
//! work. Without the feature this file is empty: `scripts/test.sh` runs the
//! suite with it.
#![cfg(feature = "peers")]

use pathtracer::accel::obvhs_peer::ObvhsPeer;
use pathtracer::accel::tinybvh_peer::{Build, TinyBvhPeer};
use pathtracer::accel::{self, BackendKind, Traversal};
use pathtracer::accel::workloads::{camera_rays, random_rays, shadow_rays};
use pathtracer::app::bench::load_bench_scene;
use pathtracer::camera::Camera;

#[test]
fn obvhs_finds_the_hits_native_finds() {
    finds_the_hits_native_finds("obvhs", |s| Box::new(ObvhsPeer::build(s).unwrap()));
}

#[test]
fn tinybvh_finds_the_hits_native_finds() {
    finds_the_hits_native_finds("tinybvh", |s| Box::new(TinyBvhPeer::build(s, Build::Sah).unwrap()));
    finds_the_hits_native_finds("tinybvh-hq", |s| Box::new(TinyBvhPeer::build(s, Build::Hq).unwrap()));
}

fn finds_the_hits_native_finds(name: &str, build: impl Fn(&[pathtracer::scene::Shape]) -> Box<dyn Traversal>) {
    for spec in ["arch:100k", "grass:50k", "sphere:20k"] {
        let scene = load_bench_scene(spec).unwrap();
        let native = accel::build(BackendKind::Native, &scene.shapes, 0).unwrap().accel;
        let peer = build(&scene.shapes);
        let cam = camera_rays(&Camera::from_scene(&scene), 160, 120);
        let mut rays = cam.clone();
        rays.extend(random_rays(&scene, 20_000, 3));
        let shadow = shadow_rays(&scene, native.as_ref(), &cam);
        let (mut differ, mut hits) = (0usize, 0usize);
        for r in &rays {
            match (native.intersect(r), peer.intersect(r)) {
                (Some(a), Some(b)) => {
                    hits += 1;
                    // Möller-Trumbore (obvhs) and the watertight test
                    // (ours) round differently; the same surface is hit.
                    if (a.t - b.t).abs() > 1e-4 * a.t.max(1.0) {
                        differ += 1;
                    }
                }
                (None, None) => {}
                _ => differ += 1,
            }
        }
        for r in &shadow {
            if native.occluded(r) != peer.occluded(r) {
                differ += 1;
            }
        }
        let total = rays.len() + shadow.len();
        eprintln!("{name} {spec}: {differ} of {total} answers differ ({hits} hits)");
        assert!(hits > rays.len() / 10, "{name} {spec}: too few hits to compare ({hits})");
        // Edge-grazing rays may go either way without a watertight test.
        assert!(differ * 1000 <= total, "{name} {spec}: {differ} of {total} answers differ from native");
    }
}

/// The work counts profiles set side by side (`examples/trace_rays`
/// KIND `work`) follow each tree's walk: a ray that hits tested at least
/// one node and one triangle (native: a node and a leaf group), a ray
/// leaving the scene's box away from it tests no triangle (native: the
/// root's children's boxes only), and the walks cull: far fewer tests
/// per ray than triangles.
#[test]
fn work_counts_follow_the_walks() {
    use pathtracer::accel::wide::{WideBvh, NATIVE_WIDTH};
    use pathtracer::ray::Ray;
    let scene = load_bench_scene("sphere:20k").unwrap();
    let obvhs = ObvhsPeer::build(&scene.shapes).unwrap();
    let native = WideBvh::<NATIVE_WIDTH>::build(&scene.shapes);
    let rays = random_rays(&scene, 4000, 5);
    let (mut nodes, mut tests, mut hits) = (0u64, 0u64, 0usize);
    for r in &rays {
        let (n, t) = obvhs.closest_work(r);
        if obvhs.intersect(r).is_some() {
            hits += 1;
            assert!(n >= 1 && t >= 1, "a hit with {n} node tests and {t} triangle tests");
            assert!(native.closest_work(std::slice::from_ref(r)) >= 2.0, "native: a hit without a node and a leaf group");
        }
        nodes += n as u64;
        tests += t as u64;
    }
    assert!(hits > rays.len() / 10, "too few hits ({hits})");
    let per_ray = tests as f64 / rays.len() as f64;
    assert!(per_ray < 200.0, "obvhs tests {per_ray:.1} triangles a ray of 20k: its walk does not cull");
    assert!(nodes >= rays.len() as u64 / 2, "obvhs: {nodes} node tests for {} rays", rays.len());
    let b = scene.bounds();
    let away = Ray::new(b.max + b.extent(), b.extent().normalize());
    assert_eq!(obvhs.closest_work(&away).1, 0, "a ray leaving the box tested a triangle");
    assert!(native.closest_work(&[away]) <= 1.0, "native: a ray missing the scene went past the root");
}
