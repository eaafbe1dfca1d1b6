//! A triangle-only leaf's triangles tested for several rays of a packet or
//! stream at once, each ray getting the answer it would get alone (the
//! same watertight test, the tie rule for closest hits): 8 rays against one
//! triangle per instruction for occlusion with a shared axis permutation
//! (`leaf_rays_x8`), two or four rays per instruction against a group of
//! four triangles (`leaf_pair`, `leaf_quad`; `leaf_pair_any` for occlusion),
//! and the occlusion of whichever rays entered a leaf (`leaf_occluded`), for
//! the frustum, swept, masked and stream traversals.

use super::triangle::{intersect_group, intersect_group_x2, intersect_group_x4, LaneHit};
use super::packet::{RaysSoA, PACKET};
use super::{Shear, WideBvh, EMPTY, LANES};
use crate::accel::prims::closer;
use crate::accel::Hit;
use crate::geometry::RayTransform;
use crate::ray::Ray;
use std::mem::MaybeUninit;

impl<const W: usize> WideBvh<W> {
    /// Which of the rays `rays_in` (bits) hit some triangle of a
    /// triangle-only leaf, for rays sharing the axis permutation `k`: each
    /// triangle against 8 rays at a time (`RaysSoA::hits_triangle`), rays
    /// leaving once they hit. Occlusion only: which triangle is not kept.
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[inline(always)]
    pub(super) unsafe fn leaf_rays_x8(&self, leaf: &super::Leaf, soa: &RaysSoA, rays_in: u64, k: [usize; 3], tmax: &[f32; PACKET]) -> u64 {
        let mut left = rays_in;
        for gi in leaf.group..leaf.group + leaf.n_groups {
            let g = &self.tree.groups[gi as usize];
            let ids = &g.ids;
            for (lane, id) in ids.iter().enumerate() {
                if id[0] == EMPTY {
                    continue;
                }
                for half in 0..PACKET / 8 {
                    if (left >> (8 * half)) & 0xff != 0 {
                        let hit = soa.hits_triangle(g, lane, half, k, tmax) as u64 & (left >> (8 * half)) & 0xff;
                        if hit != 0 {
                            soa.occluder.set(gi * LANES as u32 + lane as u32);
                        }
                        left &= !(hit << (8 * half));
                    }
                }
                if left == 0 {
                    return rays_in;
                }
            }
        }
        rays_in & !left
    }

