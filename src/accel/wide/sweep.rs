//! Shadow packets culled by the *swept box* of their segments. A shadow
//! ray is a segment from its start `o + tmin d` to its end `o + tmax d`,
//! and a packet's segments end near one light. Let A be the box of the
//! packet's start points and B the box of its end points; at parameter s
//! in [0, 1] every ray's point `start + s (end - start)` lies in the box
//! that moves linearly from A (s = 0) to B (s = 1), whatever the rays'
//! directions. An interior node's child is entered only when some s puts
//! that moving box inside the child's box on all three axes: one slab test
//! in s per packet and node, like the interval ray's (`frustum`), but with
//! no condition on the rays' directions — a packet fanning out towards a
//! nearby light, or whose rays mix direction signs, is still a thin wedge
//! from its origins to the light, where the interval ray (its reciprocal
//! directions' range) loses all grip and such packets went to `masked`
//! traversal: per ray and node, 2100-2700 cycles a packet on arch against
//! 440 for a tight one (37 % of its packets, two thirds of its time).
//!
//! Leaf boxes are then tested ray by ray (`RaysSoA::test`, or
//! `test_signed` where signs differ) and leaves as in `frustum_packet`, so
//! each ray tests exactly the triangles its own traversal would reach and
//! answers equal single-ray traversal's.
//!
//! The moving box is as loose as the start points are spread: 16 rays
//! from both sides of a depth edge span a wedge much wider than their
//! lines. Such packets (`LOOSE`) are split at the middle of their start
//! points' box, again until each part is tight, and each part is traced as
//! its own swept box (`any_sweep_packet`); a few rays left loose go alone.
//!
//! The packet set-up leaves out the interval ray's bounds (`RaysSoA::
//! new_with::<false>`, a third of its reductions and a square root); the
//! packets the sweep refuses make them afterwards (`fill_bounds`).
//!
//! Measured (2-vCPU AMD EPYC, 1 thread, Mrays/s, the bench's shadow rays,
//! best of four alternating runs of 7 passes): interval ray / ray masks as
//! before -> swept boxes: arch:500k 34.1 -> 48.4 (Embree's stream 48.9),
//! beetle 14.3 -> 18.9, maxplanck 8.2 -> 9.8, cow 24.3 -> 28.6,
//! stadium:500k 16.5 -> 19.5, CBbunny 29.8 -> 32.4, subdiv:bunny:500k 3.4
//! -> 4.4, sphere:1m 5.3 -> 5.6, grass:500k 0.42 -> 0.41. Of that, each
//! part's own signs and axis permutation (not the packet's) gave arch 37
//! -> 45, and the set-up without interval bounds 4-8 % everywhere.
//! Path-traced images are bit-identical and their times unchanged
//! (CBbunny, bunny: the renderer's shadow rays end on a nearby area light
//! or at infinity, which the sweep leaves to the interval ray).
//! Not kept: a ray mask per stacked node (each child the box enters
//! tested by its parent's rays, 8 per instruction) — arch 34.6 against
//! 41.3 at the time (the swept box alone rarely enters a child no ray
//! enters); with Embree's rule on top (the children the first ray enters
//! inherit the parent's mask untested) 28.6; whole loose packets to the
//! interval / masked paths instead of splitting them, 30.5; a new swept
//! box for the rays left once half are occluded, no gain (44.6 / 44.9);
//! no prefetch of children, within 1 %.
//!
//! Conservative in floating point: the single-ray slab test may enter a
//! box the exact segment misses by a few ulps of its length (and reach
//! `tmax · ROBUST_SCALE`), and the end points are rounded; the moving box
//! is widened by 2^-16 of the packet's largest coordinate (orders of
//! magnitude above those errors) on every side, and its rate of change
//! kept at least that far from zero so its reciprocal is finite.

use super::packet::{RaysSoA, PACKET};
use super::stack::WalkStack;
use super::{ChildOrder, WideBvh, EMPTY, LEAF_BIT};
use crate::geometry::RayTransform;
use crate::ray::Ray;
use std::mem::MaybeUninit;

