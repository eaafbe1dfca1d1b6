//! The Embree backend, through the C shim in `native/` (bindings generated
//! by bindgen from `native/shim.h` at build time).
//!
//! Same contract as every backend (see `Traversal`): the shim turns Embree's
//! closed `[tnear, tfar]` into our `(tmin, tmax]`, spheres are user geometry
//! calling our own sphere test (so `t` is bit-identical to native), geometry
//! ids are our shape indices (attached by id), invalid rays are filtered here
//! because Embree's answer to them is undefined. The scene is built with the
//! ROBUST flag (watertight) and MEDIUM quality, Embree's default (binned SAH
//! for static scenes). `embree-high` builds with HIGH quality and *without*
//! ROBUST, because ROBUST turns Embree's spatial splits off (verbose=2 then
//! reports the plain SAH builder): it is the benchmark's reference for
//! spatial-split (SBVH) build quality, not watertight, not for renders.

use super::{Hit, Traversal};
use crate::error::Result;
use crate::ray::Ray;
use crate::scene::Shape;

/// Embree's `RTCBuildQuality`, as the shim numbers it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quality {
    Low = 0,
    Medium = 1,
    High = 2,
}

/// Whether this build has the Embree backend.
pub fn available() -> bool {
    cfg!(has_embree)
}

/// Why the Embree backend is missing (or "Embree N" when present).
pub fn unavailable_reason() -> &'static str {
    env!("PATHTRACER_EMBREE_STATUS")
}

/// The Embree version this build's backend runs ("Embree 3.13.5"), or why
/// there is none.
pub fn version_string() -> String {
    #[cfg(has_embree)]
    {
        // SAFETY: a constant query of the shim.
        let v = unsafe { ffi::pt_embree_version() };
        format!("Embree {}.{}.{}", v / 10000, (v / 100) % 100, v % 100)
    }
    #[cfg(not(has_embree))]
    {
        unavailable_reason().to_string()
    }
}

#[cfg(not(has_embree))]
pub use absent::EmbreeBackend;
#[cfg(has_embree)]
pub use present::EmbreeBackend;

#[cfg(not(has_embree))]
mod absent {
    use super::*;

    /// Stand-in when the build found no Embree: building it fails with the reason.
    pub struct EmbreeBackend(());

    impl EmbreeBackend {
        pub fn build(shapes: &[Shape], threads: usize) -> Result<Self> {
            Self::build_with_quality(shapes, threads, super::Quality::Medium)
        }

        pub fn build_with_quality(_shapes: &[Shape], _threads: usize, _quality: super::Quality) -> Result<Self> {
            crate::bail!("the embree backend is not available in this build: {}", unavailable_reason())
        }
    }

    impl Traversal for EmbreeBackend {
        fn name(&self) -> &'static str {
            "embree"
        }
        fn memory_bytes(&self) -> usize {
            0
        }
        fn intersect(&self, _ray: &Ray) -> Option<Hit> {
            None
        }
        fn occluded(&self, _ray: &Ray) -> bool {
            false
        }
    }
}

#[cfg(has_embree)]
#[allow(non_camel_case_types, non_upper_case_globals, dead_code)]
mod ffi {
    include!(concat!(env!("OUT_DIR"), "/embree_shim.rs"));
}

#[cfg(has_embree)]
mod present {
    use super::ffi;
    use super::*;
    use crate::geometry::intersect_sphere;
    use glam::Vec3;
    use std::ffi::{CStr, CString};

    /// How batches are handed to Embree (measured by `pathtracer bench`).
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum BatchMode {
        Loop,
        Stream,
        Packet8,
    }

    pub struct EmbreeBackend {
        device: *mut ffi::pt_device,
        scene: *mut ffi::pt_scene,
        version: i32,
        threads: usize,
        quality: super::Quality,
        /// Batch mode for coherent (camera, shadow) and incoherent batches.
        coherent_mode: BatchMode,
        incoherent_mode: BatchMode,
    }

    // Embree's traversal calls are thread-safe on a committed scene, and the
    // handles are never mutated after `build`.
    unsafe impl Send for EmbreeBackend {}
    unsafe impl Sync for EmbreeBackend {}

    impl Drop for EmbreeBackend {
        fn drop(&mut self) {
            unsafe {
                ffi::pt_scene_release(self.scene);
                ffi::pt_device_release(self.device);
            }
        }
    }

    /// Our sphere test, called back from Embree's user geometry.
    unsafe extern "C" fn sphere_test(cr: *const f32, org: *const f32, dir: *const f32, tnear: f32, tfar: f32) -> f32 {
        let cr = std::slice::from_raw_parts(cr, 4);
        let o = std::slice::from_raw_parts(org, 3);
        let d = std::slice::from_raw_parts(dir, 3);
        intersect_sphere(Vec3::new(o[0], o[1], o[2]), Vec3::new(d[0], d[1], d[2]), Vec3::new(cr[0], cr[1], cr[2]), cr[3], tnear, tfar)
            .unwrap_or(f32::NAN)
    }

