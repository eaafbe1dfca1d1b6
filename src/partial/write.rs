//! Writing a partial: its covered pixels' records (and film of splats)
//! hashed, the header sealed with that checksum, the whole written to a
//! temporary name and renamed into place.

use super::header::{Header, Records};
use super::{covered_pixels, CHECKSUM};
use crate::error::Result;
use crate::render::splat::SplatSums;
use crate::render::sums::PixelSums;
use std::io::Write;
use std::path::Path;
use xxhash_rust::xxh3::Xxh3;

/// The covered pixels' records, in file order, `chunk` pixels at a time.
fn record_chunks<'a>(pixels: &'a [usize], sums: &'a [PixelSums], chunk: usize) -> impl Iterator<Item = Vec<u8>> + 'a {
    pixels.chunks(chunk).map(|c| {
        let mut buf = Vec::with_capacity(PixelSums::BYTES * c.len());
        for &i in c {
            sums[i].write_le(&mut buf);
        }
        buf
    })
}

/// The film of splats as stored, `chunk` pixels at a time.
fn splat_chunks(splats: &[SplatSums], chunk: usize) -> impl Iterator<Item = Vec<u8>> + '_ {
    splats.chunks(chunk).map(|c| {
        let mut buf = Vec::with_capacity(SplatSums::BYTES * c.len());
        for s in c {
            s.write_le(&mut buf);
        }
        buf
    })
}

/// Write a partial: `sums` has one entry per region pixel; only the covered
/// ones are stored; `splats` (one per region pixel, when the header's
/// integrator splats; else empty) follow. Written to a temporary name and
/// renamed into place, so a retried task simply replaces an identical file.
pub fn write(path: &Path, header: &Header, sums: &[PixelSums], splats: &[SplatSums]) -> Result<()> {
    let region = header.region()?;
    let pixels = covered_pixels(region, header.share()?);
    let want = if header.has_splats() { (region.w * region.h) as usize } else { 0 };
    if splats.len() != want {
        crate::bail!("{}: {} splat records where the render has {want}", path.display(), splats.len());
    }
    // The header carries the records' checksum, so they are hashed first
    // (serialising them twice costs far less than the render did).
    let mut hasher = Xxh3::new();
    for buf in record_chunks(&pixels, sums, 4096).chain(splat_chunks(splats, 4096)) {
        hasher.update(&buf);
    }
    let records = Records { pixels: pixels.len() as u64, checksum: hasher.digest128() };
    crate::image_io::atomically(path, |tmp| {
        let f = std::fs::File::create(tmp).map_err(|e| e.to_string())?;
        let mut w = std::io::BufWriter::with_capacity(1 << 20, f);
        w.write_all(header.to_text(records).as_bytes()).map_err(|e| e.to_string())?;
        for buf in record_chunks(&pixels, sums, 4096).chain(splat_chunks(splats, 4096)) {
            w.write_all(&buf).map_err(|e| e.to_string())?;
        }
        w.into_inner().map_err(|e| e.to_string())?.sync_all().map_err(|e| e.to_string())
    })
}

/// For fuzzing beyond the checksums: recompute a partial's `records` and
/// `header` checksums over its bytes as they are, so that a mutated file
/// reaches the field parsers. `None` when its integrity lines cannot be
/// found.
pub fn reseal(bytes: &[u8]) -> Option<Vec<u8>> {
    let find = |hay: &[u8], needle: &[u8]| hay.windows(needle.len()).position(|w| w == needle);
    let header_line = find(bytes, b"\nheader ")? + 1;
    let end = header_line + find(&bytes[header_line..], b"\nend\n")? + 5;
    let records_line = find(&bytes[..header_line], b"\nrecords ")? + 1;
    let records_end = records_line + find(&bytes[records_line..header_line], b"\n")?;
    let fields: Vec<&[u8]> = bytes[records_line..records_end].split(|&b| b == b' ').collect();
    let mut out = bytes[..records_line].to_vec();
    out.extend_from_slice(b"records ");
    out.extend_from_slice(fields.get(1)?);
    out.extend_from_slice(format!(" {CHECKSUM} {:032x}\n", xxhash_rust::xxh3::xxh3_128(&bytes[end..])).as_bytes());
    let sum = xxhash_rust::xxh3::xxh3_128(&out);
    out.extend_from_slice(format!("header {CHECKSUM} {sum:032x}\nend\n").as_bytes());
    out.extend_from_slice(&bytes[end..]);
    Some(out)
}
