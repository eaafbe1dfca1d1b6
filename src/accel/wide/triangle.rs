//! The watertight ray–triangle test of `intersect_triangle`, written once
//! over the lane width (`watertight`, generic over `Lanes`) and called at
//! four shapes: one ray against a group of four triangles (SSE2,
//! `intersect_group`), two rays against it (AVX2, `intersect_group_x2`),
//! four rays (AVX-512, `intersect_group_x4`), and eight rays of a packet
//! against one triangle (AVX2, `RaysSoA::hits_triangle`). The shapes
//! differ only in what they load into the lanes; every lane performs the
//! scalar test's operations in its order, and a lane with an edge function
//! exactly 0 (which the scalar test redoes in f64) is handed to
//! `intersect_triangle` itself, so every answer is the scalar one bit for
//! bit. Targets without x86 SIMD run the scalar test a lane at a time.

use super::{TriGroup, LANES};
use crate::geometry::{intersect_triangle, RayTransform};
use glam::Vec3;

#[cfg(target_arch = "x86_64")]
use super::lanes::Lanes;
#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// The watertight test's per-ray shear, as axis indices and broadcastable constants.
pub(super) struct Shear {
    pub(super) k: [usize; 3],
    pub(super) s: [f32; 3],
    pub(super) o: [f32; 3],
}

impl Shear {
    pub(super) fn new(rt: &RayTransform) -> Self {
        let (k, s) = rt.shear();
        Shear { k, s, o: rt.origin.to_array() }
    }
}

#[derive(Clone, Copy, Default)]
pub(super) struct LaneHit {
    pub(super) t: f32,
    pub(super) u: f32,
    pub(super) v: f32,
}

/// What `watertight` finds per lane: bit i of `mask` when lane i hits in
/// (tmin, tmax]; bit i of `any_zero` when an edge function is exactly 0
/// there (the lane is left out of `mask`; the scalar test decides it);
/// `t`, `u`, `v` valid in `mask`'s lanes (not computed when no lane hits).
#[cfg(target_arch = "x86_64")]
pub(super) struct Tested<V> {
    pub(super) mask: u32,
    pub(super) any_zero: u32,
    pub(super) t: V,
    pub(super) u: V,
    pub(super) v: V,
}

/// The watertight test in every lane: vertices `p[0..3]` and the ray's
/// origin `o`, each on the ray's permuted axes (kx, ky, kz), and its shear
/// `s`; `range` gives (tmin, tmax), asked only when some lane hits. The
/// operations and their order are `intersect_triangle`'s.
///
/// # Safety
/// The CPU must have `V`'s instruction set; the caller is compiled with it.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn watertight<V: Lanes>(p: [[V; 3]; 3], o: [V; 3], s: [V; 3], range: impl FnOnce() -> (V, V)) -> Tested<V> {
    let zero = V::splat(0.0);
    // a = p - origin, per permuted axis; then the shear of x and y.
    let rel = |q: [V; 3]| [q[0].sub(o[0]), q[1].sub(o[1]), q[2].sub(o[2])];
    let (a, b, c) = (rel(p[0]), rel(p[1]), rel(p[2]));
    let ax = a[0].sub(s[0].mul(a[2]));
    let ay = a[1].sub(s[1].mul(a[2]));
    let bx = b[0].sub(s[0].mul(b[2]));
    let by = b[1].sub(s[1].mul(b[2]));
    let cx = c[0].sub(s[0].mul(c[2]));
    let cy = c[1].sub(s[1].mul(c[2]));
    // edge(p, q) = qx*py - qy*px, as in the scalar code.
    let e0 = cx.mul(by).sub(cy.mul(bx));
    let e1 = ax.mul(cy).sub(ay.mul(cx));
    let e2 = bx.mul(ay).sub(by.mul(ax));
    let any_zero = V::bits(V::or(V::or(e0.eq(zero), e1.eq(zero)), e2.eq(zero)));
    let neg = V::or(V::or(e0.lt(zero), e1.lt(zero)), e2.lt(zero));
    let pos = V::or(V::or(e0.gt(zero), e1.gt(zero)), e2.gt(zero));
    let det = e0.add(e1).add(e2);
    // det finite: |det| < inf (false for NaN).
    let finite = det.abs().lt(V::splat(f32::INFINITY));
    let mut ok = V::and_not(V::and(neg, pos), V::and(finite, det.ne(zero)));
    let az = s[2].mul(a[2]);
    let bz = s[2].mul(b[2]);
    let cz = s[2].mul(c[2]);
    let ts = e0.mul(az).add(e1.mul(bz)).add(e2.mul(cz));
    // Behind the origin: det and t_scaled of opposite signs (or t_scaled 0).
    let behind = V::or(V::and(det.gt(zero), ts.le(zero)), V::and(det.lt(zero), ts.ge(zero)));
    ok = V::and_not(behind, ok);
    let mut mask = V::bits(ok) & !any_zero;
    let (mut t, mut u, mut v) = (zero, zero, zero);
    if mask != 0 {
        let inv = V::splat(1.0).div(det);
        t = ts.mul(inv);
        let (tmin, tmax) = range();
        mask &= V::bits(V::and(t.gt(tmin), t.le(tmax)));
        u = e1.mul(inv);
        v = e2.mul(inv);
    }
    Tested { mask, any_zero, t, u, v }
}