    fn take_error(device: *mut ffi::pt_device, what: &str) -> crate::error::Error {
        let mut buf = [0 as std::os::raw::c_char; 512];
        let code = unsafe { ffi::pt_device_take_error(device, buf.as_mut_ptr(), buf.len()) };
        let msg = unsafe { CStr::from_ptr(buf.as_ptr()) }.to_string_lossy().into_owned();
        crate::error::Error::new(format!("embree: {what} failed (error {code}: {msg})"))
    }

    #[inline]
    fn to_ffi(r: &Ray) -> ffi::pt_ray {
        ffi::pt_ray { org: r.origin.to_array(), tnear: r.tmin, dir: r.dir.to_array(), tfar: r.tmax }
    }

    /// A ray Embree will never report a hit for: used in place of invalid rays
    /// inside batches.
    const NULL_RAY: ffi::pt_ray = ffi::pt_ray { org: [0.0; 3], tnear: 1.0, dir: [0.0, 0.0, 1.0], tfar: 0.0 };

    impl EmbreeBackend {
        pub fn build(shapes: &[Shape], threads: usize) -> Result<Self> {
            Self::build_with_quality(shapes, threads, super::Quality::Medium)
        }

        pub fn build_with_quality(shapes: &[Shape], threads: usize, quality: super::Quality) -> Result<Self> {
            let mut config = if threads > 0 { format!("threads={threads}") } else { String::new() };
            // Extra device settings for measurements, e.g. "verbose=2" prints
            // Embree's BVH statistics (its SAH cost) after each build.
            if let Ok(extra) = std::env::var("PATHTRACER_EMBREE_CONFIG") {
                if !config.is_empty() && !extra.is_empty() {
                    config.push(',');
                }
                config.push_str(&extra);
            }
            let c = CString::new(config).unwrap();
            let device = unsafe { ffi::pt_device_new(c.as_ptr()) };
            if device.is_null() {
                let msg = unsafe { CStr::from_ptr(ffi::pt_device_new_error()) }.to_string_lossy().into_owned();
                crate::bail!("embree: cannot create a device: {msg}");
            }
            let robust = quality != super::Quality::High;
            let scene = unsafe { ffi::pt_scene_new(device, quality as i32, robust as i32) };
            let mut me = EmbreeBackend {
                device,
                scene,
                version: unsafe { ffi::pt_embree_version() },
                threads,
                quality,
                // Measured with `pathtracer bench` (Embree 3.13.5, 1 thread):
                // the stream call beat 8-wide packets for camera and shadow rays
                // (cow camera 46.9 vs 27.2 Mrays/s) and matched them for random
                // rays. Embree 4 has no streams: packets for coherent rays there.
                coherent_mode: if unsafe { ffi::pt_device_has_streams(device) } != 0 { BatchMode::Stream } else { BatchMode::Packet8 },
                incoherent_mode: if unsafe { ffi::pt_device_has_streams(device) } != 0 { BatchMode::Stream } else { BatchMode::Loop },
            };
            if scene.is_null() {
                me.scene = std::ptr::null_mut();
                return Err(take_error(device, "creating a scene"));
            }
            for (id, shape) in shapes.iter().enumerate() {
                let rc = match shape {
                    Shape::Mesh(m) => {
                        let xyz: Vec<f32> = m.positions.iter().flat_map(|p| p.to_array()).collect();
                        let idx: Vec<u32> = m.triangles.iter().flatten().copied().collect();
                        unsafe { ffi::pt_scene_add_mesh(scene, id as u32, xyz.as_ptr(), m.positions.len(), idx.as_ptr(), m.triangles.len()) }
                    }
                    Shape::Sphere { center, radius } => {
                        let cr = [center.x, center.y, center.z, *radius];
                        unsafe { ffi::pt_scene_add_sphere(scene, id as u32, cr.as_ptr(), Some(sphere_test)) }
                    }
                };
                if rc != 0 {
                    return Err(take_error(device, &format!("adding shape {id}")));
                }
            }
            if unsafe { ffi::pt_scene_commit(scene) } != 0 {
                return Err(take_error(device, "building the BVH"));
            }
            Ok(me)
        }

        /// Choose how batches are traced (for measurements).
        pub fn set_batch_modes(&mut self, coherent: BatchMode, incoherent: BatchMode) {
            self.coherent_mode = coherent;
            self.incoherent_mode = incoherent;
        }

        fn mode_id(m: BatchMode) -> i32 {
            (match m {
                BatchMode::Loop => ffi::PT_BATCH_LOOP,
                BatchMode::Stream => ffi::PT_BATCH_STREAM,
                BatchMode::Packet8 => ffi::PT_BATCH_PACKET8,
            }) as i32
        }