    /// Which of the rays `rays_in` (bits) `leaf` occludes, each as it would
    /// alone: with one axis permutation `shared_axes` for a triangle-only
    /// leaf, 8 rays against one triangle at a time (`leaf_rays_x8`); else
    /// two at a time through triangle-only leaves (`leaf_pair`), one at a
    /// time where spheres are, each ray's shear made the first time it
    /// reaches a leaf (bit i of `setup`). For the occlusion traversals
    /// (`sweep`, `masked`).
    ///
    /// # Safety
    /// The CPU must have AVX2; every ray in `rays_in` is valid.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub(super) unsafe fn leaf_occluded(
        &self,
        leaf: &super::Leaf,
        soa: &RaysSoA,
        rays: &[Ray],
        mut rays_in: u64,
        shared_axes: Option<[usize; 3]>,
        tmax: &mut [f32; PACKET],
        setup: &mut u64,
        rts: &mut [MaybeUninit<RayTransform>; PACKET],
        shears: &mut [MaybeUninit<Shear>; PACKET],
    ) -> u64 {
        if let Some(k) = shared_axes.filter(|_| leaf.n_spheres == 0) {
            return self.leaf_rays_x8(leaf, soa, rays_in, k, tmax);
        }
        let mut found = 0u64;
        while rays_in != 0 {
            let i = rays_in.trailing_zeros() as usize;
            rays_in &= rays_in - 1;
            let j = (rays_in != 0 && leaf.n_spheres == 0).then(|| rays_in.trailing_zeros() as usize);
            for k in [Some(i), j].into_iter().flatten() {
                if *setup & (1u64 << k) == 0 {
                    *setup |= 1u64 << k;
                    let (rt, sh) = soa.shear(k);
                    shears[k].write(sh);
                    rts[k].write(rt);
                }
            }
            if let Some(j) = j {
                rays_in &= rays_in - 1;
                // Occlusion never writes a hit: no hit slots needed.
                let hit = self.leaf_pair::<true>(leaf, [i, j], rays, rts, shears, tmax, &mut []);
                found |= (hit[0] as u64) << i | (hit[1] as u64) << j;
            } else if self.leaf(leaf, &rays[i], rts[i].assume_init_ref(), shears[i].assume_init_ref(), tmax[i], &mut |_: Hit| true) {
                found |= 1u64 << i;
            }
        }
        found
    }

    /// A triangle-only leaf for rays `ij` together (`intersect_group_x2`),
    /// as `leaf` would for each: every group tested with the range each ray
    /// had on entering the leaf, closest hits kept by the tie rule. With
    /// `ANY`, returns which rays found a hit (`leaf_pair_any`).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub(super) unsafe fn leaf_pair<const ANY: bool>(
        &self,
        leaf: &super::Leaf,
        ij: [usize; 2],
        rays: &[Ray],
        rts: &[MaybeUninit<RayTransform>; PACKET],
        shears: &[MaybeUninit<Shear>; PACKET],
        tmax: &mut [f32; PACKET],
        hits: &mut [Option<Hit>],
    ) -> [bool; 2] {
        let rt = ij.map(|i| rts[i].assume_init_ref());
        let sh = ij.map(|i| shears[i].assume_init_ref());
        let tmin = ij.map(|i| rays[i].tmin);
        let range = ij.map(|i| tmax[i]);
        if ANY {
            return self.leaf_pair_any(leaf, rt, sh, tmin, range);
        }
        let mut found = [false; 2];
        for gi in leaf.group..leaf.group + leaf.n_groups {
            let g = &self.tree.groups[gi as usize];
            let ids = &g.ids;
            let mut out = [[LaneHit::default(); LANES]; 2];
            let masks = intersect_group_x2(g, rt, sh, tmin, range, &mut out);
            take_hits::<false, 2>(ij, masks, &out, ids, &mut found, tmax, hits);
        }
        found
    }

    /// Whether two rays (their transforms, shears and ranges) hit a
    /// triangle of a triangle-only leaf: tested together until one hits,
    /// then the other alone. Shared by the packets' occlusion (`leaf_pair`)
    /// and the streams, which keep their rays' state in arrays of their own.
    #[inline(always)]
    pub(super) unsafe fn leaf_pair_any(&self, leaf: &super::Leaf, rt: [&RayTransform; 2], sh: [&Shear; 2], tmin: [f32; 2], tmax: [f32; 2]) -> [bool; 2] {
        let mut found = [false; 2];
        for gi in leaf.group..leaf.group + leaf.n_groups {
            let g = &self.tree.groups[gi as usize];
            // Padding lanes are told apart only for a hit.
            let real = |m: u32| m != 0 && (0..LANES).any(|l| m >> l & 1 != 0 && g.ids[l][0] != EMPTY);
            let mut out = [[LaneHit::default(); LANES]; 2];
            if found[0] || found[1] {
                // One ray is done: the other goes on alone.
                let r = found[0] as usize;
                found[r] = real(intersect_group(g, rt[r], sh[r], tmin[r], tmax[r], &mut out[r]));
            } else {
                let m = intersect_group_x2(g, rt, sh, tmin, tmax, &mut out);
                found = [real(m[0]), real(m[1])];
            }
            if found[0] && found[1] {
                break;
            }
        }
        found
    }

    /// `leaf_pair` for four rays (`intersect_group_x4`); a ray may appear
    /// twice (its hits are then offered twice, which the tie rule ignores).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub(super) unsafe fn leaf_quad<const ANY: bool>(
        &self,
        leaf: &super::Leaf,
        quad: [usize; 4],
        rays: &[Ray],
        rts: &[MaybeUninit<RayTransform>; PACKET],
        shears: &[MaybeUninit<Shear>; PACKET],
        tmax: &mut [f32; PACKET],
        hits: &mut [Option<Hit>],
    ) -> [bool; 4] {
        let rt = quad.map(|i| rts[i].assume_init_ref());
        let sh = quad.map(|i| shears[i].assume_init_ref());
        let tmin = quad.map(|i| rays[i].tmin);
        let range = quad.map(|i| tmax[i]);
        let mut found = [false; 4];
        for gi in leaf.group..leaf.group + leaf.n_groups {
            let g = &self.tree.groups[gi as usize];
            let ids = &g.ids;
            let mut out = [[LaneHit::default(); LANES]; 4];
            let masks = intersect_group_x4(g, rt, sh, tmin, range, &mut out);
            take_hits::<ANY, 4>(quad, masks, &out, ids, &mut found, tmax, hits);
            if ANY && found.iter().all(|&f| f) {
                break;
            }
        }
        found
    }
}

/// One triangle group's results for rays `which` (`masks[r]`, `out[r]`
/// for ray `which[r]`, lanes identified by `ids`): with `ANY`, marks in
/// `found` the rays that hit something (rays already found are skipped);
/// else keeps each ray's closest hit by the tie rule and shortens its range.
#[inline(always)]
fn take_hits<const ANY: bool, const N: usize>(
    which: [usize; N],
    masks: [u32; N],
    out: &[[LaneHit; LANES]; N],
    ids: &[[u32; 2]],
    found: &mut [bool; N],
    tmax: &mut [f32; PACKET],
    hits: &mut [Option<Hit>],
) {
    for r in 0..N {
        if ANY && found[r] {
            continue;
        }
        let mut m = masks[r];
        while m != 0 {
            let lane = m.trailing_zeros() as usize;
            m &= m - 1;
            if ids[lane][0] == EMPTY {
                continue;
            }
            if ANY {
                found[r] = true;
                break;
            }
            let l = out[r][lane];
            let h = Hit { t: l.t, u: l.u, v: l.v, geom_id: ids[lane][0], prim_id: ids[lane][1] };
            if closer(h, &hits[which[r]]) {
                tmax[which[r]] = h.t;
                hits[which[r]] = Some(h);
            }
        }
    }
}
