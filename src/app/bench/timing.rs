//! Timing ray throughput: passes of a ray set through one or several
//! backends on a given number of threads, chunks of 4096 rays per task,
//! the best pass kept.

use crate::accel::Traversal;
use crate::ray::Ray;
use rayon::prelude::*;
use std::time::Instant;

#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum RayKind {
    Camera,
    Shadow,
    /// Closest hits through the incoherent batch call (`intersect_batch`):
    /// random and diffuse rays.
    Random,
    /// Closest hits one ray per call (`intersect`): what a caller without
    /// batches gets.
    Single,
    /// Shadow rays through the incoherent batch call (`occluded_batch`):
    /// only for the Embree batch-call table, where Embree's stream with the
    /// incoherent flag is its fastest call on some scenes (so unused in a
    /// build without Embree).
    #[cfg_attr(not(has_embree), allow(dead_code))]
    ShadowIncoherent,
}

/// The ray kinds every contender is timed on, with the set each traces and
/// the call it goes through: camera and shadow rays as coherent batches;
/// random and diffuse rays as incoherent batches and one ray per call.
pub(super) const TIMED: [(&str, RaySet, RayKind); 6] = [
    ("camera", RaySet::Camera, RayKind::Camera),
    ("shadow", RaySet::Shadow, RayKind::Shadow),
    ("random", RaySet::Random, RayKind::Random),
    ("random single", RaySet::Random, RayKind::Single),
    ("diffuse", RaySet::Diffuse, RayKind::Random),
    ("diffuse single", RaySet::Diffuse, RayKind::Single),
];

/// The ray kinds' labels, in the tables' order.
pub(super) fn labels() -> impl Iterator<Item = &'static str> {
    TIMED.iter().map(|t| t.0)
}

/// Which of the bench's ray sets (`rays`) a timed kind traces.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum RaySet {
    Camera,
    Shadow,
    Random,
    Diffuse,
}

/// Best-of-`reps` Mrays/s on `threads` threads, chunks of 4096 rays, after
/// one untimed pass when `reps` > 1 (brute force's single long pass needs
/// none). Camera and shadow rays go through the coherent batch calls,
/// random rays through the plain ones. Without the warm-up pass, the first
/// backend measured on the first scene often read a third low in all three
/// timed passes (cow camera rays, 1 thread: 39-54 Mrays/s in four of seven
/// runs, 65-66 in the others), as if the CPU were still clocking up.
pub(super) fn throughput(accel: &dyn Traversal, rays: &[Ray], kind: RayKind, threads: usize, reps: usize) -> f64 {
    timed_passes(&[(accel, kind)], rays, threads, reps, reps > 1)[0]
}

/// Timed passes per contender in `throughputs`.
pub const PASSES: usize = 5;

/// `throughput` for several structures on the same rays, their passes
/// alternating — one untimed pass each, then `passes` rounds of one timed
/// pass each — and the best pass of each kept. Timed one structure after
/// the other (three passes each), a slow stretch of this shared VM that
/// fell on one contender's passes decided the ratio: arch_2M shadow rays
/// read native ÷ Embree 0.63 in a full bench run and 1.01 / 0.99 in two
/// runs of that scene alone, with the same binary.
pub(super) fn throughputs(accels: &[&dyn Traversal], rays: &[Ray], kind: RayKind, threads: usize, passes: usize) -> Vec<f64> {
    let each: Vec<(&dyn Traversal, RayKind)> = accels.iter().map(|&a| (a, kind)).collect();
    timed_passes(&each, rays, threads, passes, true)
}

/// `throughputs` with each structure's own call (`RayKind`) for the same
/// rays: native's batch call against another backend's fastest.
#[cfg(has_embree)]
pub(super) fn throughputs_by_call(each: &[(&dyn Traversal, RayKind)], rays: &[Ray], threads: usize, passes: usize) -> Vec<f64> {
    timed_passes(each, rays, threads, passes, true)
}

/// Mrays/s of each of `accels` through its call: `passes` rounds of one
/// timed pass each, after one untimed round when `warm_up`, the best pass
/// of each kept.
fn timed_passes(accels: &[(&dyn Traversal, RayKind)], rays: &[Ray], threads: usize, passes: usize, warm_up: bool) -> Vec<f64> {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("thread pool");
    let mut best = vec![f64::INFINITY; accels.len()];
    let skip = warm_up as usize;
    for pass in 0..passes + skip {
        for (&(a, kind), b) in accels.iter().zip(best.iter_mut()) {
            let start = Instant::now();
            pool.install(|| trace_pass(a, rays, kind));
            if pass >= skip {
                *b = b.min(start.elapsed().as_secs_f64());
            }
        }
    }
    best.iter().map(|b| rays.len() as f64 / b / 1e6).collect()
}

/// One pass of `rays` through `accel` on the current pool, chunks of 4096,
/// each its own task (`with_max_len(1)`): rayon's default splitting cut a
/// pass into a few long runs of chunks, and where the costly rays are
/// bunched (the camera rays that hit arch's building, a band of the frame)
/// one thread was left with most of them — arch_2M camera rays scaled 1.29x
/// from 1 to 2 threads for native and 1.98x for Embree in one run.
fn trace_pass(accel: &dyn Traversal, rays: &[Ray], kind: RayKind) {
    rays.par_chunks(4096).with_max_len(1).for_each(|chunk| match kind {
        RayKind::Shadow | RayKind::ShadowIncoherent => {
            let mut out = vec![false; chunk.len()];
            if kind == RayKind::Shadow {
                accel.occluded_coherent(chunk, &mut out);
            } else {
                accel.occluded_batch(chunk, &mut out);
            }
            std::hint::black_box(&out);
        }
        RayKind::Camera | RayKind::Random => {
            let mut out = vec![None; chunk.len()];
            if kind == RayKind::Camera {
                accel.intersect_coherent(chunk, &mut out);
            } else {
                accel.intersect_batch(chunk, &mut out);
            }
            std::hint::black_box(&out);
        }
        RayKind::Single => {
            let out: Vec<Option<crate::accel::Hit>> = chunk.iter().map(|r| accel.intersect(r)).collect();
            std::hint::black_box(&out);
        }
    })
}