/// A packet (or part) is *loose* when its start points' box is wider, on
/// its longest side, than this fraction of the distance from the start
/// points' centre to the end points'; loose packets are split (see
/// `any_sweep_packet`). Measured (1 thread, Mrays/s, shadow rays, nine
/// alternating passes, before parts had their own signs): 0.1 / 0.15 /
/// 0.2 / 0.25 — arch:500k 34.6 / 38.8 / 41.9 / 39.3, beetle 17.1 / 17.7 /
/// 18.2 / 18.3, CBbunny 27.4 / 29.0 / 29.7 / 29.9, cow and stadium:500k
/// within 2 %.
const LOOSE: f32 = 0.2;

/// Whether the start points' box (`at` 0) or the end points' (`at` 2) is
/// wider, on its widest side, than `LOOSE` of the distance between the
/// boxes' centres (a zero distance counts as loose). Squared: no root or
/// division on the way to every packet's traversal.
#[inline(always)]
fn loose(e: &[[f32; 3]; 4], at: usize) -> bool {
    let (mut ext, mut len2) = (0.0f32, 0.0f32);
    for a in 0..3 {
        ext = ext.max(e[at + 1][a] - e[at][a]);
        let d = 0.5 * (e[2][a] + e[3][a] - e[0][a] - e[1][a]);
        len2 += d * d;
    }
    !(ext * ext < LOOSE * LOOSE * len2)
}

/// Loose parts this small go ray by ray (1, 2, 5 and 8 measured within 2 %
/// of 3 on arch:500k, CBbunny, beetle and cow).
const MIN_GROUP: u32 = 3;

/// Per axis, the moving box's two sides as `side(s) = at0 + s · rate`
/// (low side first), with `1 / rate` and the clamp that turns each side's
/// crossing into a lower or an upper bound on s.
pub(super) struct Sweep {
    at0: [[f32; 3]; 2],
    inv_rate: [[f32; 3]; 2],
    /// -inf where the side's crossing bounds s from above, +inf where from
    /// below (`test`).
    clamp: [[f32; 3]; 2],
}

impl Sweep {
    /// How far the moving box is widened: 2^-16 of the largest coordinate
    /// any ray of the packet reaches (its origin, or a point of its
    /// segment).
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[inline(always)]
    unsafe fn pad(e: &[[f32; 3]; 4], soa: &RaysSoA) -> f32 {
        let mut big = soa.origin_abs_max();
        for a in 0..3 {
            for x in [e[0][a], e[1][a], e[2][a], e[3][a]] {
                big = big.max(x.abs());
            }
        }
        (big * (1.0 / 65536.0)).max(f32::MIN_POSITIVE * 65536.0)
    }

    /// The moving box from the start points' box `e[0..2]` to the end
    /// points' `e[2..4]`, widened by `pad`.
    fn new(e: &[[f32; 3]; 4], pad: f32) -> Sweep {
        let mut sw = Sweep { at0: [[0.0; 3]; 2], inv_rate: [[0.0; 3]; 2], clamp: [[0.0; 3]; 2] };
        for a in 0..3 {
            for side in 0..2 {
                // Low side (side 0) moves from start-low to end-low, pushed
                // down; high side up. The end that lies further out on its
                // side is pushed out twice as far, so the rate is at least
                // `pad` away from zero.
                let (s0, s1) = (e[side][a], e[2 + side][a]);
                let out = if side == 0 { -pad } else { pad };
                let grows = if side == 0 { s1 <= s0 } else { s1 >= s0 };
                let (p0, p1) = if grows { (s0 + out, s1 + 2.0 * out) } else { (s0 + 2.0 * out, s1 + out) };
                let rate = p1 - p0;
                sw.at0[side][a] = p0;
                sw.inv_rate[side][a] = 1.0 / rate;
                // Low side: entering needs side(s) <= box max; with a
                // positive rate that holds for s up to the crossing (an
                // upper bound). High side: side(s) >= box min; a positive
                // rate makes the crossing a lower bound.
                let upper = (side == 0) == (rate > 0.0);
                sw.clamp[side][a] = if upper { f32::NEG_INFINITY } else { f32::INFINITY };
            }
        }
        sw
    }

