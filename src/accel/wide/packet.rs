//! A packet's rays set up together: one pass of AVX2 over the 16 rays
//! gives everything the packet traversals (`frustum`, `masked`) need from
//! them — the rays in SoA form with their slab reciprocals, which are
//! valid, the interval ray's bounds (`Frustum::of`) and each ray's
//! watertight shear — where each traversal used to set up its rays one at
//! a time, three times over (the interval bounds, the SoA slab constants,
//! the shear the first time a ray reached a leaf).
//!
//! Measured before (1 thread, rdtsc around each step, 2-vCPU AMD EPYC):
//! those three set-ups cost about 310 + 115 + 225 cycles per packet of
//! shadow rays, against 1100-1900 for a whole frustum packet on arch:500k,
//! CBbunny and cow. After (1 thread, Mrays/s, best of 7 passes, two or
//! three runs each, same machine): shadow rays arch:500k 22.2-22.6 ->
//! 22.6-25.1, CBbunny 20.3-20.5 -> 21.9-22.5, cow 17.0 -> 18.4-18.6;
//! camera rays arch:500k 54.0-54.6 -> 57.7-58.7, CBbunny 45.8-46.2 ->
//! 51.7-51.9, cow 49.8-50.5 -> 57.1-57.4.
//!
//! Every per-ray constant is computed by the same IEEE operations as the
//! single-ray set-up (`Slab::new`, `RayTransform::new`): a SIMD division
//! rounds each lane exactly as the scalar one does, so the packet paths
//! still give single-ray answers bit for bit. Only the interval bounds'
//! spread (a heuristic that picks a traversal, not an answer) uses a
//! different normalisation.

use super::kernels::Slab;
use super::triangle::{scalar_lane, watertight, Shear};
use super::TriGroup;
use crate::accel::bvh::ROBUST_SCALE;
use crate::geometry::RayTransform;
use crate::ray::Ray;
use std::arch::x86_64::*;

/// Rays per packet.
pub(super) const PACKET: usize = 16;

/// The packet's rays in SoA form, and what the traversals derive from them.
/// Lanes past the packet's rays repeat its first ray, so reductions over
/// all 16 lanes are reductions over the rays.
pub(super) struct RaysSoA {
    pub(super) o: [[f32; PACKET]; 3],
    /// The slab test's reciprocals (`Slab::new`).
    pub(super) inv: [[f32; PACKET]; 3],
    pub(super) tmin: [f32; PACKET],
    pub(super) tmax: [f32; PACKET],
    /// Bit i: ray i passes `Ray::is_valid`.
    pub(super) valid: u32,
    /// Bit i of `neg[a]`: ray i's direction has its sign bit set on axis a.
    pub(super) neg: [u32; 3],
    /// The shear (`RayTransform::new`): bit i of `kz0` / `kz1` when ray i's
    /// dominant axis is x / y (else z), of `swap` when kx and ky trade
    /// places; `s` the three quotients.
    kz0: u32,
    kz1: u32,
    swap: u32,
    s: [[f32; PACKET]; 3],
    /// The interval ray's bounds over all rays (`Frustum::of`).
    pub(super) bounds: IntervalBounds,
    /// The directions, for the swept boxes' end points (`ends_of`).
    d: [[f32; PACKET]; 3],
    /// Bit i: ray i's reciprocals are all finite.
    inv_ok: u32,
    /// Bit i: ray i's `tmax` is finite (it is a segment).
    pub(super) finite_tmax: u32,
    /// The last triangle found to occlude rays of this packet by
    /// `leaf_rays_x8`, as `group · LANES + lane` (`NO_OCCLUDER`: none), for
    /// the next packet's occluder cache (`occluders::OccluderCache`).
    pub(super) occluder: std::cell::Cell<u32>,
}

/// `RaysSoA::occluder` when no triangle was recorded.
pub(super) const NO_OCCLUDER: u32 = u32::MAX;

/// Per axis: the ranges of origins, reciprocals, raw directions and unit
/// directions; and the smallest `tmin`. Meaningful only when every ray is
/// valid with finite reciprocals and one sign pattern (`uniform`).
pub(super) struct IntervalBounds {
    pub(super) o_lo: [f32; 3],
    pub(super) o_hi: [f32; 3],
    pub(super) inv_lo: [f32; 3],
    pub(super) inv_hi: [f32; 3],
    pub(super) d_lo: [f32; 3],
    pub(super) d_hi: [f32; 3],
    pub(super) unit_lo: [f32; 3],
    pub(super) unit_hi: [f32; 3],
    pub(super) tmin: f32,
    pub(super) uniform: bool,
}

