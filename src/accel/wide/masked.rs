//! Shadow packets that neither a swept box (`sweep`: rays to infinity, end
//! points spread over a nearby area light) nor one interval ray can bound
//! — they fan out towards a nearby light, or mix direction signs — traced
//! together with a
//! *ray mask per stacked node*, as Embree's stream traversal does: every
//! node is tested by each ray that entered it (the single-ray slab test,
//! 8 boxes per instruction), which gives each child the mask of the rays
//! that enter it; leaves are intersected by those rays only, two at a time
//! (`leaf_pair`). A ray leaves the packet once occluded. Against tracing
//! such packets ray by ray, a node shared by several rays is fetched once,
//! and the rays that entered a leaf test its triangles in pairs.
//!
//! Measured (2-vCPU AMD EPYC, `pathtracer bench`, 1 thread, shadow Mrays/s,
//! best of two runs each; this VM's runs swing by up to 40 %): ray by ray
//! before -> masked: CBbunny 17.4 -> 19.2, cow 15.6 -> 17.0, beetle 11.3 ->
//! 12.4, grass:500k 0.31 -> 0.37, stadium:500k 11.2 -> 12.4, arch:500k 20.7
//! -> 21.0 (its packets mostly pass the frustum test). Masked traversal
//! for *every* shadow packet lost on cow and beetle (coherent packets pay
//! 16 box tests per node where the interval ray pays one).
//!
//! Answers equal single-ray traversal's: each ray enters exactly the boxes
//! its own slab test enters (the same operations lane by lane) and tests
//! the same triangles, so it is occluded exactly when it is alone.

use super::kernels::Slab;
use super::triangle::Shear;
use super::packet::{RaysSoA, PACKET};
use super::stack::WalkStack;
use super::{WideBvh, EMPTY, LEAF_BIT};
use crate::geometry::RayTransform;
use crate::ray::Ray;
use std::mem::MaybeUninit;

impl<const W: usize> WideBvh<W> {
    /// `out[i]` = whether `rays[i]` (at most `PACKET`) is occluded.
    ///
    /// # Safety
    /// The CPU must have AVX2 and the caller must be compiled with it; `W`
    /// must be 8.
    #[inline(always)]
    pub(super) unsafe fn any_masked(&self, soa: &RaysSoA, rays: &[Ray], out: &mut [bool], order: super::ChildOrder) {
        use std::arch::x86_64::*;
        debug_assert!(W == 8 && rays.len() <= PACKET);
        let n = rays.len();
        let mut slabs: [MaybeUninit<Slab>; PACKET] = [const { MaybeUninit::uninit() }; PACKET];
        let mut rts: [MaybeUninit<RayTransform>; PACKET] = [const { MaybeUninit::uninit() }; PACKET];
        let mut shears: [MaybeUninit<Shear>; PACKET] = [const { MaybeUninit::uninit() }; PACKET];
        let mut tmax = [0.0f32; PACKET];
        let mut tmin = [0.0f32; PACKET];
        let mut active: u32 = 0;
        for i in 0..n {
            out[i] = false;
            if soa.valid >> i & 1 != 0 {
                active |= 1 << i;
                slabs[i].write(soa.slab(i));
                tmin[i] = soa.tmin[i];
                tmax[i] = soa.tmax[i];
            }
        }
        if active == 0 || self.tree.root == EMPTY {
            return;
        }
        if self.tree.root & LEAF_BIT != 0 {
            for i in 0..n {
                if active & (1 << i) != 0 {
                    out[i] = self.any::<true>(&rays[i], order);
                }
            }
            return;
        }
        // Triangle-test constants, made the first time a ray reaches a leaf.
        let mut setup: u64 = 0;
        // One axis permutation for all rays: leaves as in `frustum_packet`.
        let shared_axes = soa.shared_axes();
        // Stack of (node, the rays' nearest entry, the rays that entered it).
        let mut stack = WalkStack::<u32>::new();
        let mut sp = 0;
        let (mut code, mut entered) = (self.tree.root, active);
        let inf = _mm256_set1_ps(f32::INFINITY);
        loop {
            let node = &self.tree.nodes[code as usize];
            // Each ray that entered this node against its 8 boxes: per
            // child, the bits of the rays entering it and their nearest
            // entry distance.
            let mut masks = _mm256_setzero_si256();
            let mut near = inf;
            let mut todo = entered & active;
            while todo != 0 {
                let i = todo.trailing_zeros() as usize;
                todo &= todo - 1;
                let (t0, t1) = slabs[i].assume_init_ref().entry_exit::<__m256, W>(node, 0, tmin[i], tmax[i]);
                let hit = _mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1);
                masks = _mm256_or_si256(masks, _mm256_and_si256(_mm256_castps_si256(hit), _mm256_set1_epi32(1 << i)));
                near = _mm256_min_ps(near, _mm256_blendv_ps(inf, t0, hit));
            }
            let mut child_rays = [0u32; 8];
            let mut child_near = [0.0f32; 8];
            _mm256_storeu_si256(child_rays.as_mut_ptr() as *mut __m256i, masks);
            _mm256_storeu_ps(child_near.as_mut_ptr(), near);
            let mark = sp;
            for lane in 0..W {
                let (child, r) = (node.child[lane], child_rays[lane] & active);
                if r == 0 || child == EMPTY {
                    continue;
                }
                if child & LEAF_BIT == 0 {
                    self.prefetch_entered(node, 1 << lane);
                    stack.push(&mut sp, child, child_near[lane], r);
                    continue;
                }
                // A leaf: the rays that entered it test its triangles, two at
                // a time where it holds only triangles.
                let leaf = self.leaf_of(child);
                let mut found = self.leaf_occluded(&leaf, soa, rays, r as u64, shared_axes, &mut tmax, &mut setup, &mut rts, &mut shears) as u32;
                active &= !found;
                while found != 0 {
                    out[found.trailing_zeros() as usize] = true;
                    found &= found - 1;
                }
                if active == 0 {
                    return;
                }
            }
            // The child `order` visits next on top (see `ChildOrder`).
            stack.order_since(mark, sp, order);
            // Pop the next node some still-unoccluded ray entered.
            match stack.pop_where(&mut sp, |_, r| (r & active != 0).then_some(r)) {
                Some(e) => (code, entered) = e,
                None => return,
            }
        }
    }
}
