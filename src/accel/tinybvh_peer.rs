//! tinybvh (Jacco Bikker's single-header C++ library, 1.6.8 as vendored by
//! the `tinybvh-rs` crate), timed by `pathtracer bench` as a peer on the
//! same rays as our backends; built only with `--features peers`. Not a
//! renderer backend: its hits carry its own barycentrics and it has no
//! spheres.
//!
//! What the crate exposes: closest-hit traversal of the binary `BVH` (built
//! by binned SAH, `BVH::new`, or with spatial splits, `BVH::new_hq`) and of
//! the 8-wide `BVH8_CPU` — the latter only when the Rust side is compiled
//! with AVX2 enabled (`-C target-feature=+avx2`, which would also change our
//! own code's instruction selection, so the bench does not), no any-hit
//! call and no packets. So this peer traces with the binary BVH's
//! `Intersect`, shadow rays as closest hits (a hit before `tmax` occludes),
//! and the bench table says so. Its rays have no `tmin` (the triangle test
//! accepts t > 0), so a ray of ours starts at `origin + tmin·dir` with
//! `tmax − tmin` left (without that, shadow rays leaving a surface found it
//! again: 906 of arch:100k's 1370 answered differently from native);
//! `tests/peers.rs` checks the answers against native.
//!
//! ABI: the crate's `Ray` (64 bytes) does not match the vendored header's
//! (`tiny_bvh.h` 1.6.8 with `INST_IDX_BITS 32`: 128 bytes, 64-byte aligned,
//! the hit record with an instance index, a pointer and 56 user bytes),
//! so its `Ray::new`, which returns the C++ ray by value, overwrites 64
//! bytes past the Rust one (a segmentation fault here). This peer never
//! calls it: it lays each ray out in a 128-byte, 64-aligned buffer whose
//! first 64 bytes are the crate's `Ray` (origin, direction, reciprocal,
//! then `t, u, v, prim` at the offsets both agree on) and hands that to
//! `Intersect`, which may then use every byte of the C++ layout.

use super::{Hit, Traversal};
use crate::error::Result;
use crate::ray::Ray;
use crate::scene::Shape;
use tinybvh_rs::{bvh, Intersector, Ray as TRay};

/// Which of tinybvh's builds to traverse.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Build {
    /// Binned SAH (`BVH::Build`).
    Sah,
    /// Spatial splits (`BVH::BuildHQ`, SBVH).
    Hq,
}

/// The C++ `tinybvh::Ray`'s size and alignment around the crate's `Ray`
/// (see the top of the file).
#[repr(C, align(64))]
struct CppRay {
    ray: TRay,
    _tail: [u8; 64],
}

// The layout the comment at the top relies on.
const _: () = assert!(std::mem::size_of::<CppRay>() == 128 && std::mem::align_of::<CppRay>() == 64 && std::mem::size_of::<TRay>() == 64);

pub struct TinyBvhPeer {
    // Declared before `positions`, so dropped first: it points into them.
    bvh: bvh::BVH<'static>,
    positions: Box<[[f32; 4]]>,
    /// (geometry, primitive) of each triangle, in `positions` order.
    ids: Vec<(u32, u32)>,
    build: Build,
}

// SAFETY: after the build nothing mutates the BVH; tinybvh's `Intersect` is
// a const method that reads the nodes and writes only the ray it is given,
// so concurrent calls from several threads are safe.
unsafe impl Send for TinyBvhPeer {}
unsafe impl Sync for TinyBvhPeer {}

impl TinyBvhPeer {
    pub fn build(shapes: &[Shape], build: Build) -> Result<Self> {
        let mut positions = Vec::new();
        let mut ids = Vec::new();
        for (g, s) in shapes.iter().enumerate() {
            match s {
                Shape::Mesh(m) => {
                    for (i, t) in m.triangles.iter().enumerate() {
                        for k in t {
                            let p = m.positions[*k as usize];
                            positions.push([p.x, p.y, p.z, 0.0]);
                        }
                        ids.push((g as u32, i as u32));
                    }
                }
                Shape::Sphere { .. } => crate::bail!("tinybvh peer: spheres are not supported (triangle meshes only)"),
            }
        }
        if ids.is_empty() {
            crate::bail!("tinybvh peer: no triangles");
        }
        let positions: Box<[[f32; 4]]> = positions.into_boxed_slice();
        // SAFETY: the BVH keeps a pointer to the positions, which live in a
        // heap allocation owned by the same struct, never moved or changed,
        // and dropped after the BVH (field order).
        let slice: &'static [[f32; 4]] = unsafe { std::slice::from_raw_parts(positions.as_ptr(), positions.len()) };
        let bvh = match build {
            Build::Sah => bvh::BVH::new(slice.into()),
            Build::Hq => bvh::BVH::new_hq(slice.into()),
        }
        .map_err(|e| crate::Error::new(format!("tinybvh peer: {e:?}")))?;
        Ok(TinyBvhPeer { bvh, positions, ids, build })
    }

    #[inline]
    fn trace(&self, r: &Ray) -> Option<tinybvh_rs::Intersection> {
        if !r.is_valid() {
            return None;
        }
        // (tmin, tmax] as (0, tmax - tmin] from a moved origin.
        let origin = r.origin + r.tmin * r.dir;
        let tmax = (r.tmax - r.tmin).min(tinybvh_rs::INFINITE);
        // tinybvh's safe reciprocal (`tinybvh_safercp`).
        let rcp = |x: f32| if x.abs() > 1e-12 { 1.0 / x } else if x >= 0.0 { tinybvh_rs::INFINITE } else { -tinybvh_rs::INFINITE };
        let mut buf = CppRay {
            ray: TRay {
                origin: origin.to_array(),
                padding_0: 0xFFFF, // the ray's instance mask: all
                dir: r.dir.to_array(),
                padding_1: 0, // instance index
                r_d: [rcp(r.dir.x), rcp(r.dir.y), rcp(r.dir.z)],
                padding_2: 0, // the hit's instance index
                hit: tinybvh_rs::Intersection { t: tmax, u: 0.0, v: 0.0, prim: 0 },
            },
            _tail: [0; 64],
        };
        self.bvh.intersect(&mut buf.ray);
        let hit = buf.ray.hit;
        (hit.t < tmax && hit.t > 0.0).then_some(tinybvh_rs::Intersection { t: hit.t + r.tmin, ..hit })
    }
}

impl Traversal for TinyBvhPeer {
    fn name(&self) -> &'static str {
        match self.build {
            Build::Sah => "tinybvh",
            Build::Hq => "tinybvh-hq",
        }
    }

    fn describe(&self) -> String {
        format!("tinybvh 1.6.8 (tinybvh-rs 0.1.0-beta.3, binary BVH, {:?} build, shadow rays as closest hits)", self.build)
    }

    fn memory_bytes(&self) -> usize {
        self.bvh.nodes().len() * std::mem::size_of::<bvh::Node>() + self.bvh.indices().len() * 4 + self.positions.len() * 16
    }

    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        let h = self.trace(ray)?;
        let (geom_id, prim_id) = self.ids[h.prim as usize];
        Some(Hit { t: h.t, u: h.u, v: h.v, geom_id, prim_id })
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.trace(ray).is_some()
    }
}
