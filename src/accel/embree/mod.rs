//! The Embree backends, Embree 3 and Embree 4, through the C shim in
//! `native/` (compiled once per major; bindings by bindgen from
//! `native/shim.h`). Each major's library is loaded at run time with
//! `dlopen(RTLD_LOCAL)` and called through its own table of function
//! pointers (`ffi::pt_api`), so both can be used in one process although
//! they export the same names, and a machine without one still runs.
//!
//! Same contract as every backend (see `Traversal`): the shim turns Embree's
//! closed `[tnear, tfar]` into our `(tmin, tmax]`, spheres are user geometry
//! calling our own sphere test (so `t` is bit-identical to native), geometry
//! ids are our shape indices (attached by id), invalid rays are filtered here
//! because Embree's answer to them is undefined. Scenes are built with the
//! ROBUST flag (watertight) and MEDIUM quality, Embree's default (binned SAH
//! for static scenes). The `-high` backends build with HIGH quality and
//! *without* ROBUST, because ROBUST turns Embree's spatial splits off
//! (verbose=2 then reports the plain SAH builder): they are the benchmark's
//! reference for spatial-split (SBVH) build quality, not watertight, not for
//! renders.
//!
//! What differs between the majors is in one place each: in C, the
//! `RTC_VERSION_MAJOR` branches of `native/shim.c` (argument structures,
//! streams, ABI padding); here, [`Major::default_batch_modes`] (which call
//! traces which batches, by measurement).

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

/// An Embree major version.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Major {
    V3 = 3,
    V4 = 4,
}

/// How a batch of rays is handed to Embree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BatchMode {
    /// A loop of single-ray calls (`rtcIntersect1`).
    Loop,
    /// Embree 3's ray streams (`rtcIntersect1M`); Embree 4 has none.
    Stream,
    /// Packets of 4, 8 or 16 rays (`rtcIntersect4/8/16`).
    Packet4,
    Packet8,
    Packet16,
}

impl BatchMode {
    /// Every mode of either major (Embree 3 has them all).
    pub const EVERY: &'static [BatchMode] = &[BatchMode::Loop, BatchMode::Stream, BatchMode::Packet4, BatchMode::Packet8, BatchMode::Packet16];

    /// Every mode `major` has.
    pub fn all(major: Major) -> &'static [BatchMode] {
        match major {
            Major::V3 => BatchMode::EVERY,
            Major::V4 => &[BatchMode::Loop, BatchMode::Packet4, BatchMode::Packet8, BatchMode::Packet16],
        }
    }

    /// The mode's name in the bench's tables.
    pub fn name(self) -> &'static str {
        match self {
            BatchMode::Loop => "loop",
            BatchMode::Stream => "stream",
            BatchMode::Packet4 => "packet4",
            BatchMode::Packet8 => "packet8",
            BatchMode::Packet16 => "packet16",
        }
    }
}

impl Major {
    pub const ALL: [Major; 2] = [Major::V3, Major::V4];

    pub fn number(self) -> u32 {
        self as u32
    }

