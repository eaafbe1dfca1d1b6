//! The SIMD kernels: the slab test of a node's boxes (SSE2, AVX2, scalar)
//! and the watertight test of a group of four triangles (SSE2, scalar; AVX2
//! for two rays at once). All paths perform the same per-lane operations in
//! the same order.

use super::{Node, TriGroup, LANES};
use crate::accel::bvh::ROBUST_SCALE;
use crate::geometry::{intersect_triangle, RayTransform};
use crate::ray::Ray;
use glam::Vec3;
use std::ops::Div;

/// Insertion sort of at most 8 entered children by entry distance, farthest
/// first: pushed in that order, the nearest is visited next.
#[inline(always)]
pub(super) fn sort_far_first<T: Copy>(h: &mut [T], dist: impl Fn(&T) -> f32) {
    for i in 1..h.len() {
        let mut j = i;
        while j > 0 && dist(&h[j - 1]) < dist(&h[j]) {
            h.swap(j - 1, j);
            j -= 1;
        }
    }
}

/// Per-ray slab-test constants:
/// true reciprocals, near/far planes chosen by the direction's sign bit, and
/// comparisons written so a NaN (origin on a plane, zero direction) is ignored.
pub(super) struct Slab {
    pub(super) o: [f32; 3],
    pub(super) inv: [f32; 3],
    /// Index into `Node::bounds` of the near plane per axis (min or max).
    pub(super) near_plane: [usize; 3],
}

impl Slab {
    pub(super) fn new(ray: &Ray) -> Self {
        let d = ray.dir;
        let neg = [d.x.is_sign_negative(), d.y.is_sign_negative(), d.z.is_sign_negative()];
        Slab {
            o: ray.origin.to_array(),
            // One SIMD division; each lane is the exact scalar quotient.
            inv: glam::Vec3A::ONE.div(glam::Vec3A::from(d)).to_array(),
            near_plane: [if neg[0] { 3 } else { 0 }, if neg[1] { 4 } else { 1 }, if neg[2] { 5 } else { 2 }],
        }
    }

