//! Unit tests of `packet.rs`: the packet set-up's per-ray constants
//! against the single-ray set-up's, and the eight-ray triangle test
//! against the single-ray watertight test, bit for bit.

use super::*;
use crate::rng::Rng;
use glam::Vec3;

/// Every per-ray constant equals the single-ray set-up's bits, for
/// packets of every length with invalid, zero-component, negative and
/// tied-axis rays among them.
#[test]
fn packet_setup_equals_single_ray_setup() {
    if !is_x86_feature_detected!("avx2") {
        eprintln!("SKIPPED packet_setup_equals_single_ray_setup: no AVX2 on this CPU");
        return;
    }
    let mut rng = Rng::new(7, 1);
    let mut u = || rng.uniform() * 2.0 - 1.0;
    let mut rays: Vec<Ray> = (0..400).map(|_| Ray::with_range(Vec3::new(u(), u(), u()) * 10.0, Vec3::new(u(), u(), u()), u().abs(), 5.0 + u())).collect();
    rays[3].dir = Vec3::new(1.0, 1.0, -1.0); // ties between axes
    rays[5].dir = Vec3::new(0.0, -2.0, 0.0);
    rays[9].origin.x = f32::NAN;
    rays[12].dir = Vec3::ZERO;
    rays[14].tmin = 7.0; // tmin > tmax
    rays[20].dir = Vec3::new(-0.0, 0.5, 0.5);
    rays[33].tmax = f32::INFINITY;
    for len in 1..=PACKET {
        for p in rays.chunks(len) {
            let soa = unsafe { RaysSoA::new(p) };
            for (i, r) in p.iter().enumerate() {
                assert_eq!(soa.valid >> i & 1 != 0, r.is_valid(), "validity of {r:?}");
                let slab = Slab::new(r);
                let got = soa.slab(i);
                assert_eq!(got.o.map(f32::to_bits), slab.o.map(f32::to_bits));
                assert_eq!(got.inv.map(f32::to_bits), slab.inv.map(f32::to_bits), "{r:?}");
                assert_eq!(got.near_plane, slab.near_plane);
                assert_eq!((soa.tmin[i], soa.tmax[i]), (r.tmin, r.tmax));
                if r.is_valid() {
                    let (rt, sh) = soa.shear(i);
                    let want = RayTransform::new(r.origin, r.dir);
                    let ws = Shear::new(&want);
                    assert_eq!(rt.shear().0, want.shear().0, "{r:?}");
                    assert_eq!(rt.shear().1.map(f32::to_bits), want.shear().1.map(f32::to_bits), "{r:?}");
                    assert_eq!((sh.k, sh.s.map(f32::to_bits), sh.o), (ws.k, ws.s.map(f32::to_bits), ws.o));
                }
            }
            let b = &soa.bounds;
            let want_uniform = p.iter().all(|r| r.is_valid() && (Vec3::ONE / r.dir).is_finite() && r.dir.is_negative_bitmask() == p[0].dir.is_negative_bitmask());
            assert_eq!(b.uniform, want_uniform);
            for a in 0..3 {
                let lo = p.iter().map(|r| r.origin[a]).fold(f32::INFINITY, f32::min);
                let hi = p.iter().map(|r| 1.0 / r.dir[a]).fold(f32::NEG_INFINITY, f32::max);
                if want_uniform {
                    assert_eq!(b.o_lo[a], lo);
                    assert_eq!(b.inv_hi[a], hi);
                    assert!((b.unit_hi[a] - p.iter().map(|r| r.dir.normalize()[a]).fold(f32::NEG_INFINITY, f32::max)).abs() < 1e-6);
                }
            }
        }
    }
}

