//! Distribution tests of the samplers the materials issue added: Pearson
//! chi-square of the microfacet, glass and environment samplers against
//! their own pdfs (family-wise alpha 0.01, Šidák), and the integrals that
//! tie each pdf to its model: ∫ pdf = the probability a sample is valid,
//! ∫ f cos = the mean sampled weight (the directional albedo).

mod common;

use common::{chi2_p, sidak};
use glam::Vec3;
use pathtracer::bsdf::{Bsdf, Glass, Microfacet};
use pathtracer::light::EnvMap;
use pathtracer::rng::Rng;
use std::f64::consts::{PI, TAU};

fn dir(theta_deg: f64) -> Vec3 {
    let t = theta_deg.to_radians();
    Vec3::new(t.sin() as f32, 0.0, t.cos() as f32)
}

fn silver(alpha: f32) -> Microfacet {
    Microfacet { alpha, eta: Vec3::new(0.059193, 0.059881, 0.047366), k: Vec3::new(4.1283, 3.5892, 2.8132), front: true }
}

#[test]
fn microfacet_sampler_fits_its_pdf_and_its_integrals_match() {
    let cases: Vec<(f32, f64)> = vec![(0.15, 20.0), (0.15, 70.0), (0.25, 45.0), (0.25, 80.0), (0.5, 10.0), (0.5, 75.0)];
    let alpha = sidak(0.01, cases.len());
    let (n, rows, cols, sub) = (1_000_000usize, 20usize, 40usize, 24usize);
    for (a, theta) in cases {
        let m = silver(a);
        let b = Bsdf::Microfacet(m);
        let wo = dir(theta);
        // Samples binned over (cos θ, φ); weights summed for the albedo.
        let mut rng = Rng::new(77, theta as u64);
        let mut counts = vec![0.0f64; rows * cols];
        let (mut valid, mut w1, mut w2) = (0usize, 0.0f64, 0.0f64);
        for _ in 0..n {
            let Some(s) = b.sample(wo, &mut rng) else { continue };
            valid += 1;
            let r = ((s.wi.z * rows as f32) as usize).min(rows - 1);
            let phi = (s.wi.y as f64).atan2(s.wi.x as f64).rem_euclid(TAU);
            let c = ((phi / TAU * cols as f64) as usize).min(cols - 1);
            counts[r * cols + c] += 1.0;
            let w = s.weight.x as f64;
            w1 += w;
            w2 += w * w;
        }
        // Expected counts: n ∫_cell pdf dω by the midpoint rule, dω = dcos dφ.
        let (dc, dp) = (1.0 / rows as f64, TAU / cols as f64);
        let mut expected = vec![0.0f64; rows * cols];
        let (mut pdf_total, mut albedo) = (0.0f64, 0.0f64);
        for r in 0..rows {
            for c in 0..cols {
                let mut e = 0.0;
                for i in 0..sub {
                    let z = (r as f64 + (i as f64 + 0.5) / sub as f64) * dc;
                    let s = (1.0 - z * z).max(0.0).sqrt();
                    for j in 0..sub {
                        let phi = (c as f64 + (j as f64 + 0.5) / sub as f64) * dp;
                        let wi = Vec3::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, z as f32);
                        let dw = dc * dp / (sub * sub) as f64;
                        e += b.pdf(wo, wi) as f64 * dw;
                        albedo += b.eval(wo, wi).x as f64 * z * dw;
                    }
                }
                expected[r * cols + c] = e * n as f64;
                pdf_total += e;
            }
        }
        let p = chi2_p(&counts, &expected);
        assert!(p > alpha, "alpha {a} theta {theta}: chi-square p = {p:e}");
        // ∫ pdf dω over the hemisphere = P(sample valid): binomial, 5 sd.
        let pv = valid as f64 / n as f64;
        assert!((pdf_total - pv).abs() <= 5.0 * (pv * (1.0 - pv) / n as f64).sqrt() + 2e-3, "alpha {a} theta {theta}: ∫pdf {pdf_total} vs valid fraction {pv}");
        // ∫ f cos dω = E[weight] (0 for invalid samples), 5 sd + quadrature error.
        let mean = w1 / n as f64;
        let se = ((w2 / n as f64 - mean * mean) / n as f64).sqrt();
        assert!((albedo - mean).abs() <= 5.0 * se + 2e-3, "alpha {a} theta {theta}: ∫ f cos {albedo} vs mean weight {mean} ± {se}");
        eprintln!("alpha {a} theta {theta}: chi2 p {p:.3}, ∫pdf {pdf_total:.4} (valid {pv:.4}), albedo {albedo:.4} vs {mean:.4}");
    }
}

