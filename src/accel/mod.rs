//! Ray traversal backends behind one trait.
//!
//! A backend answers one question: *which primitive does this ray hit first*
//! (or *does it hit anything*). It knows nothing of normals, materials or
//! lights; `scene::Interaction` describes the hit from the record returned here.

pub mod agreement;
pub mod brute;
pub mod bvh;
mod huge;
pub mod wide;
pub mod embree;
#[cfg(feature = "peers")]
pub mod obvhs_peer;
#[cfg(feature = "peers")]
pub mod tinybvh_peer;
pub mod options;
pub mod prims;
pub mod workloads;

pub use options::{BatchWay, BuildOptions, NativeIsa, NativeOptions, ShadowWay, Splits};

use crate::error::Result;
pub use crate::ray::Hit;
use crate::ray::Ray;
use crate::scene::Shape;
use std::fmt;
use std::time::Instant;

/// Closest-hit and any-hit ray queries over a fixed set of shapes.
///
/// The contract, identical for every backend:
/// * **Range**: a hit counts only if `ray.tmin < t <= ray.tmax` (half-open:
///   a surface exactly at `tmin` is not hit, one exactly at `tmax` is).
///   `t` is in units of `ray.dir`, which need not be normalised.
/// * **Two-sided**: triangles are hit from both sides; spheres are hit from
///   outside (near root) and from inside (far root).
/// * **Watertight**: a ray through a shared edge or vertex of a closed mesh
///   hits at least one of the triangles sharing it.
/// * **Degenerate primitives** (zero-area triangles, zero-radius spheres) are
///   never hit, and a ray lying in a triangle's plane misses it.
/// * **Invalid rays** (see `Ray::is_valid`: NaN/Inf components, zero
///   direction, bad range) hit nothing and are never occluded.
/// * **Ties**: if two primitives are hit at exactly the same `t`, the native
///   and brute backends return the lower `(geom_id, prim_id)`; Embree may
///   return either (the cross-check counts such ties).
/// * **Thread safety**: queries take `&self` and may run from any number of
///   threads at once.
pub trait Traversal: Send + Sync {
    /// Short backend name as accepted by `--backend`.
    fn name(&self) -> &'static str;

    /// Human-readable details for the summary line (builder, version, ISA).
    fn describe(&self) -> String {
        self.name().to_string()
    }

    /// Bytes of acceleration structure and primitive data owned by the backend.
    fn memory_bytes(&self) -> usize;

    /// Whether every hit's `(t, u, v)` is exactly what
    /// `geometry::intersect_triangle` gives for the ray (spheres aside), so
    /// describing a hit need not recompute them (see `Interaction::new`).
    fn exact_barycentrics(&self) -> bool {
        false
    }

    /// The tree's SAH cost as (node part, leaf part), counted as Embree's
    /// `verbose=2` statistics count it; `None` where the backend cannot say.
    fn sah_cost(&self) -> Option<(f64, f64)> {
        None
    }

    /// The traversal choices the build fixed (instruction set, the way
    /// batches go, the any-hit child order), in words; `None` where the
    /// backend makes none of its own.
    fn choices(&self) -> Option<String> {
        None
    }

    /// The closest hit in range, or `None`.
    fn intersect(&self, ray: &Ray) -> Option<Hit>;

    /// Whether anything is hit in range. May stop at the first hit found.
    fn occluded(&self, ray: &Ray) -> bool;

    /// `hits[i] = intersect(&rays[i])`. Backends override this where batching pays.
    fn intersect_batch(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), hits.len());
        for (r, h) in rays.iter().zip(hits.iter_mut()) {
            *h = self.intersect(r);
        }
    }

    /// `out[i] = occluded(&rays[i])`.
    fn occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len());
        for (r, o) in rays.iter().zip(out.iter_mut()) {
            *o = self.occluded(r);
        }
    }

    /// `intersect_batch` for rays known to be coherent (camera rays of a
    /// tile, shadow rays towards one light), which packet tracing can exploit.
    fn intersect_coherent(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        self.intersect_batch(rays, hits)
    }

    /// `occluded_batch` for coherent rays.
    fn occluded_coherent(&self, rays: &[Ray], out: &mut [bool]) {
        self.occluded_batch(rays, out)
    }
}