/// `hits_triangle` answers exactly as the single-ray watertight test,
/// bit for bit: rays through the triangles' vertices and along their
/// shared edge (exact-zero edge functions, redone in f64), rays ending
/// exactly at their hit or one ulp before it, a degenerate triangle,
/// rays beside them; packets of every length.
#[test]
fn eight_rays_against_one_triangle_equal_the_single_ray_test() {
    if !is_x86_feature_detected!("avx2") {
        eprintln!("SKIPPED eight_rays_against_one_triangle_equal_the_single_ray_test: no AVX2 on this CPU");
        return;
    }
    // Two triangles sharing the edge (1,0,0)-(0,1,0) in the plane z = 0,
    // a tilted one and a degenerate one (all three points on a line).
    let tris = [
        [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)],
        [Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 0.0), Vec3::new(0.0, 1.0, 0.0)],
        [Vec3::new(-0.3, 0.2, -0.4), Vec3::new(1.7, 0.1, 0.6), Vec3::new(0.4, 1.9, 0.2)],
        [Vec3::new(0.0, 0.0, 0.0), Vec3::new(0.5, 0.5, 0.0), Vec3::new(1.0, 1.0, 0.0)],
    ];
    let mut g = TriGroup { v: [[[0.0; 4]; 3]; 3], ids: [[0, 0]; 4] };
    for (lane, t) in tris.iter().enumerate() {
        for (vert, p) in t.iter().enumerate() {
            for a in 0..3 {
                g.v[vert][a][lane] = p[a];
            }
        }
    }
    let mut rng = Rng::new(41, 2);
    let mut rays = Vec::new();
    // Straight down onto the shared edge, the vertices and the corners.
    for k in 0..=16 {
        let f = k as f32 / 16.0;
        for target in [Vec3::new(f, 1.0 - f, 0.0), Vec3::new(f, 0.0, 0.0), Vec3::new(0.0, f, 0.0), Vec3::new(f, f, 0.0)] {
            rays.push(Ray::new(target + Vec3::new(0.0, 0.0, 3.0), Vec3::new(0.0, 0.0, -1.0)));
        }
    }
    // From one point above, at vertices, edges, inside and beside.
    let eye = Vec3::new(0.3, 0.4, 5.0);
    for _ in 0..600 {
        let t = &tris[(rng.uniform() * 4.0) as usize % 4];
        let (a, b) = (rng.uniform(), rng.uniform());
        let target = match (rng.uniform() * 4.0) as u32 {
            0 => t[(a * 3.0) as usize % 3],
            1 => t[0] + (t[1] - t[0]) * a,
            2 => t[0] * (1.0 - a.sqrt()) + t[1] * (a.sqrt() * (1.0 - b)) + t[2] * (a.sqrt() * b),
            _ => t[0] + (t[1] - t[0]) * (a * 2.5 - 0.7) + (t[2] - t[0]) * (b * 2.5 - 0.7),
        };
        rays.push(Ray::new(eye, target - eye));
    }
    // Ranges ending exactly at a hit and one ulp before it.
    let with_hits: Vec<Ray> = rays
        .iter()
        .flat_map(|r| {
            let rt = RayTransform::new(r.origin, r.dir);
            tris.iter().filter_map(move |t| crate::geometry::intersect_triangle(&rt, t[0], t[1], t[2], 0.0, f32::INFINITY)).map(|h| h.0).collect::<Vec<_>>().into_iter().flat_map(move |t| {
                [Ray::with_range(r.origin, r.dir, 0.0, t), Ray::with_range(r.origin, r.dir, 0.0, f32::from_bits(t.to_bits() - 1))]
            })
        })
        .collect();
    rays.extend(with_hits);
    let (mut tested, mut hits) = (0usize, 0usize);
    for len in [PACKET, 11, 3] {
        for p in rays.chunks(len) {
            let soa = unsafe { RaysSoA::new(p) };
            let Some(k) = soa.shared_axes() else { continue };
            for lane in 0..4 {
                for half in 0..PACKET / 8 {
                    let got = unsafe { soa.hits_triangle(&g, lane, half, k, &soa.tmax) };
                    for r in 0..8 {
                        let i = 8 * half + r;
                        if i >= p.len() {
                            continue;
                        }
                        let rt = RayTransform::new(p[i].origin, p[i].dir);
                        let want = scalar_lane(&g, lane, &rt, p[i].tmin, p[i].tmax).is_some();
                        assert_eq!(got >> r & 1 != 0, want, "ray {:?} against triangle {lane}", p[i]);
                        tested += 1;
                        hits += want as usize;
                    }
                }
            }
        }
    }
    assert!(tested > 5000 && hits > 1000, "too few cases: {tested} tested, {hits} hits");
}