        fn batch_intersect(&self, rays: &[Ray], hits: &mut [Option<Hit>], coherent: bool) {
            assert_eq!(rays.len(), hits.len());
            let fr: Vec<ffi::pt_ray> = rays.iter().map(|r| if r.is_valid() { to_ffi(r) } else { NULL_RAY }).collect();
            let mut fh = vec![ffi::pt_hit { t: 0.0, u: 0.0, v: 0.0, geom_id: 0, prim_id: 0 }; rays.len()];
            let mode = if coherent { self.coherent_mode } else { self.incoherent_mode };
            unsafe { ffi::pt_intersect_batch(self.scene, fr.as_ptr(), fh.as_mut_ptr(), fr.len(), Self::mode_id(mode), coherent as i32) };
            for ((h, f), r) in hits.iter_mut().zip(&fh).zip(rays) {
                *h = if f.geom_id == ffi::PT_INVALID_ID || !r.is_valid() { None } else { Some(from_ffi(f)) };
            }
        }

        fn batch_occluded(&self, rays: &[Ray], out: &mut [bool], coherent: bool) {
            assert_eq!(rays.len(), out.len());
            let fr: Vec<ffi::pt_ray> = rays.iter().map(|r| if r.is_valid() { to_ffi(r) } else { NULL_RAY }).collect();
            let mut o = vec![0u8; rays.len()];
            let mode = if coherent { self.coherent_mode } else { self.incoherent_mode };
            unsafe { ffi::pt_occluded_batch(self.scene, fr.as_ptr(), o.as_mut_ptr(), fr.len(), Self::mode_id(mode), coherent as i32) };
            for ((x, &b), r) in out.iter_mut().zip(&o).zip(rays) {
                *x = b != 0 && r.is_valid();
            }
        }
    }

    #[inline]
    fn from_ffi(h: &ffi::pt_hit) -> Hit {
        Hit { t: h.t, u: h.u, v: h.v, geom_id: h.geom_id, prim_id: h.prim_id }
    }

    impl Traversal for EmbreeBackend {
        fn name(&self) -> &'static str {
            if self.quality == super::Quality::High { "embree-high" } else { "embree" }
        }

        fn describe(&self) -> String {
            let v = self.version;
            format!(
                "embree {}.{}.{} ({}, {} threads, CPU ISA {}, coherent batches {:?}, incoherent {:?})",
                v / 10000,
                (v / 100) % 100,
                v % 100,
                match self.quality {
                    super::Quality::High => "HIGH: spatial splits, not ROBUST",
                    super::Quality::Medium => "MEDIUM, ROBUST",
                    super::Quality::Low => "LOW, ROBUST",
                },
                if self.threads == 0 { "all".to_string() } else { self.threads.to_string() },
                cpu_isa(),
                self.coherent_mode,
                self.incoherent_mode
            )
        }

        fn memory_bytes(&self) -> usize {
            unsafe { ffi::pt_device_memory(self.device) }.max(0) as usize
        }

        fn intersect(&self, ray: &Ray) -> Option<Hit> {
            if !ray.is_valid() {
                return None;
            }
            let r = to_ffi(ray);
            let mut h = ffi::pt_hit { t: 0.0, u: 0.0, v: 0.0, geom_id: 0, prim_id: 0 };
            unsafe { ffi::pt_intersect1(self.scene, &r, &mut h) };
            (h.geom_id != ffi::PT_INVALID_ID).then(|| from_ffi(&h))
        }

        fn occluded(&self, ray: &Ray) -> bool {
            ray.is_valid() && unsafe { ffi::pt_occluded1(self.scene, &to_ffi(ray)) } != 0
        }

        fn intersect_batch(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
            self.batch_intersect(rays, hits, false)
        }

        fn occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
            self.batch_occluded(rays, out, false)
        }

        fn intersect_coherent(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
            self.batch_intersect(rays, hits, true)
        }

        fn occluded_coherent(&self, rays: &[Ray], out: &mut [bool]) {
            self.batch_occluded(rays, out, true)
        }
    }

    /// The widest vector ISA this CPU offers; Embree dispatches to the best
    /// of its compiled targets (Debian's: SSE2 up to AVX-512) at run time.
    fn cpu_isa() -> &'static str {
        #[cfg(target_arch = "x86_64")]
        {
            if is_x86_feature_detected!("avx512f") {
                return "AVX-512";
            }
            if is_x86_feature_detected!("avx2") {
                return "AVX2";
            }
            if is_x86_feature_detected!("avx") {
                return "AVX";
            }
            if is_x86_feature_detected!("sse4.2") {
                return "SSE4.2";
            }
            "SSE2"
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            "non-x86"
        }
    }
}

#[cfg(has_embree)]
pub use present::BatchMode;