    /// The batch calls the backend uses for coherent (camera, shadow) and
    /// incoherent batches on this CPU, by measurement (`pathtracer bench`'s
    /// table of Embree's batch calls, 1 thread, Mrays/s):
    /// * Embree 3.13.5: streams beat 8-ray packets for camera and shadow rays
    ///   (cow camera 46.9 against 27.2 Mrays/s) and matched them for random
    ///   rays, so streams for both.
    /// * Embree 4.4.0 (no streams) on a CPU with AVX-512 (a 2-vCPU Intel
    ///   Xeon, 2^18 rays, best of 3): 16-ray packets with the coherent flag
    ///   are its fastest camera call (cow 32.5, CBbunny 34.9, arch:500k 37.2
    ///   against a loop's 14.0, 14.2, 19.3) and fastest or level for shadow
    ///   rays; for random rays 8-ray packets with the incoherent flag beat
    ///   the loop of single rays (cow 8.61 / 7.78, CBbunny 9.56 / 7.93,
    ///   arch:500k 15.99 / 12.22, grass:300k 1.45 / 1.38).
    /// * Embree 4.4.0 without AVX-512 (a 2-vCPU AMD EPYC, Zen 3, AVX2; 2^18
    ///   rays, best of 3): Embree runs 16-ray packets as two 8-wide halves,
    ///   and they are its slowest coherent call; 8-ray packets with the
    ///   coherent flag are its fastest on every scene, camera / shadow rays,
    ///   packets of 8 against 16: cow 29.95 / 11.31 against 13.45 / 5.58,
    ///   CBbunny 30.94 / 20.09 against 14.07 / 11.20, maxplanck 15.46 / 4.91
    ///   against 9.27 / 3.88, beetle 32.71 / 8.22 against 15.59 / 4.79,
    ///   arch:2M 41.25 / 28.24 against 15.62 / 7.87.
    ///
    /// The bench times every call each run (`docs/benchmarks/bench.md`,
    /// "Embree batch calls").
    pub fn default_batch_modes(self) -> (BatchMode, BatchMode) {
        match self {
            Major::V3 => (BatchMode::Stream, BatchMode::Stream),
            Major::V4 if sixteen_lanes() => (BatchMode::Packet16, BatchMode::Packet8),
            Major::V4 => (BatchMode::Packet8, BatchMode::Packet8),
        }
    }
}

/// Whether this CPU has 16-lane float vectors (AVX-512), where Embree's
/// 16-ray packets run one lane a ray.
fn sixteen_lanes() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Why `major` is missing from this build, when it is (the build script's verdict).
fn build_status(major: Major) -> &'static str {
    match major {
        Major::V3 => env!("PATHTRACER_EMBREE3_STATUS"),
        Major::V4 => env!("PATHTRACER_EMBREE4_STATUS"),
    }
}

/// Whether this build has the shim for `major` (its headers were found).
pub fn compiled(major: Major) -> bool {
    match major {
        Major::V3 => cfg!(has_embree3),
        Major::V4 => cfg!(has_embree4),
    }
}

/// Whether `major` can be used here: compiled in and its library loads.
pub fn available(major: Major) -> bool {
    library(major).is_ok()
}

/// The newest major that can be used here.
pub fn newest() -> Option<Major> {
    Major::ALL.into_iter().rev().find(|&m| available(m))
}

/// Why `major` cannot be used here, with what to install.
pub fn unavailable_reason(major: Major) -> String {
    match library(major) {
        Ok(_) => String::new(),
        Err(e) => e,
    }
}

/// "Embree 4.4.0" (the version the library reports), or why there is none.
pub fn version_string(major: Major) -> String {
    match library(major) {
        Ok(lib) => lib.version_string(),
        Err(e) => format!("unavailable: {e}"),
    }
}

/// A loaded major: the shim's table and the library's version.
pub struct Library {
    #[cfg(has_embree)]
    api: &'static ffi::pt_api,
    pub major: Major,
    /// The library's own version (`RTC_DEVICE_PROPERTY_VERSION`), e.g. 40400.
    pub version: i32,
    /// The headers the shim was compiled against, e.g. 40200.
    pub header_version: i32,
}

// SAFETY: the table is immutable static data of the shim, and its functions
// are safe to call from any thread (the shim's loading is once-guarded).
unsafe impl Sync for Library {}
unsafe impl Send for Library {}

fn dotted(v: i32) -> String {
    format!("{}.{}.{}", v / 10000, (v / 100) % 100, v % 100)
}

impl Library {
    pub fn version_string(&self) -> String {
        format!("Embree {}", dotted(self.version))
    }
}

/// `major`'s library, loaded once: or why it cannot be used.
pub fn library(major: Major) -> std::result::Result<&'static Library, String> {
    use std::sync::OnceLock;
    static LIBS: [OnceLock<std::result::Result<Library, String>>; 2] = [OnceLock::new(), OnceLock::new()];
    LIBS[major as usize - 3].get_or_init(|| load(major)).as_ref().map_err(|e| e.clone())
}

