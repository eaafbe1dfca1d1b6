//! The box kernels: the slab test of a node's boxes (SSE2, AVX2, scalar)
//! and the children's front-to-back order. All paths perform the same
//! per-lane operations in the same order. The triangle test is in
//! `triangle`.

#[cfg(target_arch = "x86_64")]
use super::lanes::Lanes;
use super::Node;
use crate::accel::bvh::ROBUST_SCALE;
use crate::ray::Ray;
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