    /// Bit i set when child i's box is entered in [tmin, tmax]; `near` gets
    /// entry distances. Every path does the same per-lane operations: the
    /// far distance and `tmax` enlarged by `ROBUST_SCALE` (a rounded-up entry
    /// distance must not cull a primitive hit at exactly `tmax`, which the
    /// range `(tmin, tmax]` includes: a shadow ray's end on a light), and `max(tn, t0)` /
    /// `min(tf, t1)` returning their second operand when the first is NaN.
    #[inline(always)]
    pub(super) fn test<const W: usize, const AVX: bool>(&self, n: &Node<W>, tmin: f32, tmax: f32, near: &mut [f32; W]) -> u32 {
        #[cfg(target_arch = "x86_64")]
        unsafe {
            use std::arch::x86_64::*;
            let rows = n.bounds.as_ptr() as *const f32;
            if AVX && W == 8 {
                let (t0, t1) = self.entry_exit_avx(n, tmin, tmax);
                _mm256_storeu_ps(near.as_mut_ptr(), t0);
                return _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1)) as u32;
            }
            let mut mask = 0;
            for c in (0..W).step_by(4) {
                let mut t0 = _mm_set1_ps(tmin);
                let mut t1 = _mm_set1_ps(tmax * ROBUST_SCALE);
                let scale = _mm_set1_ps(ROBUST_SCALE);
                for a in 0..3 {
                    let o = _mm_set1_ps(self.o[a]);
                    let inv = _mm_set1_ps(self.inv[a]);
                    let lo = _mm_load_ps(rows.add(self.near_plane[a] * W + c));
                    let hi = _mm_load_ps(rows.add((self.near_plane[a] + 3) % 6 * W + c));
                    let tn = _mm_mul_ps(_mm_sub_ps(lo, o), inv);
                    let tf = _mm_mul_ps(_mm_mul_ps(_mm_sub_ps(hi, o), inv), scale);
                    // maxps(a, b) = a > b ? a : b, so a NaN in tn leaves t0 as it is.
                    t0 = _mm_max_ps(tn, t0);
                    t1 = _mm_min_ps(tf, t1);
                }
                _mm_storeu_ps(near.as_mut_ptr().add(c), t0);
                mask |= (_mm_movemask_ps(_mm_cmple_ps(t0, t1)) as u32) << c;
            }
            mask
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            self.test_scalar(n, tmin, tmax, near)
        }
    }

    /// The AVX2 body of `test`: per child of an 8-wide node, the entry
    /// distance and the (scaled) exit distance; the ray enters child i when
    /// lane i has entry ≤ exit. Shared with `masked`, whose per-ray node
    /// tests must do exactly these operations.
    ///
    /// # Safety
    /// The caller runs with AVX2 enabled; `W` must be 8.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(super) unsafe fn entry_exit_avx<const W: usize>(&self, n: &Node<W>, tmin: f32, tmax: f32) -> (std::arch::x86_64::__m256, std::arch::x86_64::__m256) {
        use std::arch::x86_64::*;
        debug_assert_eq!(W, 8);
        // Rows are 32 bytes and the node is 64-byte aligned.
        let rows = n.bounds.as_ptr() as *const f32;
        let load = |p: usize| _mm256_load_ps(rows.add(p * W));
        let lo = [load(self.near_plane[0]), load(self.near_plane[1]), load(self.near_plane[2])];
        let hi = [load((self.near_plane[0] + 3) % 6), load((self.near_plane[1] + 3) % 6), load((self.near_plane[2] + 3) % 6)];
        slab_planes_avx(&lo, &hi, self.o, self.inv, tmin, tmax * ROBUST_SCALE)
    }

    /// `test` one lane at a time, for targets without x86 SIMD (and the
    /// unit tests, which check that every path gives the same bits).
    #[cfg_attr(target_arch = "x86_64", allow(dead_code))]
    pub(super) fn test_scalar<const W: usize>(&self, n: &Node<W>, tmin: f32, tmax: f32, near: &mut [f32; W]) -> u32 {
        let mut mask = 0;
        for lane in 0..W {
            let (mut t0, mut t1) = (tmin, tmax * ROBUST_SCALE);
            for a in 0..3 {
                let lo = n.bounds[self.near_plane[a]][lane];
                let hi = n.bounds[(self.near_plane[a] + 3) % 6][lane];
                let tn = (lo - self.o[a]) * self.inv[a];
                let tf = (hi - self.o[a]) * self.inv[a] * ROBUST_SCALE;
                // As maxps/minps: a NaN distance leaves the bound as it is.
                if tn > t0 {
                    t0 = tn;
                }
                if tf < t1 {
                    t1 = tf;
                }
            }
            near[lane] = t0;
            if t0 <= t1 {
                mask |= 1 << lane;
            }
        }
        mask
    }
}

/// The slab test of one ray against 8 boxes whose near and far planes are
/// already loaded (`lo`, `hi`, per axis), `far` being `tmax` enlarged by
/// `ROBUST_SCALE`: per box, the entry and the (scaled) exit distance. The
/// one sequence of operations behind `Slab::entry_exit_avx` and the
/// streams' node tests (`stream`), whose rays share their planes.
///
/// # Safety
/// The caller runs with AVX2 enabled.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn slab_planes_avx(
    lo: &[std::arch::x86_64::__m256; 3],
    hi: &[std::arch::x86_64::__m256; 3],
    o: [f32; 3],
    inv: [f32; 3],
    tmin: f32,
    far: f32,
) -> (std::arch::x86_64::__m256, std::arch::x86_64::__m256) {
    use std::arch::x86_64::*;
    let scale = _mm256_set1_ps(ROBUST_SCALE);
    let mut t0 = _mm256_set1_ps(tmin);
    let mut t1 = _mm256_set1_ps(far);
    for a in 0..3 {
        let o = _mm256_set1_ps(o[a]);
        let inv = _mm256_set1_ps(inv[a]);
        let tn = _mm256_mul_ps(_mm256_sub_ps(lo[a], o), inv);
        let tf = _mm256_mul_ps(_mm256_mul_ps(_mm256_sub_ps(hi[a], o), inv), scale);
        // maxps(a, b) = a > b ? a : b, so a NaN in tn leaves t0 as it is.
        t0 = _mm256_max_ps(tn, t0);
        t1 = _mm256_min_ps(tf, t1);
    }
    (t0, t1)
}

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