#[cfg(not(has_embree))]
fn load(major: Major) -> std::result::Result<Library, String> {
    Err(format!("the embree{} backend is not in this build: {}", major.number(), build_status(major)))
}

#[cfg(has_embree)]
fn load(major: Major) -> std::result::Result<Library, String> {
    use std::ffi::CStr;
    // SAFETY: the getters return a pointer to a static table (or are absent
    // from the build, which the cfg checks).
    let api: Option<&'static ffi::pt_api> = match major {
        #[cfg(has_embree3)]
        Major::V3 => unsafe { ffi::pt_embree3_api().as_ref() },
        #[cfg(has_embree4)]
        Major::V4 => unsafe { ffi::pt_embree4_api().as_ref() },
        #[allow(unreachable_patterns)]
        _ => None,
    };
    let install = match major {
        Major::V3 => "install Embree 3 (Debian/Ubuntu: apt-get install libembree3-4; scripts/install-deps.sh does it)",
        Major::V4 => "run scripts/install-deps.sh (it puts Embree 4 into third_party/embree4) and rebuild",
    };
    let Some(api) = api else {
        return Err(format!("the embree{} backend is not in this build: {}", major.number(), build_status(major)));
    };
    // SAFETY: load() returns NULL or a static C string.
    let why = unsafe { (api.load.expect("shim table"))() };
    if !why.is_null() {
        let why = unsafe { CStr::from_ptr(why) }.to_string_lossy().into_owned();
        return Err(format!("{why}; {install}"));
    }
    let version = unsafe { (api.library_version.expect("shim table"))() };
    Ok(Library { api, major, version, header_version: api.header_version })
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
        pub fn build(major: Major, shapes: &[Shape], threads: usize, quality: Quality) -> Result<Self> {
            Self::build_configured(major, shapes, threads, quality, "")
        }

        pub fn build_configured(major: Major, _shapes: &[Shape], _threads: usize, _quality: Quality, _extra: &str) -> Result<Self> {
            let lib = library(major).map_err(crate::Error::new)?;
            let _ = lib;
            unreachable!("no Embree library loads in a build without the shim")
        }

        pub fn set_batch_modes(&mut self, _coherent: BatchMode, _incoherent: BatchMode) {}
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
pub(crate) mod ffi {
    include!(concat!(env!("OUT_DIR"), "/embree_shim.rs"));
}

/// The ABI canary: how many bytes past its hit structure for `width` rays
/// (1, 4, 8 or 16) `major`'s library writes, and how many the shim pads
/// every such buffer with (see `native/shim.c`).
pub fn abi_probe(major: Major, width: i32) -> std::result::Result<(i32, i32), String> {
    let lib = library(major)?;
    #[cfg(has_embree)]
    {
        // SAFETY: a self-contained call of the loaded shim.
        let written = unsafe { (lib.api.abi_probe.expect("shim table"))(width) };
        if written < 0 {
            return Err(format!("the {} ABI probe failed for width {width}", lib.version_string()));
        }
        Ok((written, lib.api.abi_padding))
    }
    #[cfg(not(has_embree))]
    {
        let _ = (lib, width);
        unreachable!()
    }
}

#[cfg(has_embree)]
mod present {
    use super::ffi;
    use super::*;
    use crate::geometry::intersect_sphere;
    use glam::Vec3;
    use std::ffi::{CStr, CString};

    pub struct EmbreeBackend {
        api: &'static ffi::pt_api,
        lib: &'static Library,
        device: *mut ffi::pt_device,
        scene: *mut ffi::pt_scene,
        threads: usize,
        quality: Quality,
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
                if !self.scene.is_null() {
                    (self.api.scene_release.unwrap())(self.scene);
                }
                (self.api.device_release.unwrap())(self.device);
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