/// The watertight test on four triangles at once; bit i set when lane i hits
/// in (tmin, tmax]. Lane results equal `intersect_triangle` bit for bit.
#[inline(always)]
pub(super) fn intersect_group(g: &TriGroup, rt: &RayTransform, sh: &Shear, tmin: f32, tmax: f32, out: &mut [LaneHit; LANES]) -> u32 {
    #[cfg(target_arch = "x86_64")]
    unsafe {
        let ld = |v: usize, a: usize| _mm_load_ps(g.v[v][sh.k[a]].as_ptr());
        let p = [[ld(0, 0), ld(0, 1), ld(0, 2)], [ld(1, 0), ld(1, 1), ld(1, 2)], [ld(2, 0), ld(2, 1), ld(2, 2)]];
        let o = |a: usize| _mm_set1_ps(sh.o[sh.k[a]]);
        let s = |a: usize| _mm_set1_ps(sh.s[a]);
        let tested = watertight::<__m128>(p, [o(0), o(1), o(2)], [s(0), s(1), s(2)], || (_mm_set1_ps(tmin), _mm_set1_ps(tmax)));
        per_ray(g, [rt], [tmin], [tmax], &tested, std::array::from_mut(out))[0]
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = sh;
        intersect_group_scalar(g, rt, tmin, tmax, out)
    }
}

/// `intersect_group` for two rays at once, ray `r` in the 128-bit half `r`
/// of each AVX register: each ray's mask and hits are exactly those of
/// `intersect_group` for that ray.
///
/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn intersect_group_x2(g: &TriGroup, rt: [&RayTransform; 2], sh: [&Shear; 2], tmin: [f32; 2], tmax: [f32; 2], out: &mut [[LaneHit; LANES]; 2]) -> [u32; 2] {
    // The closures return SSE values only: a closure left out of line
    // would call AVX intrinsics from code built without AVX.
    let row = |v: usize, a: usize| [_mm_load_ps(g.v[v][sh[0].k[a]].as_ptr()), _mm_load_ps(g.v[v][sh[1].k[a]].as_ptr())];
    let each = |x: [f32; 2]| [_mm_set1_ps(x[0]), _mm_set1_ps(x[1])];
    let o = |a: usize| each([sh[0].o[sh[0].k[a]], sh[1].o[sh[1].k[a]]]);
    let s = |a: usize| each([sh[0].s[a], sh[1].s[a]]);
    let p = [pair3([row(0, 0), row(0, 1), row(0, 2)]), pair3([row(1, 0), row(1, 1), row(1, 2)]), pair3([row(2, 0), row(2, 1), row(2, 2)])];
    let tested = watertight::<__m256>(p, pair3([o(0), o(1), o(2)]), pair3([s(0), s(1), s(2)]), || (pair(each(tmin)), pair(each(tmax))));
    per_ray(g, rt, tmin, tmax, &tested, out)
}

/// `intersect_group` for four rays at once, ray `r` in the 128-bit lane `r`
/// of each AVX-512 register. Each ray's mask and hits are exactly
/// `intersect_group`'s.
///
/// # Safety
/// The CPU must have AVX-512F.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn intersect_group_x4(g: &TriGroup, rt: [&RayTransform; 4], sh: [&Shear; 4], tmin: [f32; 4], tmax: [f32; 4], out: &mut [[LaneHit; LANES]; 4]) -> [u32; 4] {
    // As in `intersect_group_x2`, the closures return SSE values only.
    let row = |v: usize, r: usize, a: usize| _mm_load_ps(g.v[v][sh[r].k[a]].as_ptr());
    let rows = |v: usize, a: usize| [row(v, 0, a), row(v, 1, a), row(v, 2, a), row(v, 3, a)];
    let each = |x: [f32; 4]| [_mm_set1_ps(x[0]), _mm_set1_ps(x[1]), _mm_set1_ps(x[2]), _mm_set1_ps(x[3])];
    let p = [[rows(0, 0), rows(0, 1), rows(0, 2)], [rows(1, 0), rows(1, 1), rows(1, 2)], [rows(2, 0), rows(2, 1), rows(2, 2)]];
    let o = |a: usize| each([sh[0].o[sh[0].k[a]], sh[1].o[sh[1].k[a]], sh[2].o[sh[2].k[a]], sh[3].o[sh[3].k[a]]]);
    let s = |a: usize| each([sh[0].s[a], sh[1].s[a], sh[2].s[a], sh[3].s[a]]);
    let p = [quad3(p[0]), quad3(p[1]), quad3(p[2])];
    let tested = watertight::<__m512>(p, quad3([o(0), o(1), o(2)]), quad3([s(0), s(1), s(2)]), || (quad(each(tmin)), quad(each(tmax))));
    per_ray(g, rt, tmin, tmax, &tested, out)
}