#[test]
fn glass_picks_reflection_with_the_fresnel_probability() {
    // Two cells per angle and side (reflected, transmitted) against F, 1 - F.
    let angles = [0.0f64, 30.0, 40.0, 43.0, 60.0, 85.0];
    let alpha = sidak(0.01, angles.len() * 2);
    let n = 200_000usize;
    for front in [true, false] {
        let g = Glass { reflectance: Vec3::ONE, transmittance: Vec3::ONE, ior: 1.45, front };
        for theta in angles {
            let wo = dir(theta);
            let f = g.fresnel(wo) as f64;
            let mut rng = Rng::new(5, theta as u64 + front as u64 * 100);
            let mut refl = 0.0;
            for _ in 0..n {
                let s = Bsdf::Glass(g).sample(wo, &mut rng).expect("lossless glass always scatters");
                if s.wi.z > 0.0 {
                    refl += 1.0;
                }
            }
            if f >= 1.0 || f <= 0.0 {
                assert_eq!(refl, if f >= 1.0 { n as f64 } else { 0.0 }, "theta {theta} front {front}");
                continue;
            }
            let p = chi2_p(&[refl, n as f64 - refl], &[f * n as f64, (1.0 - f) * n as f64]);
            assert!(p > alpha, "theta {theta} front {front}: reflected {refl} of {n}, F = {f}: p = {p:e}");
        }
    }
}

#[test]
fn environment_sampler_fits_its_pdf() {
    // A small map with a hot spot, zero regions and a gradient; bins at
    // half-texel resolution so the jitter inside texels is tested too.
    let (w, h) = (16usize, 8usize);
    let mut t = Vec::new();
    for j in 0..h {
        for i in 0..w {
            let v = if (i, j) == (5, 2) { Vec3::new(60.0, 50.0, 40.0) } else if (10..13).contains(&i) { Vec3::ZERO } else { Vec3::new(0.2 + 0.1 * j as f32, 0.3, 0.1 * i as f32) };
            t.push(v);
        }
    }
    let env = EnvMap::from_texels("test".into(), w, h, t);
    let (bx, by) = (2 * w, 2 * h);
    let n = 2_000_000usize;
    let mut counts = vec![0.0f64; bx * by];
    let mut rng = Rng::new(9, 9);
    for _ in 0..n {
        let (d, _, pdf) = env.sample(rng.uniform2()).expect("map is not black");
        assert!(pdf > 0.0 && pdf.is_finite());
        let theta = (d.y as f64).clamp(-1.0, 1.0).acos();
        let phi = (-(d.z as f64)).atan2(d.x as f64) + PI;
        let x = ((phi / TAU * bx as f64) as usize).min(bx - 1);
        let y = ((theta / PI * by as f64) as usize).min(by - 1);
        counts[y * bx + x] += 1.0;
    }
    let sub = 16;
    let mut expected = vec![0.0f64; bx * by];
    let mut total = 0.0;
    for y in 0..by {
        for x in 0..bx {
            let mut e = 0.0;
            for a in 0..sub {
                let theta = (y as f64 + (a as f64 + 0.5) / sub as f64) / by as f64 * PI;
                for b in 0..sub {
                    let phi = (x as f64 + (b as f64 + 0.5) / sub as f64) / bx as f64 * TAU;
                    let d = Vec3::new((-phi.cos() * theta.sin()) as f32, theta.cos() as f32, (phi.sin() * theta.sin()) as f32);
                    e += env.pdf(d) as f64 * theta.sin() * (TAU / bx as f64) * (PI / by as f64) / (sub * sub) as f64;
                }
            }
            expected[y * bx + x] = e * n as f64;
            total += e;
        }
    }
    assert!((total - 1.0).abs() < 2e-3, "∫ pdf dω = {total}");
    // chi2_p fails on any sample in a cell of zero expected count (the
    // black columns' inner half-texels).
    let p = chi2_p(&counts, &expected);
    assert!(p > 0.01, "chi-square p = {p:e}");
}
