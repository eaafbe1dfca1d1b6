//! The box kernels: the slab test of a node's boxes (SSE2, AVX2, scalar)
//! and the children's front-to-back order (`nearest_first_keys` for one
//! ray's closest hit, `sort_far_first` for the stacks that carry ray
//! masks and for farthest-first walks). All paths perform the same
//! per-lane operations in the same order, and order children alike. The
//! triangle test is in `triangle`.

#[cfg(target_arch = "x86_64")]
use super::lanes::Lanes;
use super::Node;
use crate::accel::bvh::ROBUST_SCALE;
use crate::ray::Ray;
use std::ops::Div;

/// Insertion sort of at most 8 entered children by entry distance, farthest
/// first: pushed in that order, the nearest is visited next. Stable, so
/// on a tie the child pushed last (the higher lane) is visited first.
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

/// The entered children of a node (lanes in `mask`, entry distances
/// `near`) nearest first, as sort keys, ascending: lane i's key is its
/// entry distance's bits with the low three replaced by `7 - i`
/// (`key_lane` reads the lane back), and a lane not entered gets
/// `u32::MAX`; the first `mask.count_ones()` keys are the entered lanes'.
/// Distances within 8 units in the last place count as a tie, which the
/// higher lane wins (as `single`'s two-child step and the insertion sort
/// before this did). Entry distances are at least the ray's `tmin`, so
/// non-negative, and such floats order as their bits; a negative one
/// (a ray with a negative `tmin`) would be visited later, never missed.
///
/// The keys are distinct, so every correct sort gives the same array. Up
/// to three entered (most nodes) take three compare-exchanges on scalars;
/// more take, with AVX2 and 8 lanes, a bitonic network in one register
/// (six shuffle, min, max and blend steps), else `sort_unstable`. No
/// branch depends on the distances: the insertion sort this replaced
/// mispredicted where children are entered at nearly the same distance,
/// as grass's diffuse rays enter theirs (see `docs/notes/2026-12-02-child-order-keys.md`).
#[inline(always)]
pub(super) fn nearest_first_keys<const W: usize, const AVX: bool>(near: &[f32; W], mask: u32) -> [u32; W] {
    if mask.count_ones() <= 3 {
        let mut keys = [u32::MAX; W];
        [keys[0], keys[1], keys[2]] = three_nearest_first(near, mask);
        return keys;
    }
    #[cfg(target_arch = "x86_64")]
    if AVX && W == 8 {
        // SAFETY: the caller runs with AVX2 (`AVX`); `near` has 8 lanes,
        // and so has the array written.
        unsafe {
            use std::arch::x86_64::*;
            let tie = _mm256_setr_epi32(7, 6, 5, 4, 3, 2, 1, 0);
            let bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
            let bits = _mm256_castps_si256(_mm256_loadu_ps(near.as_ptr()));
            let keys = _mm256_or_si256(_mm256_andnot_si256(_mm256_set1_epi32(7), bits), tie);
            let entered = _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(mask as i32), bit), bit);
            let mut v = _mm256_or_si256(keys, _mm256_xor_si256(entered, _mm256_set1_epi32(-1)));
            // Each step pairs lane i with lane i ^ 1, 2 or 4 (the shuffle)
            // and keeps the larger of the two where the blend's bit is set.
            macro_rules! step {
                ($partner:expr, $larger:literal) => {{
                    let p = $partner;
                    v = _mm256_blend_epi32::<$larger>(_mm256_min_epu32(v, p), _mm256_max_epu32(v, p));
                }};
            }
            step!(_mm256_shuffle_epi32::<0xB1>(v), 0x66);
            step!(_mm256_shuffle_epi32::<0x4E>(v), 0x3C);
            step!(_mm256_shuffle_epi32::<0xB1>(v), 0x5A);
            step!(_mm256_permute4x64_epi64::<0x4E>(v), 0xF0);
            step!(_mm256_shuffle_epi32::<0x4E>(v), 0xCC);
            step!(_mm256_shuffle_epi32::<0xB1>(v), 0xAA);
            let mut out = [0u32; W];
            _mm256_storeu_si256(out.as_mut_ptr() as *mut __m256i, v);
            return out;
        }
    }
    nearest_first_keys_scalar(near, mask)
}