/// The backends selectable with `--backend`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum BackendKind {
    /// Our binned-SAH BVH.
    Native,
    /// The newest Embree this build can load (Embree 4 where both are):
    /// MEDIUM build quality, Embree's default, and ROBUST (watertight).
    Embree,
    /// The newest Embree with HIGH build quality: its spatial-split builder
    /// (slower builds, fewer box tests per ray), which needs the ROBUST flag
    /// off, so not watertight: the benchmark's build-quality reference.
    #[value(name = "embree-high")]
    EmbreeHigh,
    /// Embree 3 (Debian's 3.13.5), MEDIUM, ROBUST.
    #[value(name = "embree3")]
    Embree3,
    /// Embree 3, HIGH quality (not watertight; for the benchmark).
    #[value(name = "embree3-high")]
    Embree3High,
    /// Embree 4 (4.4.0 from PyPI's embreex4 wheel), MEDIUM, ROBUST.
    #[value(name = "embree4")]
    Embree4,
    /// Embree 4, HIGH quality (not watertight; for the benchmark).
    #[value(name = "embree4-high")]
    Embree4High,
    /// No acceleration: every ray tests every primitive (the test oracle).
    Brute,
}

impl BackendKind {
    /// For the Embree backends: which major, resolving `embree` and
    /// `embree-high` to the newest that loads here, and which quality.
    pub fn embree(self) -> Option<Result<(embree::Major, embree::Quality)>> {
        use embree::{Major, Quality};
        let newest = || {
            embree::newest().ok_or_else(|| {
                crate::Error::new(format!(
                    "no Embree can be used here: embree4: {}; embree3: {}",
                    embree::unavailable_reason(Major::V4),
                    embree::unavailable_reason(Major::V3)
                ))
            })
        };
        Some(match self {
            BackendKind::Embree => newest().map(|m| (m, Quality::Medium)),
            BackendKind::EmbreeHigh => newest().map(|m| (m, Quality::High)),
            BackendKind::Embree3 => Ok((Major::V3, Quality::Medium)),
            BackendKind::Embree3High => Ok((Major::V3, Quality::High)),
            BackendKind::Embree4 => Ok((Major::V4, Quality::Medium)),
            BackendKind::Embree4High => Ok((Major::V4, Quality::High)),
            BackendKind::Native | BackendKind::Brute => return None,
        })
    }
}

impl fmt::Display for BackendKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            BackendKind::Native => "native",
            BackendKind::Embree => "embree",
            BackendKind::EmbreeHigh => "embree-high",
            BackendKind::Embree3 => "embree3",
            BackendKind::Embree3High => "embree3-high",
            BackendKind::Embree4 => "embree4",
            BackendKind::Embree4High => "embree4-high",
            BackendKind::Brute => "brute",
        })
    }
}

/// A built backend and the wall time its build took.
pub struct Built {
    pub accel: Box<dyn Traversal>,
    pub build_seconds: f64,
}

/// Build the chosen backend over `shapes` with the default choices.
/// `threads` bounds any thread pool the backend owns (Embree's TBB); 0
/// means all cores.
pub fn build(kind: BackendKind, shapes: &[Shape], threads: usize) -> Result<Built> {
    build_with(kind, shapes, &BuildOptions { threads, ..Default::default() })
}

/// Build the chosen backend over `shapes` with the given choices (the
/// command line passes the `PATHTRACER_NATIVE_*` switches this way).
pub fn build_with(kind: BackendKind, shapes: &[Shape], options: &BuildOptions) -> Result<Built> {
    let start = Instant::now();
    let threads = options.threads;
    let accel: Box<dyn Traversal> = match kind {
        BackendKind::Native => Box::new(wide::WideBvh::<{ wide::NATIVE_WIDTH }>::build_with(shapes, &options.native)),
        BackendKind::Brute => Box::new(brute::BruteForce::new(shapes)),
        other => {
            let (major, quality) = other.embree().expect("an Embree backend")?;
            Box::new(embree::EmbreeBackend::build_configured(major, shapes, threads, quality, &options.embree_config)?)
        }
    };
    Ok(Built { accel, build_seconds: start.elapsed().as_secs_f64() })
}