/// Smallest / largest lane of two 8-lane registers.
#[inline(always)]
unsafe fn hmin(a: __m256, b: __m256) -> f32 {
    let m = _mm256_min_ps(a, b);
    let m = _mm_min_ps(_mm256_castps256_ps128(m), _mm256_extractf128_ps::<1>(m));
    let m = _mm_min_ps(m, _mm_movehl_ps(m, m));
    _mm_cvtss_f32(_mm_min_ss(m, _mm_shuffle_ps::<0b01>(m, m)))
}

#[inline(always)]
unsafe fn hmax(a: __m256, b: __m256) -> f32 {
    let m = _mm256_max_ps(a, b);
    let m = _mm_max_ps(_mm256_castps256_ps128(m), _mm256_extractf128_ps::<1>(m));
    let m = _mm_max_ps(m, _mm_movehl_ps(m, m));
    _mm_cvtss_f32(_mm_max_ss(m, _mm_shuffle_ps::<0b01>(m, m)))
}

/// Eight rays (32 bytes each: origin, direction, tmin, tmax) as eight
/// registers of one field each.
#[inline(always)]
unsafe fn transpose(rows: [__m256; 8]) -> [__m256; 8] {
    let [r0, r1, r2, r3, r4, r5, r6, r7] = rows;
    let (t0, t1) = (_mm256_unpacklo_ps(r0, r1), _mm256_unpackhi_ps(r0, r1));
    let (t2, t3) = (_mm256_unpacklo_ps(r2, r3), _mm256_unpackhi_ps(r2, r3));
    let (t4, t5) = (_mm256_unpacklo_ps(r4, r5), _mm256_unpackhi_ps(r4, r5));
    let (t6, t7) = (_mm256_unpacklo_ps(r6, r7), _mm256_unpackhi_ps(r6, r7));
    let (u0, u1) = (_mm256_shuffle_ps::<0x44>(t0, t2), _mm256_shuffle_ps::<0xEE>(t0, t2));
    let (u2, u3) = (_mm256_shuffle_ps::<0x44>(t1, t3), _mm256_shuffle_ps::<0xEE>(t1, t3));
    let (u4, u5) = (_mm256_shuffle_ps::<0x44>(t4, t6), _mm256_shuffle_ps::<0xEE>(t4, t6));
    let (u6, u7) = (_mm256_shuffle_ps::<0x44>(t5, t7), _mm256_shuffle_ps::<0xEE>(t5, t7));
    [
        _mm256_permute2f128_ps::<0x20>(u0, u4),
        _mm256_permute2f128_ps::<0x20>(u1, u5),
        _mm256_permute2f128_ps::<0x20>(u2, u6),
        _mm256_permute2f128_ps::<0x20>(u3, u7),
        _mm256_permute2f128_ps::<0x31>(u0, u4),
        _mm256_permute2f128_ps::<0x31>(u1, u5),
        _mm256_permute2f128_ps::<0x31>(u2, u6),
        _mm256_permute2f128_ps::<0x31>(u3, u7),
    ]
}

impl RaysSoA {
    /// Up to `PACKET` (at least one) rays.
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[inline(always)]
    pub(super) unsafe fn new(rays: &[Ray]) -> RaysSoA {
        Self::new_with::<true>(rays)
    }

