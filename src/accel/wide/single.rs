//! Single rays, front to back: the 8-wide walk every other traversal
//! falls back on (`walk`), closest and any hit for one ray and for
//! batches traced ray by ray, and the child order any-hit rays take,
//! chosen when the tree is built from a sample of shadow-like rays over
//! the scene's triangles (`any_order_of`).

use super::kernels::Slab;
#[cfg(target_arch = "x86_64")]
use super::packet::{RaysSoA, PACKET};
use super::triangle::Shear;
use super::stack::{ChildOrder, WalkStack};
use super::{WideBvh, EMPTY, LEAF_BIT};
use crate::accel::prims::closer;
use crate::accel::Hit;
use crate::geometry::RayTransform;
use crate::ray::Ray;

/// Rays in the sample that chooses the any-hit child order
/// (`any_order_of`): from 512 to 4096 rays the ratios moved by 3 % at
/// most (grass:500k 0.660 to 0.678, subdiv:bunny:100k 1.100 to 1.073), no
/// choice with them.
const ORDER_SAMPLE: usize = 512;
/// Nearest first is chosen only where its sampled work is below 7/8 of
/// farthest first's. The sample times single rays; coherent batches go in
/// packets, where nearest first's saving showed up smaller: on maxplanck
/// its sums were 5 % below farthest first's, yet its shadow rays ran at
/// 10.7 Mrays/s against 11.8 (1 thread); on stadium 22 % below (24.1
/// against 19.8 Mrays/s), on grass 62 % below (0.24 against 0.15).
const ORDER_MARGIN: (f64, f64) = (7.0, 8.0);

impl<const W: usize> WideBvh<W> {
    /// Front-to-back traversal; `visit` may lower `tmax` and returns true to
    /// stop. `AVX` selects the AVX2 box test, which the caller must have
    /// checked the CPU has (`self.policy.avx()`) and compiled for (`#[target_feature]`).
    #[inline(always)]
    fn walk<const AVX: bool, const ANY: bool, F: FnMut(Hit, &mut f32) -> bool>(&self, ray: &Ray, order: ChildOrder, work: &mut u32, visit: F) {
        if self.tree.root == EMPTY {
            return;
        }
        let rt = RayTransform::new(ray.origin, ray.dir);
        let shear = Shear::new(&rt);
        let slab = Slab::new(ray);
        self.walk_set_up::<AVX, ANY, F>(ray, &rt, &shear, &slab, order, work, visit)
    }