/// The `nearest_first_keys` key of `lane`, entered at distance `near`.
#[inline(always)]
fn child_key(near: f32, lane: u32) -> u32 {
    near.to_bits() & !7 | (7 - lane)
}

/// The lane a `nearest_first_keys` key stands for (`child_key`'s inverse).
#[inline(always)]
pub(super) fn key_lane(key: u32) -> usize {
    (7 - (key & 7)) as usize
}

/// `nearest_first_keys`'s first three, where at most three children are
/// entered (`u32::MAX` for each one fewer).
#[inline(always)]
fn three_nearest_first<const W: usize>(near: &[f32; W], mask: u32) -> [u32; 3] {
    let key = |m: u32| {
        let lane = m.trailing_zeros();
        if m == 0 {
            u32::MAX
        } else {
            child_key(near[lane as usize], lane)
        }
    };
    let m1 = mask & mask.wrapping_sub(1);
    let m2 = m1 & m1.wrapping_sub(1);
    let (a, b, c) = (key(mask), key(m1), key(m2));
    let (a, b) = (a.min(b), a.max(b));
    let (b, c) = (b.min(c), b.max(c));
    [a.min(b), a.max(b), c]
}

/// `nearest_first_keys` by a library sort, for every width and
/// instruction set (and the unit tests' reference).
#[inline(always)]
fn nearest_first_keys_scalar<const W: usize>(near: &[f32; W], mask: u32) -> [u32; W] {
    let mut keys = [u32::MAX; W];
    for (lane, k) in keys.iter_mut().enumerate() {
        if mask >> lane & 1 != 0 {
            *k = child_key(near[lane], lane as u32);
        }
    }
    keys.sort_unstable();
    keys
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
            if AVX && W == 8 {
                let (t0, t1) = self.entry_exit::<__m256, W>(n, 0, tmin, tmax);
                t0.store(near.as_mut_ptr());
                return __m256::bits(t0.le(t1));
            }
            let mut mask = 0;
            for c in (0..W).step_by(4) {
                let (t0, t1) = self.entry_exit::<__m128, W>(n, c, tmin, tmax);
                t0.store(near.as_mut_ptr().add(c));
                mask |= __m128::bits(t0.le(t1)) << c;
            }
            mask
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            self.test_scalar(n, tmin, tmax, near)
        }
    }

    /// The body of `test` for children `c..` (as many as `V` has lanes):
    /// per child, the entry distance and the (scaled) exit distance; the
    /// ray enters child i when lane i has entry ≤ exit. Shared with
    /// `masked`, whose per-ray node tests must do exactly these operations.
    ///
    /// # Safety
    /// The caller runs with `V`'s instruction set; `c` is a multiple of
    /// `V`'s lane count below `W` (node rows are 64-byte aligned).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(super) unsafe fn entry_exit<V: Lanes, const W: usize>(&self, n: &Node<W>, c: usize, tmin: f32, tmax: f32) -> (V, V) {
        let rows = (n.bounds.as_ptr() as *const f32).add(c);
        let [p0, p1, p2] = self.near_plane;
        let lo = [V::load(rows.add(p0 * W)), V::load(rows.add(p1 * W)), V::load(rows.add(p2 * W))];
        let hi = [V::load(rows.add((p0 + 3) % 6 * W)), V::load(rows.add((p1 + 3) % 6 * W)), V::load(rows.add((p2 + 3) % 6 * W))];
        slab_planes(&lo, &hi, self.o, self.inv, tmin, tmax)
    }

    /// `test` one lane at a time, for targets without x86 SIMD (and the
    /// unit tests, which check that every path gives the same bits).
    #[cfg_attr(target_arch = "x86_64", allow(dead_code))]
    pub(super) fn test_scalar<const W: usize>(&self, n: &Node<W>, tmin: f32, tmax: f32, near: &mut [f32; W]) -> u32 {
        let mut mask = 0;
        for lane in 0..W {
            let (mut t0, mut t1) = (tmin, tmax);
            for a in 0..3 {
                let lo = n.bounds[self.near_plane[a]][lane];
                let hi = n.bounds[(self.near_plane[a] + 3) % 6][lane];
                let tn = (lo - self.o[a]) * self.inv[a];
                let tf = (hi - self.o[a]) * self.inv[a];
                // As maxps/minps: a NaN distance leaves the bound as it is.
                if tn > t0 {
                    t0 = tn;
                }
                if tf < t1 {
                    t1 = tf;
                }
            }
            near[lane] = t0;
            if t0 <= t1 * ROBUST_SCALE {
                mask |= 1 << lane;
            }
        }
        mask
    }
}