/// Two 128-bit registers as one AVX register, `x[r]` in half `r`.
///
/// # Safety
/// The CPU must have AVX.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn pair(x: [__m128; 2]) -> __m256 {
    _mm256_set_m128(x[1], x[0])
}

/// `pair` of three.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn pair3(x: [[__m128; 2]; 3]) -> [__m256; 3] {
    [pair(x[0]), pair(x[1]), pair(x[2])]
}

/// Four 128-bit registers as one AVX-512 register, `x[r]` in lane `r`.
///
/// # Safety
/// The CPU must have AVX-512F.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn quad(x: [__m128; 4]) -> __m512 {
    let lo = _mm512_insertf32x4::<1>(_mm512_castps128_ps512(x[0]), x[1]);
    _mm512_insertf32x4::<3>(_mm512_insertf32x4::<2>(lo, x[2]), x[3])
}

/// `quad` of three.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn quad3(x: [[__m128; 4]; 3]) -> [__m512; 3] {
    [quad(x[0]), quad(x[1]), quad(x[2])]
}

/// The group tests' common end, for `N` rays whose results sit in lanes
/// `LANES * r ..` of the registers: each ray's mask, its lanes' `t`, `u`,
/// `v` (stored when some lane hit) into `out[r]`, and lanes with an exact
/// zero edge function decided by the scalar test (in f64).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn per_ray<V: Lanes, const N: usize>(g: &TriGroup, rt: [&RayTransform; N], tmin: [f32; N], tmax: [f32; N], tested: &Tested<V>, out: &mut [[LaneHit; LANES]; N]) -> [u32; N] {
    let lanes = (1u32 << LANES) - 1;
    let mut masks = [0u32; N];
    let mut tuv = [[0.0f32; 4 * LANES]; 3];
    if tested.mask != 0 {
        unsafe {
            tested.t.store(tuv[0].as_mut_ptr());
            tested.u.store(tuv[1].as_mut_ptr());
            tested.v.store(tuv[2].as_mut_ptr());
        }
    }
    for r in 0..N {
        masks[r] = (tested.mask >> (LANES * r)) & lanes;
        if tested.mask != 0 {
            for lane in 0..LANES {
                let k = r * LANES + lane;
                out[r][lane] = LaneHit { t: tuv[0][k], u: tuv[1][k], v: tuv[2][k] };
            }
        }
        let mut z = (tested.any_zero >> (LANES * r)) & lanes;
        while z != 0 {
            let lane = z.trailing_zeros() as usize;
            z &= z - 1;
            if let Some((t, u, v)) = scalar_lane(g, lane, rt[r], tmin[r], tmax[r]) {
                out[r][lane] = LaneHit { t, u, v };
                masks[r] |= 1 << lane;
            }
        }
    }
    masks
}

/// `intersect_group` one lane at a time with `intersect_triangle` itself,
/// for targets without x86 SIMD (and the unit tests).
#[cfg_attr(target_arch = "x86_64", allow(dead_code))]
pub(super) fn intersect_group_scalar(g: &TriGroup, rt: &RayTransform, tmin: f32, tmax: f32, out: &mut [LaneHit; LANES]) -> u32 {
    let mut mask = 0;
    for lane in 0..LANES {
        if let Some((t, u, v)) = scalar_lane(g, lane, rt, tmin, tmax) {
            out[lane] = LaneHit { t, u, v };
            mask |= 1 << lane;
        }
    }
    mask
}

/// Lane `lane` of `g` by the scalar test.
#[inline]
pub(super) fn scalar_lane(g: &TriGroup, lane: usize, rt: &RayTransform, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
    let p = |k: usize| Vec3::new(g.v[k][0][lane], g.v[k][1][lane], g.v[k][2][lane]);
    intersect_triangle(rt, p(0), p(1), p(2), tmin, tmax)
}