    /// `walk` of a ray whose constants are already made (`RayTransform`,
    /// `Shear`, `Slab`: as their `new` makes them, or as the packet set-up
    /// makes them for 16 rays at once); the tree is not empty.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn walk_set_up<const AVX: bool, const ANY: bool, F: FnMut(Hit, &mut f32) -> bool>(&self, ray: &Ray, rt: &RayTransform, shear: &Shear, slab: &Slab, order: ChildOrder, work: &mut u32, visit: F) {
        self.walk_from::<AVX, ANY, F>(self.tree.root, ray, rt, shear, slab, order, work, visit)
    }

    /// `walk_set_up` of the subtree at `start` (a node's or a leaf's code)
    /// instead of the whole tree.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn walk_from<const AVX: bool, const ANY: bool, F: FnMut(Hit, &mut f32) -> bool>(&self, start: u32, ray: &Ray, rt: &RayTransform, shear: &Shear, slab: &Slab, order: ChildOrder, work: &mut u32, mut visit: F) {
        let mut tmax = ray.tmax;
        let mut stack = WalkStack::<()>::new();
        let mut sp = 0;
        let mut cur = start;
        loop {
            if cur & LEAF_BIT != 0 {
                let leaf = self.leaf_of(cur);
                *work += leaf.n_groups + leaf.n_spheres;
                let mut stop = false;
                self.leaf(&leaf, ray, rt, shear, tmax, &mut |h| {
                    stop = visit(h, &mut tmax);
                    stop
                });
                if stop {
                    return;
                }
            } else {
                *work += 1;
                let node = &self.tree.nodes[cur as usize];
                let mut near = [0.0f32; W];
                let mask = slab.test::<W, AVX>(node, ray.tmin, tmax, &mut near);
                if mask != 0 {
                    if mask & (mask - 1) == 0 {
                        // One child entered: no stack traffic.
                        self.prefetch_entered(node, mask);
                        cur = node.child[mask.trailing_zeros() as usize];
                        continue;
                    }
                    let rest = mask & (mask - 1);
                    if rest & (rest - 1) == 0 && order == ChildOrder::NearestFirst {
                        // Two children, nearest first: go on with the nearer
                        // and push the other, without the general push and
                        // sort (on a tie the higher lane first, as there).
                        // Random rays on cow, maxplanck, beetle +4-6 %.
                        let (a, b) = (mask.trailing_zeros() as usize, rest.trailing_zeros() as usize);
                        let (ca, cb) = (node.child[a], node.child[b]);
                        self.prefetch(ca);
                        self.prefetch(cb);
                        let a_first = near[a] < near[b];
                        let (go, push, d) = if a_first { (ca, cb, near[b]) } else { (cb, ca, near[a]) };
                        stack.push(&mut sp, push, d, ());
                        cur = go;
                        continue;
                    }
                    // Push every entered child (the one `order` visits
                    // next on top), and continue with the top one.
                    self.push_entered::<AVX>(&mut stack, &mut sp, node, mask, &near, order);
                    cur = stack.take_top(&mut sp).0;
                    continue;
                }
            }
            // Pop, skipping subtrees that start beyond the current closest hit.
            match stack.pop_within(&mut sp, tmax) {
                Some(code) => cur = code,
                None => return,
            }
        }
    }

    #[inline(always)]
    pub(super) fn closest<const AVX: bool>(&self, ray: &Ray) -> Option<Hit> {
        self.closest_counted::<AVX>(ray, &mut 0)
    }

    /// `closest`, adding the nodes and leaf groups it visits to `work`.
    #[inline(always)]
    pub(super) fn closest_counted<const AVX: bool>(&self, ray: &Ray, work: &mut u32) -> Option<Hit> {
        if self.tree.root == EMPTY {
            return None;
        }
        let rt = RayTransform::new(ray.origin, ray.dir);
        self.closest_set_up::<AVX>(ray, &rt, &Shear::new(&rt), &Slab::new(ray), work)
    }

    /// `closest_counted` of a ray whose constants are made (`walk_set_up`).
    #[inline(always)]
    fn closest_set_up<const AVX: bool>(&self, ray: &Ray, rt: &RayTransform, shear: &Shear, slab: &Slab, work: &mut u32) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        self.walk_set_up::<AVX, false, _>(ray, rt, shear, slab, ChildOrder::NearestFirst, work, |h, tmax| {
            if closer(h, &best) {
                *tmax = h.t;
                best = Some(h);
            }
            false
        });
        best
    }

    /// `walk_set_up` over the subtrees `roots` in turn, each given with a
    /// lower bound of the ray's entry distance (one beyond the ray's range
    /// by then is skipped, as a popped stack entry is): how a packet that
    /// gives up hands each ray the subtrees it had still to visit
    /// (`frustum`), instead of the whole tree again.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn walk_subtrees<const AVX: bool, const ANY: bool, F: FnMut(Hit, &mut f32) -> bool>(&self, roots: impl Iterator<Item = (u32, f32)>, ray: &Ray, rt: &RayTransform, shear: &Shear, slab: &Slab, order: ChildOrder, mut visit: F) {
        let mut tmax = ray.tmax;
        for (code, near) in roots {
            if !super::stack::may_hold_closer(near, tmax) {
                continue;
            }
            let mut stop = false;
            self.walk_from::<AVX, ANY, _>(code, &Ray { tmax, ..*ray }, rt, shear, slab, order, &mut 0, |h, t| {
                stop = visit(h, t);
                tmax = *t;
                stop
            });
            if stop {
                return;
            }
        }
    }

    avx_twins! {
        /// `closest_all` of a batch whose rays are set up 16 at a time in one
        /// AVX2 pass (`RaysSoA`: the same constants, bit for bit, as each
        /// ray's own set-up), then walked one at a time, but for the rays
        /// that the batch's `first` stream traced (none when `None`), whose
        /// hits are left as they are. Never inlined: one compiled loop for
        /// every caller (`FirstStream`).
        fn closest_batch_except / closest_batch_except_avx2 / closest_batch_except_avx512vl(&self, rays: &[Ray], hits: &mut [Option<Hit>], first: Option<super::stream::FirstStream>)
        #[inline(never)]
        {
            if self.tree.root == EMPTY {
                hits.fill(None);
                return;
            }
            for (c, (r, h)) in rays.chunks(PACKET).zip(hits.chunks_mut(PACKET)).enumerate() {
                let soa = RaysSoA::new_with::<false>(r);
                for (i, (ray, hit)) in r.iter().zip(h.iter_mut()).enumerate() {
                    if super::stream::FirstStream::traced(first, rays, c * PACKET + i) {
                        continue;
                    }
                    *hit = if soa.valid >> i & 1 == 0 {
                        None
                    } else {
                        let (rt, shear) = soa.shear(i);
                        self.closest_set_up::<true>(ray, &rt, &shear, &soa.slab(i), &mut 0)
                    };
                }
            }
        }
    }

    #[inline(always)]
    pub(super) fn any<const AVX: bool>(&self, ray: &Ray, order: ChildOrder) -> bool {
        self.any_counted::<AVX>(ray, order, &mut 0)
    }

    /// `any`, adding the nodes and leaf groups it visits to `work`.
    #[inline(always)]
    pub(super) fn any_counted<const AVX: bool>(&self, ray: &Ray, order: ChildOrder, work: &mut u32) -> bool {
        let mut hit = false;
        self.walk::<AVX, true, _>(ray, order, work, |_, _| {
            hit = true;
            true
        });
        hit
    }

    /// The child order for this tree's occlusion rays: whichever of
    /// farthest first and nearest first visits fewer nodes and leaf groups
    /// on `ORDER_SAMPLE` shadow-like rays, nearest first only by a margin
    /// (`ORDER_MARGIN`). Which order finds occluders sooner depends on the
    /// scene (see `ChildOrder`); both give the same answers.
    ///
    /// The sample (`sample`, `Within::Centroid`): rays from the centroids
    /// of triangles picked by area, stratified over the scene's own order
    /// of triangles (not the tree's, which changes with how the build
    /// partitions: sampled by place in the tree's arrays, a partition that
    /// built the same tree in another order flipped grass:500k's choice),
    /// on the side facing a point just under the top of the scene's box,
    /// where lights usually are and where the benchmark's shadow rays go.
    /// Against the work of the benchmark's own shadow rays (256x192 camera
    /// hits), nearest ÷ farthest first, the sample ÷ the shadow rays: cow
    /// 1.57 / 1.79, maxplanck 0.996 / 0.977, beetle 0.971 / 1.068, CBbunny
    /// 1.062 / 1.075, stadium:500k 0.864 / 0.856, grass:500k 0.660 / 0.720,
    /// arch:100k 1.03 / 1.36, sphere:100k 1.00 / 1.00, subdiv:bunny:100k
    /// 1.10 / 1.20: the same choice on every scene. From points uniform
    /// within the triangles instead of centroids, stadium's sample read
    /// 0.938 (512 and 4096 rays alike) and chose farthest first. Chosen
    /// once, when the tree is built, so that the same batch always takes
    /// the same way; chosen per batch from the batches' own rays (every
    /// 16th batch, the sums decaying), the choice depended on which
    /// thread's batch came first. The sample's pass over the triangles'
    /// areas costs about 1 % of a build (10 ms of sphere:5m's 800 on 2
    /// threads).
    pub(super) fn any_order_of(&self, prims: &crate::accel::prims::PrimTable) -> ChildOrder {
        let (far, near) = self.any_order_work(prims);
        if near * ORDER_MARGIN.1 < far * ORDER_MARGIN.0 {
            ChildOrder::NearestFirst
        } else {
            ChildOrder::FarthestFirst
        }
    }

    /// The mean work of farthest-first and nearest-first any-hit rays over
    /// the shadow rays of the tree's sample (`any_order_of`).
    pub(super) fn any_order_work(&self, prims: &crate::accel::prims::PrimTable) -> (f64, f64) {
        let sample = self.sample(prims, ORDER_SAMPLE, super::sample::Within::Centroid);
        (self.any_work(&sample.shadow, ChildOrder::FarthestFirst), self.any_work(&sample.shadow, ChildOrder::NearestFirst))
    }

    /// The closest hit of `ray`, `None` for an invalid one.
    #[inline(always)]
    fn closest_if_valid<const AVX: bool>(&self, ray: &Ray) -> Option<Hit> {
        if ray.is_valid() { self.closest::<AVX>(ray) } else { None }
    }

    /// Whether `ray` is valid and occluded, its walk in `order`.
    #[inline(always)]
    fn any_if_valid<const AVX: bool>(&self, ray: &Ray, order: ChildOrder) -> bool {
        ray.is_valid() && self.any::<AVX>(ray, order)
    }

    #[inline(always)]
    pub(super) fn closest_all<const AVX: bool>(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        for (r, h) in rays.iter().zip(hits.iter_mut()) {
            *h = self.closest_if_valid::<AVX>(r);
        }
    }

    #[inline(always)]
    pub(super) fn any_all<const AVX: bool>(&self, rays: &[Ray], out: &mut [bool]) {
        self.any_all_ordered::<AVX>(rays, out, self.policy.any_order)
    }

    #[inline(always)]
    pub(super) fn any_all_ordered<const AVX: bool>(&self, rays: &[Ray], out: &mut [bool], order: ChildOrder) {
        for (r, o) in rays.iter().zip(out.iter_mut()) {
            *o = self.any_if_valid::<AVX>(r, order);
        }
    }

    /// The closest hit of one ray (`None` for an invalid one) with the
    /// policy's kernels. Inlined into `intersect`, each way's walk out of
    /// line: with the scalar walk inlined too, `intersect` had a 6 KiB
    /// frame, realigned and probed on every call; and not as a batch of
    /// one, whose loop and hit written to memory cost a little more. The
    /// one-ray calls gained up to 11 % (arch's random rays; grass's diffuse
    /// rays level), docs/notes/2026-12-02-one-ray-calls.md.
    #[inline(always)]
    pub(super) fn closest_one_simd(&self, ray: &Ray) -> Option<Hit> {
        #[cfg(target_arch = "x86_64")]
        if self.policy.avx() {
            // SAFETY: checked just now.
            return unsafe { self.closest_one_avx(ray) };
        }
        self.closest_one_scalar(ray)
    }

    /// Whether one ray is occluded, as `closest_one_simd`.
    #[inline(always)]
    pub(super) fn any_one_simd(&self, ray: &Ray) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self.policy.avx() {
            // SAFETY: checked just now.
            return unsafe { self.any_one_avx(ray) };
        }
        self.any_one_scalar(ray)
    }

    /// `any_all` with the policy's kernels, each way out of line (as
    /// `closest_one_simd`).
    #[inline(always)]
    pub(super) fn any_all_simd(&self, rays: &[Ray], out: &mut [bool]) {
        #[cfg(target_arch = "x86_64")]
        if self.policy.avx() {
            // SAFETY: checked just now.
            return unsafe { self.any_all_avx(rays, out) };
        }
        self.any_all_scalar(rays, out)
    }

    /// `closest_one_simd` without AVX2.
    #[inline(never)]
    fn closest_one_scalar(&self, ray: &Ray) -> Option<Hit> {
        self.closest_if_valid::<false>(ray)
    }

    /// `any_one_simd` without AVX2.
    #[inline(never)]
    fn any_one_scalar(&self, ray: &Ray) -> bool {
        self.any_if_valid::<false>(ray, self.policy.any_order)
    }

    /// `any_all_simd` without AVX2.
    #[inline(never)]
    fn any_all_scalar(&self, rays: &[Ray], out: &mut [bool]) {
        self.any_all::<false>(rays, out)
    }

    avx_twins! {
        /// `closest_one_simd` with the AVX2 kernels.
        fn closest_one_avx / closest_one_avx2 / closest_one_avx512vl(&self, ray: &Ray) -> [Option<Hit>]
        #[inline(never)]
        {
            self.closest_if_valid::<true>(ray)
        }
    }

    avx_twins! {
        /// `any_one_simd` with the AVX2 kernels.
        fn any_one_avx / any_one_avx2 / any_one_avx512vl(&self, ray: &Ray) -> [bool]
        #[inline(never)]
        {
            self.any_if_valid::<true>(ray, self.policy.any_order)
        }
    }

    avx_twins! {
        /// `any_all` with the AVX2 kernels.
        fn any_all_avx / any_all_avx2 / any_all_avx512vl(&self, rays: &[Ray], out: &mut [bool]) {
            self.any_all::<true>(rays, out)
        }
    }
}