/// The slab test of one ray against as many boxes as `V` has lanes, whose
/// near and far planes are already loaded (`lo`, `hi`, per axis): per box,
/// the entry and the exit distance enlarged by `ROBUST_SCALE`. Enlarged
/// once, after the minimum over the axes and `tmax`, not each axis's exit:
/// rounding is monotonic, so the minimum of the enlarged values is the
/// enlarged minimum, bit for bit, with two multiplications fewer per
/// node. The one sequence of operations behind
/// `Slab::entry_exit` and the streams' node tests (`stream`), whose rays
/// share their planes.
///
/// # Safety
/// The caller runs with `V`'s instruction set.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn slab_planes<V: Lanes>(lo: &[V; 3], hi: &[V; 3], o: [f32; 3], inv: [f32; 3], tmin: f32, tmax: f32) -> (V, V) {
    let mut t0 = V::splat(tmin);
    let mut t1 = V::splat(tmax);
    for a in 0..3 {
        let o = V::splat(o[a]);
        let inv = V::splat(inv[a]);
        let tn = lo[a].sub(o).mul(inv);
        let tf = hi[a].sub(o).mul(inv);
        // maxps(a, b) = a > b ? a : b, so a NaN in tn leaves t0 as it is.
        t0 = tn.max(t0);
        t1 = tf.min(t1);
    }
    (t0, t1.mul(V::splat(ROBUST_SCALE)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The three sorts `nearest_first_keys` may take give the same keys
    /// for every mask, with exact ties, near ties, zeros and spread
    /// distances; the entered lanes come first, each once, nearest first,
    /// the higher lane first on a tie.
    #[test]
    fn nearest_first_keys_agree_on_every_path() {
        #[cfg(target_arch = "x86_64")]
        let avx2 = is_x86_feature_detected!("avx2");
        #[cfg(not(target_arch = "x86_64"))]
        let avx2 = false;
        if !avx2 {
            eprintln!("SKIPPED in part: no AVX2 here, so the sorting network is not checked");
        }
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for round in 0..20_000 {
            let mut near = [0.0f32; 8];
            for x in near.iter_mut() {
                let r = next();
                *x = match (round + (r as usize & 3)) % 4 {
                    0 => (r >> 40) as f32 * 1e-3,
                    1 => (r % 3) as f32,
                    2 => 0.0,
                    _ => f32::from_bits(0x3f80_0000 + (r as u32 & 15)),
                };
            }
            let mask = (next() & 0xff) as u32;
            let want = nearest_first_keys_scalar(&near, mask);
            if avx2 {
                assert_eq!(nearest_first_keys::<8, true>(&near, mask), want, "near {near:?}, mask {mask:#b}");
            }
            assert_eq!(nearest_first_keys::<8, false>(&near, mask), want, "near {near:?}, mask {mask:#b}");
            let n = mask.count_ones() as usize;
            let lanes: Vec<usize> = want[..n].iter().map(|&k| key_lane(k)).collect();
            assert!(lanes.iter().all(|&l| mask >> l & 1 != 0) && want[n..].iter().all(|&k| k == u32::MAX));
            let coarse = |l: usize| near[l].to_bits() & !7;
            assert!(lanes.windows(2).all(|w| coarse(w[0]) < coarse(w[1]) || coarse(w[0]) == coarse(w[1]) && w[0] > w[1]), "{lanes:?} {near:?}");
        }
    }
}