    fn take_error(api: &ffi::pt_api, device: *mut ffi::pt_device, major: Major, what: &str) -> crate::error::Error {
        let mut buf = [0 as std::os::raw::c_char; 512];
        let code = unsafe { (api.device_take_error.unwrap())(device, buf.as_mut_ptr(), buf.len()) };
        let msg = unsafe { CStr::from_ptr(buf.as_ptr()) }.to_string_lossy().into_owned();
        crate::error::Error::new(format!("embree{}: {what} failed (error {code}: {msg})", major.number()))
    }

    #[inline]
    fn to_ffi(r: &Ray) -> ffi::pt_ray {
        ffi::pt_ray { org: r.origin.to_array(), tnear: r.tmin, dir: r.dir.to_array(), tfar: r.tmax }
    }

    /// A ray Embree will never report a hit for: used in place of invalid rays
    /// inside batches.
    const NULL_RAY: ffi::pt_ray = ffi::pt_ray { org: [0.0; 3], tnear: 1.0, dir: [0.0, 0.0, 1.0], tfar: 0.0 };

    impl EmbreeBackend {
        /// Build `major`'s scene over `shapes`; `threads` sizes Embree's TBB
        /// pool (0: all cores).
        pub fn build(major: Major, shapes: &[Shape], threads: usize, quality: Quality) -> Result<Self> {
            Self::build_configured(major, shapes, threads, quality, "")
        }

        /// `build` with `extra` appended to the device's configuration
        /// (for measurements, e.g. "verbose=2" prints Embree's BVH
        /// statistics, its SAH cost, after each build).
        pub fn build_configured(major: Major, shapes: &[Shape], threads: usize, quality: Quality, extra: &str) -> Result<Self> {
            let lib = library(major).map_err(crate::Error::new)?;
            let api = lib.api;
            let mut config = if threads > 0 { format!("threads={threads}") } else { String::new() };
            if !config.is_empty() && !extra.is_empty() {
                config.push(',');
            }
            config.push_str(extra);
            let c = CString::new(config).unwrap();
            let device = unsafe { (api.device_new.unwrap())(c.as_ptr()) };
            if device.is_null() {
                let msg = unsafe { CStr::from_ptr((api.device_new_error.unwrap())()) }.to_string_lossy().into_owned();
                crate::bail!("embree{}: cannot create a device: {msg}", major.number());
            }
            let robust = quality != Quality::High;
            let scene = unsafe { (api.scene_new.unwrap())(device, quality as i32, robust as i32) };
            let (coherent_mode, incoherent_mode) = major.default_batch_modes();
            let me = EmbreeBackend { api, lib, device, scene, threads, quality, coherent_mode, incoherent_mode };
            if scene.is_null() {
                return Err(take_error(api, device, major, "creating a scene"));
            }
            for (id, shape) in shapes.iter().enumerate() {
                let rc = match shape {
                    Shape::Mesh(m) => {
                        let xyz: Vec<f32> = m.positions.iter().flat_map(|p| p.to_array()).collect();
                        let idx: Vec<u32> = m.triangles.iter().flatten().copied().collect();
                        unsafe { (api.scene_add_mesh.unwrap())(scene, id as u32, xyz.as_ptr(), m.positions.len(), idx.as_ptr(), m.triangles.len()) }
                    }
                    Shape::Sphere { center, radius } => {
                        let cr = [center.x, center.y, center.z, *radius];
                        unsafe { (api.scene_add_sphere.unwrap())(scene, id as u32, cr.as_ptr(), Some(sphere_test)) }
                    }
                };
                if rc != 0 {
                    return Err(take_error(api, device, major, &format!("adding shape {id}")));
                }
            }
            if unsafe { (api.scene_commit.unwrap())(scene) } != 0 {
                return Err(take_error(api, device, major, "building the BVH"));
            }
            Ok(me)
        }

        /// Choose how batches are traced (for measurements). A mode the
        /// major lacks (streams in Embree 4) falls back to single rays.
        pub fn set_batch_modes(&mut self, coherent: BatchMode, incoherent: BatchMode) {
            self.coherent_mode = coherent;
            self.incoherent_mode = incoherent;
        }

        pub fn major(&self) -> Major {
            self.lib.major
        }