    /// Bit i set when the moving box meets child i's box for some s in
    /// [0, 1]; `near` gets the smallest such s (the children's order).
    /// Empty lanes (inverted infinite boxes) give an infinite crossing of
    /// the wrong sign and fail.
    ///
    /// # Safety
    /// The CPU must have AVX2; `W` must be 8.
    #[inline(always)]
    pub(super) unsafe fn test<const W: usize>(&self, n: &super::Node<W>, near: &mut [f32; W]) -> u32 {
        use std::arch::x86_64::*;
        debug_assert_eq!(W, 8);
        let rows = n.bounds.as_ptr() as *const f32;
        let mut s0 = _mm256_setzero_ps();
        let mut s1 = _mm256_set1_ps(1.0);
        for a in 0..3 {
            // The low side against the box's max, the high side against
            // its min.
            for (side, plane) in [(0, a + 3), (1, a)] {
                let b = _mm256_load_ps(rows.add(plane * W));
                let c = _mm256_mul_ps(_mm256_sub_ps(b, _mm256_set1_ps(self.at0[side][a])), _mm256_set1_ps(self.inv_rate[side][a]));
                let clamp = _mm256_set1_ps(self.clamp[side][a]);
                s0 = _mm256_max_ps(s0, _mm256_min_ps(c, clamp));
                s1 = _mm256_min_ps(s1, _mm256_max_ps(c, clamp));
            }
        }
        _mm256_storeu_ps(near.as_mut_ptr(), s0);
        _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(s0, s1)) as u32
    }
}

impl<const W: usize> WideBvh<W> {
    /// Occlusion of a shadow packet by swept boxes: `false` (nothing done)
    /// when some ray is invalid or ends at infinity, or when the end points
    /// spread wider than `LOOSE` of the packet's length (an area light
    /// seen from nearby, which makes a wide wedge of every packet). A
    /// packet whose start points spread that wide is split at the middle
    /// of their box's longest side, again and again, and each part traced
    /// as its own swept box; parts of `MIN_GROUP` rays or fewer that are
    /// still loose go ray by ray. The rays in `occluded` (bits; found by
    /// the occluder cache, not all of them) are answered `true` and left
    /// out of the swept boxes.
    ///
    /// # Safety
    /// The CPU must have AVX2; `W` must be 8; the root must be an interior
    /// node.
    #[target_feature(enable = "avx2")]
    #[inline(never)]
    pub(super) unsafe fn any_sweep_packet(&self, soa: &RaysSoA, rays: &[Ray], out: &mut [bool], order: ChildOrder, occluded: u32) -> bool {
        let n = rays.len();
        let all = (1u32 << n) - 1;
        if soa.valid & soa.finite_tmax & all != all {
            return false;
        }
        let live = all & !occluded;
        debug_assert!(live != 0);
        let e = soa.ends_of(live);
        let mut finite = true;
        for a in 0..3 {
            finite &= e[0][a].is_finite() & e[1][a].is_finite() & e[2][a].is_finite() & e[3][a].is_finite();
        }
        if !finite || loose(&e, 2) {
            return false;
        }
        let pad = Sweep::pad(&e, soa);
        for (i, o) in out[..n].iter_mut().enumerate() {
            *o = occluded >> i & 1 != 0;
        }
        let mut groups = [0u32; PACKET];
        let (mut ng, mut g, mut e) = (0, live, e);
        loop {
            if loose(&e, 0) {
                if g.count_ones() > MIN_GROUP {
                    let axis = (0..3).fold(0, |m, a| if e[1][a] - e[0][a] > e[1][m] - e[0][m] { a } else { m });
                    let below = soa.starts_below(axis, 0.5 * (e[0][axis] + e[1][axis])) & g;
                    if below != 0 && below != g {
                        #[cfg(test)]
                        COUNTS[1].fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        groups[ng] = g & !below;
                        ng += 1;
                        (g, e) = (below, soa.ends_of(below));
                        continue;
                    }
                }
                #[cfg(test)]
                COUNTS[2].fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let mut m = g;
                while m != 0 {
                    let i = m.trailing_zeros() as usize;
                    m &= m - 1;
                    out[i] = self.any::<true>(&rays[i], order);
                }
            } else {
                #[cfg(test)]
                COUNTS[0].fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                self.any_swept(&Sweep::new(&e, pad), soa, rays, out, order, g);
            }
            if ng == 0 {
                return true;
            }
            ng -= 1;
            g = groups[ng];
            e = soa.ends_of(g);
        }
    }