/// The watertight test on four triangles at once; bit i set when lane i hits
/// in (tmin, tmax]. Lane results equal `intersect_triangle` bit for bit; a
/// lane with an edge function exactly 0 (which needs the f64 path) is
/// handed to `intersect_triangle` itself.
#[inline(always)]
pub(super) fn intersect_group(g: &TriGroup, rt: &RayTransform, sh: &Shear, tmin: f32, tmax: f32, out: &mut [LaneHit; LANES]) -> u32 {
    #[cfg(target_arch = "x86_64")]
    unsafe {
        use std::arch::x86_64::*;
        let [kx, ky, kz] = sh.k;
        let ld = |k: usize, a: usize| _mm_load_ps(g.v[k][a].as_ptr());
        let (ox, oy, oz) = (_mm_set1_ps(sh.o[kx]), _mm_set1_ps(sh.o[ky]), _mm_set1_ps(sh.o[kz]));
        let (sx, sy, sz) = (_mm_set1_ps(sh.s[0]), _mm_set1_ps(sh.s[1]), _mm_set1_ps(sh.s[2]));
        // a = p - origin, per needed axis, then the shear.
        let axk = _mm_sub_ps(ld(0, kx), ox);
        let ayk = _mm_sub_ps(ld(0, ky), oy);
        let azk = _mm_sub_ps(ld(0, kz), oz);
        let bxk = _mm_sub_ps(ld(1, kx), ox);
        let byk = _mm_sub_ps(ld(1, ky), oy);
        let bzk = _mm_sub_ps(ld(1, kz), oz);
        let cxk = _mm_sub_ps(ld(2, kx), ox);
        let cyk = _mm_sub_ps(ld(2, ky), oy);
        let czk = _mm_sub_ps(ld(2, kz), oz);
        let ax = _mm_sub_ps(axk, _mm_mul_ps(sx, azk));
        let ay = _mm_sub_ps(ayk, _mm_mul_ps(sy, azk));
        let bx = _mm_sub_ps(bxk, _mm_mul_ps(sx, bzk));
        let by = _mm_sub_ps(byk, _mm_mul_ps(sy, bzk));
        let cx = _mm_sub_ps(cxk, _mm_mul_ps(sx, czk));
        let cy = _mm_sub_ps(cyk, _mm_mul_ps(sy, czk));
        // edge(p, q) = qx*py - qy*px, as in the scalar code.
        let e0 = _mm_sub_ps(_mm_mul_ps(cx, by), _mm_mul_ps(cy, bx));
        let e1 = _mm_sub_ps(_mm_mul_ps(ax, cy), _mm_mul_ps(ay, cx));
        let e2 = _mm_sub_ps(_mm_mul_ps(bx, ay), _mm_mul_ps(by, ax));
        let zero = _mm_setzero_ps();
        let any_zero = _mm_movemask_ps(_mm_or_ps(_mm_or_ps(_mm_cmpeq_ps(e0, zero), _mm_cmpeq_ps(e1, zero)), _mm_cmpeq_ps(e2, zero))) as u32;
        let neg = _mm_or_ps(_mm_or_ps(_mm_cmplt_ps(e0, zero), _mm_cmplt_ps(e1, zero)), _mm_cmplt_ps(e2, zero));
        let pos = _mm_or_ps(_mm_or_ps(_mm_cmpgt_ps(e0, zero), _mm_cmpgt_ps(e1, zero)), _mm_cmpgt_ps(e2, zero));
        let det = _mm_add_ps(_mm_add_ps(e0, e1), e2);
        // det finite: |det| < inf (false for NaN).
        let abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7fff_ffff));
        let finite = _mm_cmplt_ps(_mm_and_ps(det, abs_mask), _mm_set1_ps(f32::INFINITY));
        let mut ok = _mm_andnot_ps(_mm_and_ps(neg, pos), _mm_and_ps(finite, _mm_cmpneq_ps(det, zero)));
        let az = _mm_mul_ps(sz, azk);
        let bz = _mm_mul_ps(sz, bzk);
        let cz = _mm_mul_ps(sz, czk);
        let ts = _mm_add_ps(_mm_add_ps(_mm_mul_ps(e0, az), _mm_mul_ps(e1, bz)), _mm_mul_ps(e2, cz));
        // Behind the origin: det and t_scaled of opposite signs (or t_scaled 0).
        let behind = _mm_or_ps(_mm_and_ps(_mm_cmpgt_ps(det, zero), _mm_cmple_ps(ts, zero)), _mm_and_ps(_mm_cmplt_ps(det, zero), _mm_cmpge_ps(ts, zero)));
        ok = _mm_andnot_ps(behind, ok);
        let mut mask = _mm_movemask_ps(ok) as u32 & !any_zero;
        let mut tuv = [[0.0f32; LANES]; 3];
        if mask != 0 {
            let inv = _mm_div_ps(_mm_set1_ps(1.0), det);
            let t = _mm_mul_ps(ts, inv);
            let in_range = _mm_and_ps(_mm_cmpgt_ps(t, _mm_set1_ps(tmin)), _mm_cmple_ps(t, _mm_set1_ps(tmax)));
            mask &= _mm_movemask_ps(in_range) as u32;
            _mm_storeu_ps(tuv[0].as_mut_ptr(), t);
            _mm_storeu_ps(tuv[1].as_mut_ptr(), _mm_mul_ps(e1, inv));
            _mm_storeu_ps(tuv[2].as_mut_ptr(), _mm_mul_ps(e2, inv));
        }
        per_ray(g, [rt], [tmin], [tmax], mask, any_zero, &tuv, std::array::from_mut(out))[0]
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = sh;
        intersect_group_scalar(g, rt, tmin, tmax, out)
    }
}