        fn mode_id(m: BatchMode) -> i32 {
            (match m {
                BatchMode::Loop => ffi::PT_BATCH_LOOP,
                BatchMode::Stream => ffi::PT_BATCH_STREAM,
                BatchMode::Packet4 => ffi::PT_BATCH_PACKET4,
                BatchMode::Packet8 => ffi::PT_BATCH_PACKET8,
                BatchMode::Packet16 => ffi::PT_BATCH_PACKET16,
            }) as i32
        }

        fn batch_intersect(&self, rays: &[Ray], hits: &mut [Option<Hit>], coherent: bool) {
            assert_eq!(rays.len(), hits.len());
            let fr: Vec<ffi::pt_ray> = rays.iter().map(|r| if r.is_valid() { to_ffi(r) } else { NULL_RAY }).collect();
            let mut fh = vec![ffi::pt_hit { t: 0.0, u: 0.0, v: 0.0, geom_id: 0, prim_id: 0 }; rays.len()];
            let mode = if coherent { self.coherent_mode } else { self.incoherent_mode };
            unsafe { (self.api.intersect_batch.unwrap())(self.scene, fr.as_ptr(), fh.as_mut_ptr(), fr.len(), Self::mode_id(mode), coherent as i32) };
            for ((h, f), r) in hits.iter_mut().zip(&fh).zip(rays) {
                *h = if f.geom_id == ffi::PT_INVALID_ID || !r.is_valid() { None } else { Some(from_ffi(f)) };
            }
        }

        fn batch_occluded(&self, rays: &[Ray], out: &mut [bool], coherent: bool) {
            assert_eq!(rays.len(), out.len());
            let fr: Vec<ffi::pt_ray> = rays.iter().map(|r| if r.is_valid() { to_ffi(r) } else { NULL_RAY }).collect();
            let mut o = vec![0u8; rays.len()];
            let mode = if coherent { self.coherent_mode } else { self.incoherent_mode };
            unsafe { (self.api.occluded_batch.unwrap())(self.scene, fr.as_ptr(), o.as_mut_ptr(), fr.len(), Self::mode_id(mode), coherent as i32) };
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
            match (self.lib.major, self.quality == Quality::High) {
                (Major::V3, false) => "embree3",
                (Major::V3, true) => "embree3-high",
                (Major::V4, false) => "embree4",
                (Major::V4, true) => "embree4-high",
            }
        }

        fn describe(&self) -> String {
            format!(
                "{} ({}, {} threads, CPU ISA {}, coherent batches {:?}, incoherent {:?}; headers {})",
                self.lib.version_string(),
                match self.quality {
                    Quality::High => "HIGH: spatial splits, not ROBUST",
                    Quality::Medium => "MEDIUM, ROBUST",
                    Quality::Low => "LOW, ROBUST",
                },
                if self.threads == 0 { "all".to_string() } else { self.threads.to_string() },
                cpu_isa(),
                self.coherent_mode,
                self.incoherent_mode,
                dotted(self.lib.header_version)
            )
        }

        fn memory_bytes(&self) -> usize {
            unsafe { (self.api.device_memory.unwrap())(self.device) }.max(0) as usize
        }

        fn intersect(&self, ray: &Ray) -> Option<Hit> {
            if !ray.is_valid() {
                return None;
            }
            let r = to_ffi(ray);
            let mut h = ffi::pt_hit { t: 0.0, u: 0.0, v: 0.0, geom_id: 0, prim_id: 0 };
            unsafe { (self.api.intersect1.unwrap())(self.scene, &r, &mut h) };
            (h.geom_id != ffi::PT_INVALID_ID).then(|| from_ffi(&h))
        }

        fn occluded(&self, ray: &Ray) -> bool {
            ray.is_valid() && unsafe { (self.api.occluded1.unwrap())(self.scene, &to_ffi(ray)) } != 0
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
    /// of its compiled targets (SSE2 up to AVX-512) at run time.
    fn cpu_isa() -> &'static str {
        #[cfg(target_arch = "x86_64")]
        {
            if super::sixteen_lanes() {
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