    /// `new`, with the interval bounds (`bounds`) only when `BOUNDS`: the
    /// swept boxes (`sweep`) do without them, and `fill_bounds` makes them
    /// later where a shadow packet goes the interval ray's way after all.
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[inline(always)]
    pub(super) unsafe fn new_with<const BOUNDS: bool>(rays: &[Ray]) -> RaysSoA {
        debug_assert!(!rays.is_empty() && rays.len() <= PACKET);
        let mut soa = RaysSoA {
            o: [[0.0; PACKET]; 3],
            inv: [[0.0; PACKET]; 3],
            tmin: [0.0; PACKET],
            tmax: [0.0; PACKET],
            valid: 0,
            neg: [0; 3],
            kz0: 0,
            kz1: 0,
            swap: 0,
            s: [[0.0; PACKET]; 3],
            bounds: IntervalBounds {
                o_lo: [0.0; 3],
                o_hi: [0.0; 3],
                inv_lo: [0.0; 3],
                inv_hi: [0.0; 3],
                d_lo: [0.0; 3],
                d_hi: [0.0; 3],
                unit_lo: [0.0; 3],
                unit_hi: [0.0; 3],
                tmin: 0.0,
                uniform: false,
            },
            d: [[0.0; PACKET]; 3],
            inv_ok: u32::MAX,
            finite_tmax: 0,
            occluder: std::cell::Cell::new(NO_OCCLUDER),
        };
        let row = |i: usize| _mm256_loadu_ps(&rays[if i < rays.len() { i } else { 0 }] as *const Ray as *const f32);
        let zero = _mm256_setzero_ps();
        let one = _mm256_set1_ps(1.0);
        let abs = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
        let inf = _mm256_set1_ps(f32::INFINITY);
        let finite = |x: __m256| _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_and_ps(x, abs), inf);
        // Per half: the fields, then the derived registers kept for the
        // reductions.
        let mut keep = [[zero; 2]; 13];
        for half in 0..2 {
            let b = half * 8;
            // Arrays of intrinsics are spelled out here and below, never
            // built with `std::array::from_fn` or `[_; N]::map`: when the
            // compiler does not inline those generic helpers, the closure
            // is compiled without AVX and each load becomes a call. A build
            // with `--features peers` (other code-generation units) did
            // exactly that: CBbunny camera rays 56 Mrays/s against 68, cow
            // 58 against 71, arch:500k shadow rays 49 against 56.
            // `tests/simd_inlined.rs` checks the binary for such calls.
            let f = transpose([row(b), row(b + 1), row(b + 2), row(b + 3), row(b + 4), row(b + 5), row(b + 6), row(b + 7)]);
            let (o, d) = ([f[0], f[1], f[2]], [f[3], f[4], f[5]]);
            let (tmin, tmax) = (f[6], f[7]);
            let inv = [_mm256_div_ps(one, d[0]), _mm256_div_ps(one, d[1]), _mm256_div_ps(one, d[2])];
            for a in 0..3 {
                _mm256_storeu_ps(soa.o[a].as_mut_ptr().add(b), o[a]);
                _mm256_storeu_ps(soa.inv[a].as_mut_ptr().add(b), inv[a]);
                _mm256_storeu_ps(soa.d[a].as_mut_ptr().add(b), d[a]);
                soa.neg[a] |= (_mm256_movemask_ps(d[a]) as u32) << b;
                soa.inv_ok &= !((!_mm256_movemask_ps(finite(inv[a])) as u32 & 0xff) << b);
            }
            _mm256_storeu_ps(soa.tmin.as_mut_ptr().add(b), tmin);
            _mm256_storeu_ps(soa.tmax.as_mut_ptr().add(b), tmax);
            soa.finite_tmax |= (_mm256_movemask_ps(finite(tmax)) as u32) << b;
            // `Ray::is_valid`, lane by lane.
            let mut ok = _mm256_and_ps(_mm256_and_ps(finite(o[0]), finite(o[1])), _mm256_and_ps(finite(o[2]), finite(d[0])));
            ok = _mm256_and_ps(ok, _mm256_and_ps(finite(d[1]), finite(d[2])));
            let nonzero = _mm256_or_ps(
                _mm256_or_ps(_mm256_cmp_ps::<_CMP_NEQ_OQ>(d[0], zero), _mm256_cmp_ps::<_CMP_NEQ_OQ>(d[1], zero)),
                _mm256_cmp_ps::<_CMP_NEQ_OQ>(d[2], zero),
            );
            ok = _mm256_and_ps(ok, nonzero);
            ok = _mm256_and_ps(ok, _mm256_cmp_ps::<_CMP_GE_OQ>(tmin, zero));
            ok = _mm256_and_ps(ok, _mm256_cmp_ps::<_CMP_ORD_Q>(tmax, tmax));
            ok = _mm256_and_ps(ok, _mm256_cmp_ps::<_CMP_LE_OQ>(tmin, tmax));
            soa.valid |= (_mm256_movemask_ps(ok) as u32) << b;
            // The shear of `RayTransform::new`: the dominant axis kz (x
            // when |x| is largest, ties to the lower axis), kx and ky after
            // it, swapped when d[kz] < 0; s = (d[kx], d[ky], 1) / d[kz].
            let ad = [_mm256_and_ps(d[0], abs), _mm256_and_ps(d[1], abs), _mm256_and_ps(d[2], abs)];
            let is_x = _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(ad[0], ad[1]), _mm256_cmp_ps::<_CMP_GE_OQ>(ad[0], ad[2]));
            let is_y = _mm256_andnot_ps(is_x, _mm256_cmp_ps::<_CMP_GE_OQ>(ad[1], ad[2]));
            let pick = |x: __m256, y: __m256, z: __m256| _mm256_blendv_ps(_mm256_blendv_ps(z, y, is_y), x, is_x);
            let dz = pick(d[0], d[1], d[2]);
            let (nx, ny) = (pick(d[1], d[2], d[0]), pick(d[2], d[0], d[1]));
            let swap = _mm256_cmp_ps::<_CMP_LT_OQ>(dz, zero);
            let (nx, ny) = (_mm256_blendv_ps(nx, ny, swap), _mm256_blendv_ps(ny, nx, swap));
            soa.kz0 |= (_mm256_movemask_ps(is_x) as u32) << b;
            soa.kz1 |= (_mm256_movemask_ps(is_y) as u32) << b;
            soa.swap |= (_mm256_movemask_ps(swap) as u32) << b;
            _mm256_storeu_ps(soa.s[0].as_mut_ptr().add(b), _mm256_div_ps(nx, dz));
            _mm256_storeu_ps(soa.s[1].as_mut_ptr().add(b), _mm256_div_ps(ny, dz));
            _mm256_storeu_ps(soa.s[2].as_mut_ptr().add(b), _mm256_div_ps(one, dz));
            if BOUNDS {
                soa.keep_half(&mut keep, half, o, inv, d, tmin);
            }
        }
        if BOUNDS {
            soa.reduce_bounds(&keep);
        }
        soa
    }

    /// The registers the interval bounds reduce, for one half of the
    /// packet: origins, reciprocals, directions, unit directions, tmin.
    #[inline(always)]
    unsafe fn keep_half(&self, keep: &mut [[__m256; 2]; 13], half: usize, o: [__m256; 3], inv: [__m256; 3], d: [__m256; 3], tmin: __m256) {
        // Unit directions, for the spread of shadow packets.
        let len = _mm256_sqrt_ps(_mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(d[0], d[0]), _mm256_mul_ps(d[1], d[1])), _mm256_mul_ps(d[2], d[2])));
        let rlen = _mm256_div_ps(_mm256_set1_ps(1.0), len);
        for a in 0..3 {
            keep[a][half] = o[a];
            keep[3 + a][half] = inv[a];
            keep[6 + a][half] = d[a];
            keep[9 + a][half] = _mm256_mul_ps(d[a], rlen);
        }
        keep[12][half] = tmin;
    }

    /// `bounds` for a packet set up without them (`new_with::<false>`),
    /// from its stored rays.
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[inline(always)]
    pub(super) unsafe fn fill_bounds(&mut self) {
        let mut keep = [[_mm256_setzero_ps(); 2]; 13];
        for half in 0..2 {
            let b = half * 8;
            let row = |v: &[f32; PACKET]| _mm256_loadu_ps(v.as_ptr().add(b));
            // Spelled out, not `[0, 1, 2].map(..)`: see `new_with`.
            let rows = |v: &[[f32; PACKET]; 3]| [row(&v[0]), row(&v[1]), row(&v[2])];
            let (o, inv, d) = (rows(&self.o), rows(&self.inv), rows(&self.d));
            self.keep_half(&mut keep, half, o, inv, d, row(&self.tmin));
        }
        self.reduce_bounds(&keep);
    }

    #[inline(always)]
    unsafe fn reduce_bounds(&mut self, keep: &[[__m256; 2]; 13]) {
        let all = (1u32 << PACKET) - 1;
        let uniform_signs = self.neg.iter().all(|&m| m == 0 || m == all);
        let bd = &mut self.bounds;
        bd.uniform = self.valid == all && self.inv_ok & all == all && uniform_signs;
        for a in 0..3 {
            bd.o_lo[a] = hmin(keep[a][0], keep[a][1]);
            bd.o_hi[a] = hmax(keep[a][0], keep[a][1]);
            bd.inv_lo[a] = hmin(keep[3 + a][0], keep[3 + a][1]);
            bd.inv_hi[a] = hmax(keep[3 + a][0], keep[3 + a][1]);
            bd.d_lo[a] = hmin(keep[6 + a][0], keep[6 + a][1]);
            bd.d_hi[a] = hmax(keep[6 + a][0], keep[6 + a][1]);
            bd.unit_lo[a] = hmin(keep[9 + a][0], keep[9 + a][1]);
            bd.unit_hi[a] = hmax(keep[9 + a][0], keep[9 + a][1]);
        }
        bd.tmin = hmin(keep[12][0], keep[12][1]);
    }

    /// The largest |coordinate| of any ray's origin.
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[inline(always)]
    pub(super) unsafe fn origin_abs_max(&self) -> f32 {
        let abs = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
        let mut m = _mm256_setzero_ps();
        for a in 0..3 {
            for half in [0, 8] {
                m = _mm256_max_ps(m, _mm256_and_ps(abs, _mm256_loadu_ps(self.o[a].as_ptr().add(half))));
            }
        }
        hmax(m, m)
    }

    /// Ray i's point at `t` on `axis`, for the 8 rays from `half`.
    #[inline(always)]
    unsafe fn at(&self, axis: usize, t: &[f32; PACKET], half: usize) -> __m256 {
        let o = _mm256_loadu_ps(self.o[axis].as_ptr().add(half));
        let d = _mm256_loadu_ps(self.d[axis].as_ptr().add(half));
        _mm256_add_ps(o, _mm256_mul_ps(_mm256_loadu_ps(t.as_ptr().add(half)), d))
    }

    /// Bit i set when ray i's start point `o + tmin d` lies below `at` on
    /// `axis`.
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[inline(always)]
    pub(super) unsafe fn starts_below(&self, axis: usize, at: f32) -> u32 {
        let v = _mm256_set1_ps(at);
        let lo = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(self.at(axis, &self.tmin, 0), v)) as u32;
        let hi = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(self.at(axis, &self.tmin, 8), v)) as u32;
        lo | hi << 8
    }

    /// Over the rays in `which` (bits; not empty), per axis: the range of
    /// their start points `o + tmin d` ([0] low, [1] high) and of their
    /// end points `o + tmax d` ([2], [3]), for the swept boxes (`sweep`).
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[inline(always)]
    pub(super) unsafe fn ends_of(&self, which: u32) -> [[f32; 3]; 4] {
        let bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
        let m0 = _mm256_and_si256(_mm256_set1_epi32(which as i32 & 0xff), bit);
        let m0 = _mm256_castsi256_ps(_mm256_cmpeq_epi32(m0, bit));
        let m1 = _mm256_and_si256(_mm256_set1_epi32((which >> 8) as i32 & 0xff), bit);
        let m1 = _mm256_castsi256_ps(_mm256_cmpeq_epi32(m1, bit));
        let (inf, ninf) = (_mm256_set1_ps(f32::INFINITY), _mm256_set1_ps(f32::NEG_INFINITY));
        let mut e = [[0.0; 3]; 4];
        for (k, t) in [&self.tmin, &self.tmax].into_iter().enumerate() {
            for axis in 0..3 {
                let (a, b) = (self.at(axis, t, 0), self.at(axis, t, 8));
                e[2 * k][axis] = hmin(_mm256_blendv_ps(inf, a, m0), _mm256_blendv_ps(inf, b, m1));
                e[2 * k + 1][axis] = hmax(_mm256_blendv_ps(ninf, a, m0), _mm256_blendv_ps(ninf, b, m1));
            }
        }
        e
    }

    /// The axis permutation `[kx, ky, kz]` every ray of the packet shares,
    /// or `None` when their dominant axes or swaps differ. Lanes past the
    /// packet's rays repeat its first ray, so they never break uniformity.
    #[inline(always)]
    pub(super) fn shared_axes(&self) -> Option<[usize; 3]> {
        self.shared_axes_of((1u32 << PACKET) - 1)
    }

    /// `shared_axes` among the rays in `which` (bits; not empty).
    #[inline(always)]
    pub(super) fn shared_axes_of(&self, which: u32) -> Option<[usize; 3]> {
        let uniform = |m: u32| m & which == 0 || m & which == which;
        if !(uniform(self.kz0) && uniform(self.kz1) && uniform(self.swap)) {
            return None;
        }
        Some(self.shear(which.trailing_zeros() as usize).1.k)
    }

    /// Bit r set when ray `8·half + r` hits triangle `lane` of `g` in
    /// (tmin, `tmax[i]`], for rays sharing the permutation `k`
    /// (`shared_axes`): the watertight test (`triangle::watertight`) with
    /// the rays in the lanes and one triangle broadcast, where
    /// `intersect_group_x2` puts two rays against four triangles; a lane
    /// with an exact zero edge function is redone by `scalar_lane`, so
    /// every bit is the single-ray test's answer. For occlusion, where the
    /// ray constants are already here in SoA form: no per-ray set-up.
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[inline(always)]
    pub(super) unsafe fn hits_triangle(&self, g: &TriGroup, lane: usize, half: usize, k: [usize; 3], tmax: &[f32; PACKET]) -> u32 {
        let b = half * 8;
        let rows = |row: &[f32; PACKET]| _mm256_loadu_ps(row.as_ptr().add(b));
        let [kx, ky, kz] = k;
        let v = |vert: usize, axis: usize| _mm256_set1_ps(g.v[vert][axis][lane]);
        let p = [[v(0, kx), v(0, ky), v(0, kz)], [v(1, kx), v(1, ky), v(1, kz)], [v(2, kx), v(2, ky), v(2, kz)]];
        let o = [rows(&self.o[kx]), rows(&self.o[ky]), rows(&self.o[kz])];
        let s = [rows(&self.s[0]), rows(&self.s[1]), rows(&self.s[2])];
        let tested = watertight::<__m256>(p, o, s, || (rows(&self.tmin), rows(tmax)));
        let mut mask = tested.mask;
        let mut z = tested.any_zero & 0xff;
        while z != 0 {
            let r = z.trailing_zeros() as usize;
            z &= z - 1;
            let i = b + r;
            if scalar_lane(g, lane, &self.shear(i).0, self.tmin[i], tmax[i]).is_some() {
                mask |= 1 << r;
            }
        }
        mask
    }

    /// Ray `i`'s watertight-test constants, as `RayTransform::new` and
    /// `Shear::new` make them.
    #[inline(always)]
    pub(super) fn shear(&self, i: usize) -> (RayTransform, Shear) {
        // By arithmetic and a table, not branches: the axes of incoherent
        // rays are unpredictable. `kz1` is set only where `kz0` is not.
        const AFTER: [[usize; 2]; 3] = [[1, 2], [2, 0], [0, 1]];
        let (x, y, swap) = ((self.kz0 >> i & 1) as usize, (self.kz1 >> i & 1) as usize, (self.swap >> i & 1) as usize);
        let kz = 2 - 2 * x - y;
        let (kx, ky) = (AFTER[kz][swap], AFTER[kz][1 - swap]);
        let o = [self.o[0][i], self.o[1][i], self.o[2][i]];
        let s = [self.s[0][i], self.s[1][i], self.s[2][i]];
        let rt = RayTransform::from_shear(glam::Vec3::from_array(o), [kx, ky, kz], s);
        (rt, Shear { k: [kx, ky, kz], s, o })
    }

    /// Ray `i`'s slab-test constants, as `Slab::new` makes them.
    #[inline(always)]
    pub(super) fn slab(&self, i: usize) -> Slab {
        Slab {
            o: [self.o[0][i], self.o[1][i], self.o[2][i]],
            inv: [self.inv[0][i], self.inv[1][i], self.inv[2][i]],
            // Spelled out, by arithmetic: see `new_with` on closures.
            near_plane: [3 * (self.neg[0] >> i & 1) as usize, 1 + 3 * (self.neg[1] >> i & 1) as usize, 2 + 3 * (self.neg[2] >> i & 1) as usize],
        }
    }

    /// Bit i set when ray i enters child `lane` of `n` in [tmin_i, tmax[i]]:
    /// `Slab::test` of each ray for that one box, 8 rays per instruction
    /// instead of 8 boxes, the same operations on each lane. The packet's
    /// rays share their direction signs, so the near planes are
    /// `near_plane`'s.
    ///
    /// # Safety
    /// The CPU must have AVX2; `W` must be 8.
    #[inline(always)]
    pub(super) unsafe fn test<const W: usize>(&self, near_plane: &[usize; 3], n: &super::Node<W>, lane: usize, tmax: &[f32; PACKET]) -> u64 {
        self.slab_lanes::<W, false>(near_plane, n, lane, tmax)
    }

    /// `test` for rays whose direction signs may differ: each lane takes
    /// its own ray's near plane (`Slab::new`'s choice), with the same
    /// operations.
    ///
    /// # Safety
    /// The CPU must have AVX2; `W` must be 8.
    #[inline(always)]
    pub(super) unsafe fn test_signed<const W: usize>(&self, n: &super::Node<W>, lane: usize, tmax: &[f32; PACKET]) -> u64 {
        self.slab_lanes::<W, true>(&[0, 1, 2], n, lane, tmax)
    }

    /// `test` (`SIGNED`: `test_signed`, `near_plane` unused).
    #[inline(always)]
    unsafe fn slab_lanes<const W: usize, const SIGNED: bool>(&self, near_plane: &[usize; 3], n: &super::Node<W>, lane: usize, tmax: &[f32; PACKET]) -> u64 {
        let scale = _mm256_set1_ps(ROBUST_SCALE);
        let bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
        let mut mask = 0u64;
        for half in (0..PACKET).step_by(8) {
            let mut t0 = _mm256_loadu_ps(self.tmin.as_ptr().add(half));
            let mut t1 = _mm256_mul_ps(_mm256_loadu_ps(tmax.as_ptr().add(half)), scale);
            for a in 0..3 {
                let (lo, hi) = if SIGNED {
                    let neg = _mm256_set1_epi32((self.neg[a] >> half) as i32 & 0xff);
                    let neg = _mm256_castsi256_ps(_mm256_cmpeq_epi32(_mm256_and_si256(neg, bit), bit));
                    let (min, max) = (_mm256_set1_ps(n.bounds[a][lane]), _mm256_set1_ps(n.bounds[a + 3][lane]));
                    (_mm256_blendv_ps(min, max, neg), _mm256_blendv_ps(max, min, neg))
                } else {
                    (_mm256_set1_ps(n.bounds[near_plane[a]][lane]), _mm256_set1_ps(n.bounds[(near_plane[a] + 3) % 6][lane]))
                };
                let o = _mm256_loadu_ps(self.o[a].as_ptr().add(half));
                let inv = _mm256_loadu_ps(self.inv[a].as_ptr().add(half));
                let tn = _mm256_mul_ps(_mm256_sub_ps(lo, o), inv);
                let tf = _mm256_mul_ps(_mm256_mul_ps(_mm256_sub_ps(hi, o), inv), scale);
                t0 = _mm256_max_ps(tn, t0);
                t1 = _mm256_min_ps(tf, t1);
            }
            mask |= (_mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1)) as u64) << half;
        }
        mask
    }

    /// `test` with all 16 rays in one AVX-512 register.
    ///
    /// # Safety
    /// The CPU must have AVX-512F; `W` must be 8.
    #[inline(always)]
    pub(super) unsafe fn test512<const W: usize>(&self, near_plane: &[usize; 3], n: &super::Node<W>, lane: usize, tmax: &[f32; PACKET]) -> u64 {
        let scale = _mm512_set1_ps(ROBUST_SCALE);
        let mut t0 = _mm512_loadu_ps(self.tmin.as_ptr());
        let mut t1 = _mm512_mul_ps(_mm512_loadu_ps(tmax.as_ptr()), scale);
        for a in 0..3 {
            let lo = _mm512_set1_ps(n.bounds[near_plane[a]][lane]);
            let hi = _mm512_set1_ps(n.bounds[(near_plane[a] + 3) % 6][lane]);
            let o = _mm512_loadu_ps(self.o[a].as_ptr());
            let inv = _mm512_loadu_ps(self.inv[a].as_ptr());
            let tn = _mm512_mul_ps(_mm512_sub_ps(lo, o), inv);
            let tf = _mm512_mul_ps(_mm512_mul_ps(_mm512_sub_ps(hi, o), inv), scale);
            t0 = _mm512_max_ps(tn, t0);
            t1 = _mm512_min_ps(tf, t1);
        }
        _mm512_cmp_ps_mask::<_CMP_LE_OQ>(t0, t1) as u64
    }
}

#[cfg(test)]
mod tests;