/// The SIMD triangle tests' common end, for `N` rays whose results sit
/// in lanes `LANES * r ..` of the registers: each ray's mask, its lanes of
/// `tuv` (`t`, `u`, `v` rows, stored when some lane hit) into `out[r]`,
/// and lanes with an exact zero edge function (in `any_zero`) decided by
/// the scalar test (in f64).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn per_ray<const N: usize, const L: usize>(g: &TriGroup, rt: [&RayTransform; N], tmin: [f32; N], tmax: [f32; N], mask: u32, any_zero: u32, tuv: &[[f32; L]; 3], out: &mut [[LaneHit; LANES]; N]) -> [u32; N] {
    let lanes = (1u32 << LANES) - 1;
    let mut masks = [0u32; N];
    for r in 0..N {
        masks[r] = (mask >> (LANES * r)) & lanes;
        if mask != 0 {
            for lane in 0..LANES {
                let k = r * LANES + lane;
                out[r][lane] = LaneHit { t: tuv[0][k], u: tuv[1][k], v: tuv[2][k] };
            }
        }
        let mut z = (any_zero >> (LANES * r)) & lanes;
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

#[inline]
pub(super) fn scalar_lane(g: &TriGroup, lane: usize, rt: &RayTransform, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
    let p = |k: usize| Vec3::new(g.v[k][0][lane], g.v[k][1][lane], g.v[k][2][lane]);
    intersect_triangle(rt, p(0), p(1), p(2), tmin, tmax)
}

/// `intersect_group` for two rays at once, ray `r` in the 128-bit half `r`
/// of each AVX register: the same operations on every lane, so each ray's
/// mask and hits are exactly those of `intersect_group` for that ray.
///
/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn intersect_group_x2(g: &TriGroup, rt: [&RayTransform; 2], sh: [&Shear; 2], tmin: [f32; 2], tmax: [f32; 2], out: &mut [[LaneHit; LANES]; 2]) -> [u32; 2] {
    use std::arch::x86_64::*;
    let ld = |k: usize, a0: usize, a1: usize| _mm256_set_m128(_mm_load_ps(g.v[k][a1].as_ptr()), _mm_load_ps(g.v[k][a0].as_ptr()));
    let pair = |x0: f32, x1: f32| _mm256_set_m128(_mm_set1_ps(x1), _mm_set1_ps(x0));
    let ([kx0, ky0, kz0], [kx1, ky1, kz1]) = (sh[0].k, sh[1].k);
    let ox = pair(sh[0].o[kx0], sh[1].o[kx1]);
    let oy = pair(sh[0].o[ky0], sh[1].o[ky1]);
    let oz = pair(sh[0].o[kz0], sh[1].o[kz1]);
    let (sx, sy, sz) = (pair(sh[0].s[0], sh[1].s[0]), pair(sh[0].s[1], sh[1].s[1]), pair(sh[0].s[2], sh[1].s[2]));
    let axk = _mm256_sub_ps(ld(0, kx0, kx1), ox);
    let ayk = _mm256_sub_ps(ld(0, ky0, ky1), oy);
    let azk = _mm256_sub_ps(ld(0, kz0, kz1), oz);
    let bxk = _mm256_sub_ps(ld(1, kx0, kx1), ox);
    let byk = _mm256_sub_ps(ld(1, ky0, ky1), oy);
    let bzk = _mm256_sub_ps(ld(1, kz0, kz1), oz);
    let cxk = _mm256_sub_ps(ld(2, kx0, kx1), ox);
    let cyk = _mm256_sub_ps(ld(2, ky0, ky1), oy);
    let czk = _mm256_sub_ps(ld(2, kz0, kz1), oz);
    let ax = _mm256_sub_ps(axk, _mm256_mul_ps(sx, azk));
    let ay = _mm256_sub_ps(ayk, _mm256_mul_ps(sy, azk));
    let bx = _mm256_sub_ps(bxk, _mm256_mul_ps(sx, bzk));
    let by = _mm256_sub_ps(byk, _mm256_mul_ps(sy, bzk));
    let cx = _mm256_sub_ps(cxk, _mm256_mul_ps(sx, czk));
    let cy = _mm256_sub_ps(cyk, _mm256_mul_ps(sy, czk));
    let e0 = _mm256_sub_ps(_mm256_mul_ps(cx, by), _mm256_mul_ps(cy, bx));
    let e1 = _mm256_sub_ps(_mm256_mul_ps(ax, cy), _mm256_mul_ps(ay, cx));
    let e2 = _mm256_sub_ps(_mm256_mul_ps(bx, ay), _mm256_mul_ps(by, ax));
    let zero = _mm256_setzero_ps();
    // The SSE comparisons' predicates: cmpeq EQ_OQ, cmplt LT_OS, cmpgt
    // GT_OS, cmple LE_OS, cmpge GE_OS, cmpneq NEQ_UQ.
    let eq = |a, b| _mm256_cmp_ps::<_CMP_EQ_OQ>(a, b);
    let lt = |a, b| _mm256_cmp_ps::<_CMP_LT_OS>(a, b);
    let gt = |a, b| _mm256_cmp_ps::<_CMP_GT_OS>(a, b);
    let any_zero = _mm256_movemask_ps(_mm256_or_ps(_mm256_or_ps(eq(e0, zero), eq(e1, zero)), eq(e2, zero))) as u32;
    let neg = _mm256_or_ps(_mm256_or_ps(lt(e0, zero), lt(e1, zero)), lt(e2, zero));
    let pos = _mm256_or_ps(_mm256_or_ps(gt(e0, zero), gt(e1, zero)), gt(e2, zero));
    let det = _mm256_add_ps(_mm256_add_ps(e0, e1), e2);
    let abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
    let finite = lt(_mm256_and_ps(det, abs_mask), _mm256_set1_ps(f32::INFINITY));
    let mut ok = _mm256_andnot_ps(_mm256_and_ps(neg, pos), _mm256_and_ps(finite, _mm256_cmp_ps::<_CMP_NEQ_UQ>(det, zero)));
    let az = _mm256_mul_ps(sz, azk);
    let bz = _mm256_mul_ps(sz, bzk);
    let cz = _mm256_mul_ps(sz, czk);
    let ts = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(e0, az), _mm256_mul_ps(e1, bz)), _mm256_mul_ps(e2, cz));
    let behind = _mm256_or_ps(
        _mm256_and_ps(gt(det, zero), _mm256_cmp_ps::<_CMP_LE_OS>(ts, zero)),
        _mm256_and_ps(lt(det, zero), _mm256_cmp_ps::<_CMP_GE_OS>(ts, zero)),
    );
    ok = _mm256_andnot_ps(behind, ok);
    let mut mask = _mm256_movemask_ps(ok) as u32 & !any_zero;
    let mut tuv = [[0.0f32; 2 * LANES]; 3];
    if mask != 0 {
        let inv = _mm256_div_ps(_mm256_set1_ps(1.0), det);
        let t = _mm256_mul_ps(ts, inv);
        let in_range = _mm256_and_ps(gt(t, pair(tmin[0], tmin[1])), _mm256_cmp_ps::<_CMP_LE_OS>(t, pair(tmax[0], tmax[1])));
        mask &= _mm256_movemask_ps(in_range) as u32;
        _mm256_storeu_ps(tuv[0].as_mut_ptr(), t);
        _mm256_storeu_ps(tuv[1].as_mut_ptr(), _mm256_mul_ps(e1, inv));
        _mm256_storeu_ps(tuv[2].as_mut_ptr(), _mm256_mul_ps(e2, inv));
    }
    per_ray(g, rt, tmin, tmax, mask, any_zero, &tuv, out)
}