    /// `out[i]` for the rays in `which`: interior nodes tested by the swept
    /// box `sw` of those rays, leaf boxes ray by ray.
    ///
    /// # Safety
    /// The CPU must have AVX2 and the caller must be compiled with it; `W`
    /// must be 8; the root must be an interior node.
    #[inline(always)]
    unsafe fn any_swept(&self, sw: &Sweep, soa: &RaysSoA, rays: &[Ray], out: &mut [bool], order: ChildOrder, which: u32) {
        let n = rays.len();
        debug_assert!(W == 8 && n <= PACKET && self.tree.root & LEAF_BIT == 0);
        let mut tmax = [0.0f32; PACKET];
        tmax[..n].copy_from_slice(&soa.tmax[..n]);
        let mut active = which as u64;
        // Signs and axis permutation shared by these rays, not the packet's.
        let first = which.trailing_zeros();
        let mut signed = false;
        let mut near_plane = [0, 1, 2];
        for a in 0..3 {
            let m = soa.neg[a] & which;
            signed |= m != 0 && m != which;
            if soa.neg[a] >> first & 1 != 0 {
                near_plane[a] = 3 + a;
            }
        }
        let shared_axes = soa.shared_axes_of(which);
        let mut rts: [MaybeUninit<RayTransform>; PACKET] = [const { MaybeUninit::uninit() }; PACKET];
        let mut shears: [MaybeUninit<super::Shear>; PACKET] = [const { MaybeUninit::uninit() }; PACKET];
        let mut setup: u64 = 0;
        let mut stack = WalkStack::<()>::new();
        let mut sp = 0;
        let mut cur = self.tree.root;
        let (mut wasted, mut useful) = (0u32, 0u32);
        loop {
            if wasted > super::frustum::WASTED_LEAF_TESTS && wasted > useful {
                // Looser than it looked (see `WASTED_LEAF_TESTS`): the rest
                // ray by ray.
                let mut a = active;
                while a != 0 {
                    let i = a.trailing_zeros() as usize;
                    a &= a - 1;
                    out[i] = self.any::<true>(&rays[i], order);
                }
                return;
            }
            let node = &self.tree.nodes[cur as usize];
            let mut near = [0.0f32; W];
            let mask = sw.test::<W>(node, &mut near);
            let mut leaves = 0u32;
            for lane in 0..W {
                if node.child[lane] & LEAF_BIT != 0 && node.child[lane] != EMPTY {
                    leaves |= 1 << lane;
                }
            }
            let mut todo = mask & leaves;
            self.prefetch_entered(node, todo);
            while todo != 0 {
                let lane = todo.trailing_zeros() as usize;
                todo &= todo - 1;
                let rays_in = if signed { soa.test_signed(node, lane, &tmax) } else { soa.test(&near_plane, node, lane, &tmax) } & active;
                if rays_in == 0 {
                    wasted += 1;
                    continue;
                }
                useful += 1;
                let leaf = self.leaf_of(node.child[lane]);
                let found = self.leaf_occluded(&leaf, soa, rays, rays_in, shared_axes, &mut tmax, &mut setup, &mut rts, &mut shears);
                if found != 0 {
                    active &= !found;
                    let mut f = found;
                    while f != 0 {
                        let i = f.trailing_zeros() as usize;
                        f &= f - 1;
                        out[i] = true;
                        // Out of the leaf box tests from here on.
                        tmax[i] = f32::NEG_INFINITY;
                    }
                    if active == 0 {
                        return;
                    }
                }
            }
            let inner = mask & !leaves;
            if inner != 0 {
                self.push_entered::<true>(&mut stack, &mut sp, node, inner, &near, order);
            }
            match stack.pop_where(&mut sp, |_, ()| Some(())) {
                Some((code, ())) => cur = code,
                None => return,
            }
        }
    }
}

