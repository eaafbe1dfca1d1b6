//! Partials: one part of a split render, as a file (`--part I/N --partial FILE`).
//!
//! A split render divides the work of one render between processes (Slurm
//! array tasks, say): by sample range — sample indices `[I·S/N, (I+1)·S/N)`
//! of every pixel — or, with adaptive sampling, by tiles. Each part writes
//! its pixels' exact sums (`render::sums`); `merge` adds them and writes
//! exactly the images the one-machine render writes.
//!
//! Format (version 2): a text header of `key value` lines, from the line
//! `pathtracer-partial 2` to the line `end`, then one binary record per pixel
//! the part covers (`PixelSums::BYTES`: n as u32, then Σx and Σx² as 192-bit
//! fixed point, all little-endian), in row-major order over the region,
//! skipping pixels outside the part's tiles. The header has two groups:
//! *settings* — everything that changes the image (scene and environment
//! file hashes, camera, flags, seed, backend, version, the split kind),
//! which every part of one render must share, hashed into `settings_sha256`
//! — and this part's own lines (which part, its samples, rays, times).
//!
//! Integrity: partials cross shared file systems and wait on disks for days,
//! so damage after writing must be caught, not merged. The header's last two
//! lines are `records <pixels> xxh3-128 <hex>`, the XXH3-128 of every record
//! byte, and `header xxh3-128 <hex>`, the XXH3-128 of every header byte
//! before that line; `end` must follow it. XXH3 rather than SHA-256 because
//! merging reads every byte of every part: on a 1920×1080 partial (307 MB
//! of records) it hashes at 6.8 GB/s against SHA-256's 1.1 GB/s
//! (docs/reliability.md), and damage, not forgery, is what it guards
//! against. Version 1 partials (no checksums) are refused with a message
//! saying so.
//!
//! Splats: a render whose integrator lands light on other pixels
//! (`IntegratorSpec::splats` of the header's `integrator`) stores
//! after its pixel records the film of splats of the whole region
//! (`SplatSums::BYTES` per pixel, row-major, every pixel), which `merge`
//! adds as exactly as the pixel sums; the `records` checksum covers both.

mod header;
mod read;
mod write;
#[cfg(test)]
mod tests;

pub use header::{Header, Records};
pub use read::Partial;
pub use write::{reseal, write};

use crate::render::{tile_grid, Region, Share, TILE};
use sha2::{Digest, Sha256};

/// The format this pathtracer writes and reads.
pub const FORMAT_VERSION: u32 = 2;
const MAGIC: &str = "pathtracer-partial 2";
/// The checksum's name in the header.
const CHECKSUM: &str = "xxh3-128";

/// How a render's work is split.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SplitKind {
    Samples,
    Tiles,
}

impl SplitKind {
    pub fn name(self) -> &'static str {
        match self {
            SplitKind::Samples => "samples",
            SplitKind::Tiles => "tiles",
        }
    }
}

/// Hex SHA-256 of some bytes.
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

/// The CPU time this process has used so far (user + system), in seconds.
pub fn process_cpu_seconds() -> f64 {
    // SAFETY: getrusage only writes the struct it is given.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) } != 0 {
        return 0.0;
    }
    let t = |tv: libc::timeval| tv.tv_sec as f64 + tv.tv_usec as f64 * 1e-6;
    t(u.ru_utime) + t(u.ru_stime)
}

/// The region-local pixel indices (row 0 at the top) a share covers, in
/// the order a partial stores them.
pub fn covered_pixels(region: Region, share: Share) -> Vec<usize> {
    let (cols, _) = tile_grid(region);
    let mut out = Vec::new();
    for ly in 0..region.h {
        for lx in 0..region.w {
            if share.has_tile((ly / TILE) * cols + lx / TILE) {
                out.push((ly * region.w + lx) as usize);
            }
        }
    }
    out
}