/// `intersect_group` for four rays at once, ray `r` in the 128-bit lane `r`
/// of each AVX-512 register; comparisons give masks with the SSE
/// predicates. Each ray's mask and hits are exactly `intersect_group`'s.
///
/// # Safety
/// The CPU must have AVX-512F.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn intersect_group_x4(g: &TriGroup, rt: [&RayTransform; 4], sh: [&Shear; 4], tmin: [f32; 4], tmax: [f32; 4], out: &mut [[LaneHit; LANES]; 4]) -> [u32; 4] {
    use std::arch::x86_64::*;
    let quad = |x: [__m128; 4]| {
        let lo = _mm512_insertf32x4::<1>(_mm512_castps128_ps512(x[0]), x[1]);
        _mm512_insertf32x4::<3>(_mm512_insertf32x4::<2>(lo, x[2]), x[3])
    };
    let k = sh.map(|s| s.k);
    let ld = |v: usize, axis: usize| quad([0, 1, 2, 3].map(|r| _mm_load_ps(g.v[v][k[r][axis]].as_ptr())));
    let each = |f: &dyn Fn(usize) -> f32| quad([0, 1, 2, 3].map(|r| _mm_set1_ps(f(r))));
    let ox = each(&|r| sh[r].o[k[r][0]]);
    let oy = each(&|r| sh[r].o[k[r][1]]);
    let oz = each(&|r| sh[r].o[k[r][2]]);
    let (sx, sy, sz) = (each(&|r| sh[r].s[0]), each(&|r| sh[r].s[1]), each(&|r| sh[r].s[2]));
    let axk = _mm512_sub_ps(ld(0, 0), ox);
    let ayk = _mm512_sub_ps(ld(0, 1), oy);
    let azk = _mm512_sub_ps(ld(0, 2), oz);
    let bxk = _mm512_sub_ps(ld(1, 0), ox);
    let byk = _mm512_sub_ps(ld(1, 1), oy);
    let bzk = _mm512_sub_ps(ld(1, 2), oz);
    let cxk = _mm512_sub_ps(ld(2, 0), ox);
    let cyk = _mm512_sub_ps(ld(2, 1), oy);
    let czk = _mm512_sub_ps(ld(2, 2), oz);
    let ax = _mm512_sub_ps(axk, _mm512_mul_ps(sx, azk));
    let ay = _mm512_sub_ps(ayk, _mm512_mul_ps(sy, azk));
    let bx = _mm512_sub_ps(bxk, _mm512_mul_ps(sx, bzk));
    let by = _mm512_sub_ps(byk, _mm512_mul_ps(sy, bzk));
    let cx = _mm512_sub_ps(cxk, _mm512_mul_ps(sx, czk));
    let cy = _mm512_sub_ps(cyk, _mm512_mul_ps(sy, czk));
    let e0 = _mm512_sub_ps(_mm512_mul_ps(cx, by), _mm512_mul_ps(cy, bx));
    let e1 = _mm512_sub_ps(_mm512_mul_ps(ax, cy), _mm512_mul_ps(ay, cx));
    let e2 = _mm512_sub_ps(_mm512_mul_ps(bx, ay), _mm512_mul_ps(by, ax));
    let zero = _mm512_setzero_ps();
    let eq = |a, b| _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(a, b);
    let lt = |a, b| _mm512_cmp_ps_mask::<_CMP_LT_OS>(a, b);
    let gt = |a, b| _mm512_cmp_ps_mask::<_CMP_GT_OS>(a, b);
    let any_zero = eq(e0, zero) | eq(e1, zero) | eq(e2, zero);
    let neg = lt(e0, zero) | lt(e1, zero) | lt(e2, zero);
    let pos = gt(e0, zero) | gt(e1, zero) | gt(e2, zero);
    let det = _mm512_add_ps(_mm512_add_ps(e0, e1), e2);
    let finite = lt(_mm512_abs_ps(det), _mm512_set1_ps(f32::INFINITY));
    let mut ok = !(neg & pos) & finite & _mm512_cmp_ps_mask::<_CMP_NEQ_UQ>(det, zero);
    let az = _mm512_mul_ps(sz, azk);
    let bz = _mm512_mul_ps(sz, bzk);
    let cz = _mm512_mul_ps(sz, czk);
    let ts = _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(e0, az), _mm512_mul_ps(e1, bz)), _mm512_mul_ps(e2, cz));
    let behind = (gt(det, zero) & _mm512_cmp_ps_mask::<_CMP_LE_OS>(ts, zero)) | (lt(det, zero) & _mm512_cmp_ps_mask::<_CMP_GE_OS>(ts, zero));
    ok &= !behind;
    let mut mask = (ok & !any_zero) as u32;
    let mut tuv = [[0.0f32; 4 * LANES]; 3];
    if mask != 0 {
        let inv = _mm512_div_ps(_mm512_set1_ps(1.0), det);
        let t = _mm512_mul_ps(ts, inv);
        let in_range = gt(t, each(&|r| tmin[r])) & _mm512_cmp_ps_mask::<_CMP_LE_OS>(t, each(&|r| tmax[r]));
        mask &= in_range as u32;
        _mm512_storeu_ps(tuv[0].as_mut_ptr(), t);
        _mm512_storeu_ps(tuv[1].as_mut_ptr(), _mm512_mul_ps(e1, inv));
        _mm512_storeu_ps(tuv[2].as_mut_ptr(), _mm512_mul_ps(e2, inv));
    }
    per_ray(g, rt, tmin, tmax, mask, any_zero as u32, &tuv, out)
}