/// How the packets were traced (tests check every way is exercised):
/// swept parts, splits, rays traced alone because their part stayed loose.
#[cfg(test)]
pub(super) static COUNTS: [std::sync::atomic::AtomicU64; 3] = [const { std::sync::atomic::AtomicU64::new(0) }; 3];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::brute::BruteForce;
    use crate::accel::wide::kernels::Slab;
    use crate::accel::wide::tests::{avx_or_skip, shapes};
    use crate::accel::Traversal;
    use crate::rng::Rng;
    use crate::scene::Shape;
    use glam::Vec3;
    use std::sync::atomic::Ordering::Relaxed;

    /// Packets of shadow rays from points spread over `fan` around a centre
    /// to points spread over `light` around a light (the bench's rays: a
    /// point light; the renderer's: an area light), all in a cube of side
    /// 4 `scale` centred at `offset`.
    fn shadow_packets(n: usize, seed: u64, fan: f32, light: f32, scale: f32, offset: f32) -> Vec<Ray> {
        let mut rng = Rng::new(seed, 3);
        let mut v = |s: f32| (Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) - 0.5) * s;
        let mut rays = Vec::new();
        for _ in 0..n {
            let (c, l) = (v(4.0), v(4.0));
            for _ in 0..PACKET {
                let o = (c + v(fan)) * scale + offset;
                let e = (l + v(light)) * scale + offset;
                rays.push(Ray::with_range(o, e - o, 1e-4, 1.0 - 1e-4));
            }
        }
        rays
    }

    /// The swept box of any subset of a packet's rays enters every child
    /// box one of those rays' own slab test enters (over every node of a
    /// tree, at three scales, for point and area lights, tight and loose
    /// packets), and for tight packets towards a point it enters few more.
    #[test]
    fn the_swept_box_enters_every_box_a_ray_enters() {
        if !avx_or_skip("swept boxes") {
            return;
        }
        for (scale, offset) in [(1.0, 0.0), (1e-3, 5e-3), (1e4, -3e4)] {
            let shapes: Vec<_> = shapes()
                .into_iter()
                .map(|s| match s {
                    Shape::Mesh(mut m) => {
                        m.positions.iter_mut().for_each(|p| *p = *p * scale + offset);
                        Shape::Mesh(m)
                    }
                    Shape::Sphere { center, radius } => Shape::Sphere { center: center * scale + offset, radius: radius * scale },
                })
                .collect();
            let bvh = WideBvh::<8>::build(&shapes);
            let mut rng = Rng::new(5, 8);
            for (fan, light) in [(0.05, 0.0), (0.5, 0.0), (0.05, 0.5), (3.0, 1.0)] {
                let (mut passed, mut entered) = (0u64, 0u64);
                for p in shadow_packets(60, 11, fan, light, scale, offset).chunks(PACKET) {
                    // SAFETY: AVX2 checked above.
                    let soa = unsafe { RaysSoA::new(p) };
                    // SAFETY: as above.
                    let pad = unsafe { Sweep::pad(&soa.ends_of(u16::MAX as u32), &soa) };
                    for w in [u16::MAX as u32, (rng.next_u32() & 0xffff) | 1] {
                        // SAFETY: as above.
                        let sw = Sweep::new(&unsafe { soa.ends_of(w) }, pad);
                        for node in &bvh.tree.nodes {
                            let mut near = [0.0; 8];
                            // SAFETY: as above.
                            let got = unsafe { sw.test::<8>(node, &mut near) };
                            let mut want = 0;
                            for (_, r) in p.iter().enumerate().filter(|(i, _)| w >> i & 1 != 0) {
                                want |= Slab::new(r).test::<8, false>(node, r.tmin, r.tmax, &mut near);
                            }
                            assert_eq!(want & !got, 0, "scale {scale}, fan {fan}, light {light}: a ray enters a box the swept box misses");
                            passed += got.count_ones() as u64;
                            entered += want.count_ones() as u64;
                        }
                    }
                }
                if fan < 0.1 && light == 0.0 {
                    assert!(passed as f64 <= 1.25 * entered as f64, "scale {scale}: a tight packet's swept box enters {passed} boxes, its rays {entered}");
                }
            }
        }
    }

    /// `ends_of` is the bounds of the chosen rays' end points, and
    /// `test_signed` each ray's own slab test for one box.
    #[test]
    fn subset_bounds_and_mixed_sign_box_tests_equal_the_scalar_ones() {
        if !avx_or_skip("swept boxes") {
            return;
        }
        let bvh = WideBvh::<8>::build(&shapes());
        let mut rng = Rng::new(9, 2);
        for p in shadow_packets(40, 3, 3.0, 1.0, 1.0, 0.0).chunks(PACKET) {
            // SAFETY: AVX2 checked above.
            let soa = unsafe { RaysSoA::new(p) };
            let w = (rng.next_u32() & 0xffff) | 4;
            // SAFETY: as above.
            let e = unsafe { soa.ends_of(w) };
            for a in 0..3 {
                let pick = |f: &dyn Fn(&Ray) -> f32| p.iter().enumerate().filter(|(i, _)| w >> i & 1 != 0).map(|(_, r)| f(r)).collect::<Vec<_>>();
                let starts = pick(&|r| r.origin[a] + r.tmin * r.dir[a]);
                let ends = pick(&|r| r.origin[a] + r.tmax * r.dir[a]);
                let lo = |v: &[f32]| v.iter().copied().fold(f32::INFINITY, f32::min);
                let hi = |v: &[f32]| v.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                assert_eq!([e[0][a], e[1][a], e[2][a], e[3][a]], [lo(&starts), hi(&starts), lo(&ends), hi(&ends)]);
            }
            let tmax: [f32; PACKET] = std::array::from_fn(|i| p[i].tmax);
            for node in &bvh.tree.nodes {
                for lane in 0..8 {
                    // SAFETY: as above.
                    let got = unsafe { soa.test_signed(node, lane, &tmax) };
                    for (i, r) in p.iter().enumerate() {
                        let mut near = [0.0; 8];
                        let want = Slab::new(r).test::<8, false>(node, r.tmin, r.tmax, &mut near) >> lane & 1;
                        assert_eq!(got >> i & 1, want as u64, "ray {i}, lane {lane}");
                    }
                }
            }
        }
    }

    /// Shadow packets of every kind — tight, fanned, loose (split, with
    /// rays left alone), mixed signs, area lights, rays to infinity and
    /// invalid rays (the other paths) — are occluded exactly when brute
    /// force says so, and every way of tracing them is taken.
    #[test]
    fn swept_shadow_packets_match_brute_force() {
        if !avx_or_skip("swept boxes") {
            return;
        }
        let shapes = shapes();
        let brute = BruteForce::new(&shapes);
        let bvh = WideBvh::<8>::build(&shapes);
        let mut rays = Vec::new();
        for (k, (fan, light)) in [(0.05, 0.0), (0.5, 0.0), (0.05, 0.5), (3.0, 1.0), (1.5, 0.0)].into_iter().enumerate() {
            rays.extend(shadow_packets(80, 20 + k as u64, fan, light, 1.0, 0.0));
        }
        rays[5].tmax = f32::INFINITY;
        rays[21].dir = Vec3::ZERO;
        rays[40].origin.y = f32::NAN;
        let before: Vec<u64> = COUNTS.iter().map(|c| c.load(Relaxed)).collect();
        let mut out = vec![false; rays.len()];
        bvh.occluded_coherent(&rays, &mut out);
        let bad = rays.iter().zip(&out).filter(|(r, o)| brute.occluded(r) != **o).count();
        assert_eq!(bad, 0, "swept packets: occlusion mismatches against brute force");
        let occluded = out.iter().filter(|o| **o).count();
        assert!(occluded > rays.len() / 10 && occluded < rays.len() * 9 / 10, "{occluded} of {} occluded: the test needs both", rays.len());
        let took: Vec<u64> = COUNTS.iter().zip(&before).map(|(c, b)| c.load(Relaxed) - b).collect();
        assert!(took.iter().all(|&n| n > 0), "swept parts, splits, lone rays: {took:?}");
    }
}
