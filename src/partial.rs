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

use crate::error::{Error, Result};
use crate::render::splat::SplatSums;
use crate::render::sums::PixelSums;
use crate::render::{tile_grid, Region, Share, TILE};
use sha2::{Digest, Sha256};
use std::io::{BufRead, BufReader, Read, Write};
use xxhash_rust::xxh3::Xxh3;
use std::path::Path;

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

/// A partial's header.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    /// What every part of one render shares, in a fixed order.
    pub settings: Vec<(String, String)>,
    /// This part: `index` of `count`.
    pub index: u32,
    pub count: u32,
    /// Rays traced, render seconds (wall) and the process's CPU seconds.
    pub rays: u64,
    pub render_seconds: f64,
    pub cpu_seconds: f64,
    /// Samples with a NaN or out-of-range channel.
    pub bad_samples: u64,
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

impl Header {
    pub fn get(&self, key: &str) -> Option<&str> {
        self.settings.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }

    fn get_parsed<T: std::str::FromStr>(&self, key: &str) -> Result<T> {
        let v = self.get(key).ok_or_else(|| Error::new(format!("no '{key}' line")))?;
        v.parse().map_err(|_| Error::new(format!("'{key}' is not valid: '{v}'")))
    }

    pub fn settings_hash(&self) -> String {
        let text: String = self.settings.iter().map(|(k, v)| format!("{k} {v}\n")).collect();
        sha256_hex(text.as_bytes())
    }

    pub fn split(&self) -> Result<SplitKind> {
        match self.get("split") {
            Some("samples") => Ok(SplitKind::Samples),
            Some("tiles") => Ok(SplitKind::Tiles),
            other => Err(Error::new(format!("split '{}' is neither samples nor tiles", other.unwrap_or("")))),
        }
    }

    /// Whether the part stores a film of splats after its pixel records:
    /// whether its integrator (`IntegratorSpec::splats`) lands light on
    /// other pixels.
    pub fn has_splats(&self) -> bool {
        self.get("integrator").and_then(crate::render::integrator::IntegratorSpec::splats_by_name).unwrap_or(false)
    }

    /// The frame's pixel count (width × height; a region is a part of it).
    pub fn frame_pixels(&self) -> Result<u64> {
        Ok(self.get_parsed::<u64>("width")? * self.get_parsed::<u64>("height")?)
    }

    pub fn spp(&self) -> Result<u32> {
        self.get_parsed("spp")
    }

    /// The rendered region (its size is the images' size).
    pub fn region(&self) -> Result<Region> {
        let v: Vec<u32> = self
            .get("region")
            .unwrap_or("")
            .split_whitespace()
            .map(|w| w.parse().map_err(|_| Error::new(format!("region '{w}' is not a number"))))
            .collect::<Result<_>>()?;
        match v[..] {
            [x, y, w, h] if w > 0 && h > 0 && w <= 16384 && h <= 16384 => Ok(Region { x, y, w, h }),
            _ => Err(Error::new("'region' must be four numbers X Y W H with 1 <= W, H <= 16384")),
        }
    }

    /// What this part renders.
    pub fn share(&self) -> Result<Share> {
        Ok(match self.split()? {
            SplitKind::Samples => Share::samples_of(self.index, self.count, self.spp()?),
            SplitKind::Tiles => Share::Tiles { index: self.index, count: self.count },
        })
    }

    /// The header's lines from the magic line to the part's own lines,
    /// without the integrity lines (`records_and_checksums` adds them).
    fn body_text(&self) -> String {
        let mut t = format!("{MAGIC}\n");
        for (k, v) in &self.settings {
            t += &format!("{k} {v}\n");
        }
        t += &format!("settings_sha256 {}\n", self.settings_hash());
        t += &format!("part {} {}\n", self.index, self.count);
        t += &format!("rays {}\nrender_seconds {}\ncpu_seconds {}\nbad_samples {}\n", self.rays, self.render_seconds, self.cpu_seconds, self.bad_samples);
        t
    }

    /// The whole header as written: the body, the `records` line, the
    /// `header` checksum line over everything before it, and `end`.
    fn to_text(&self, records: Records) -> String {
        let mut t = self.body_text();
        t += &format!("records {} {CHECKSUM} {:032x}\n", records.pixels, records.checksum);
        t += &format!("header {CHECKSUM} {:032x}\nend\n", xxhash_rust::xxh3::xxh3_128(t.as_bytes()));
        t
    }

    fn parse(lines: &[String]) -> Result<(Header, Records)> {
        let mut h = Header { settings: Vec::new(), index: 0, count: 0, rays: 0, render_seconds: 0.0, cpu_seconds: 0.0, bad_samples: 0 };
        let mut hash = None;
        let mut part = None;
        let mut records = None;
        let num = |k: &str, v: &str| -> Result<f64> { v.parse::<f64>().map_err(|_| Error::new(format!("'{k}' is not a number: '{v}'"))) };
        for line in lines {
            let (k, v) = line.split_once(' ').unwrap_or((line.as_str(), ""));
            match k {
                "settings_sha256" => hash = Some(v.to_string()),
                "part" => {
                    let p: Vec<u32> = v.split_whitespace().filter_map(|w| w.parse().ok()).collect();
                    match p[..] {
                        [i, n] if i < n => part = Some((i, n)),
                        _ => crate::bail!("'part {v}' is not I N with I < N"),
                    }
                }
                "records" => {
                    let w: Vec<&str> = v.split(' ').collect();
                    records = match w[..] {
                        [n, CHECKSUM, sum] => n.parse().ok().zip(parse_hex128(sum)).map(|(pixels, checksum)| Records { pixels, checksum }),
                        _ => None,
                    };
                    if records.is_none() {
                        crate::bail!("'records {v}' is not 'records PIXELS {CHECKSUM} HEX'");
                    }
                }
                "rays" => h.rays = num(k, v)? as u64,
                "render_seconds" => h.render_seconds = num(k, v)?,
                "cpu_seconds" => h.cpu_seconds = num(k, v)?,
                "bad_samples" => h.bad_samples = num(k, v)? as u64,
                _ => h.settings.push((k.to_string(), v.to_string())),
            }
        }
        (h.index, h.count) = part.ok_or_else(|| Error::new("no 'part' line"))?;
        let records = records.ok_or_else(|| Error::new("no 'records' line"))?;
        if hash.as_deref() != Some(h.settings_hash().as_str()) {
            crate::bail!("the header's settings do not match its settings_sha256 (edited or damaged)");
        }
        h.share()?;
        Ok((h, records))
    }

    /// How many samples each stored pixel record must hold: exactly the
    /// share's (fixed sampling), or at most `-s` (adaptive sampling).
    fn samples_per_record(&self) -> Result<(u32, bool)> {
        let adaptive = self.get("adaptive").is_some_and(|a| a != "none");
        Ok(match self.share()? {
            Share::Samples { lo, hi } => (hi - lo, true),
            Share::Tiles { .. } | Share::All => (self.spp()?, !adaptive),
        })
    }
}

/// A partial's `records` line: how many pixel records follow the header,
/// and the XXH3-128 of their bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Records {
    pub pixels: u64,
    pub checksum: u128,
}

fn parse_hex128(s: &str) -> Option<u128> {
    if s.len() == 32 && s.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b)) {
        u128::from_str_radix(s, 16).ok()
    } else {
        None
    }
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

/// One header line (at most 4096 bytes, ending in a newline), appended to
/// `raw`; `None` at the end of the file, or for a line too long or not text.
fn header_line(reader: &mut impl BufRead, raw: &mut Vec<u8>) -> std::io::Result<Option<String>> {
    let mut line = Vec::new();
    reader.take(4096).read_until(b'\n', &mut line)?;
    raw.extend_from_slice(&line);
    Ok(String::from_utf8(line).ok().filter(|l| l.ends_with('\n')).map(|l| l.trim_end_matches('\n').to_string()))
}

/// Read and check a header: its first line, its checksum, its fields.
/// Returns the header, its `records` line and its length in bytes.
fn read_header(reader: &mut impl BufRead) -> Result<(Header, Records, u64)> {
    let io = |e: std::io::Error| Error::new(format!("cannot read: {e}"));
    let mut raw = Vec::new();
    match header_line(reader, &mut raw).map_err(io)? {
        Some(first) if first == MAGIC => {}
        Some(first) if first.starts_with("pathtracer-partial ") => {
            let version = &first["pathtracer-partial ".len()..];
            if version == "1" {
                crate::bail!("a version 1 partial (no checksums), which this pathtracer no longer merges: render the part again (format {FORMAT_VERSION})");
            }
            crate::bail!("partial format '{version}' is not the one this pathtracer reads ({FORMAT_VERSION})");
        }
        None if raw.is_empty() => crate::bail!("not a pathtracer partial (empty file)"),
        _ => crate::bail!("not a pathtracer partial, or its first line is damaged (no '{MAGIC}' line)"),
    }
    let mut lines = Vec::new();
    loop {
        let start = raw.len();
        let Some(line) = header_line(reader, &mut raw).map_err(io)? else {
            crate::bail!("header damaged or cut short (a line that is not text or has no end)");
        };
        if line == "end" {
            crate::bail!("header damaged (no 'header' checksum line before 'end')");
        }
        if let Some(rest) = line.strip_prefix("header ") {
            let sum = rest.strip_prefix(CHECKSUM).and_then(|r| r.strip_prefix(' ')).and_then(parse_hex128);
            let Some(sum) = sum else { crate::bail!("header damaged (unreadable checksum line)") };
            if header_line(reader, &mut raw).map_err(io)?.as_deref() != Some("end") {
                crate::bail!("header damaged (no 'end' line after its checksum line)");
            }
            if xxhash_rust::xxh3::xxh3_128(&raw[..start]) != sum {
                crate::bail!("header damaged (checksum mismatch)");
            }
            break;
        }
        lines.push(line);
        if lines.len() > 1000 {
            crate::bail!("header damaged (no checksum line in its first 1000 lines)");
        }
    }
    let (header, records) = Header::parse(&lines).map_err(|e| Error::new(format!("bad header: {}", e.0)))?;
    Ok((header, records, raw.len() as u64))
}

/// An open partial: its checked header, and a reader at its first record.
pub struct Partial {
    pub header: Header,
    pub records: Records,
    reader: BufReader<std::fs::File>,
}

impl Partial {
    /// Open `path`, read and check its header (first line, checksum,
    /// fields) and the length of its records; the records themselves are
    /// checked as they are read (`add_into`, `verify`).
    pub fn open(path: &Path) -> Result<Partial> {
        let fail = |why: String| Error::new(format!("{}: {why}", path.display()));
        let f = std::fs::File::open(path).map_err(|e| fail(format!("cannot read: {e}")))?;
        let len = f.metadata().map_err(|e| fail(format!("cannot read: {e}")))?.len();
        let mut reader = BufReader::with_capacity(1 << 20, f);
        let (header, records, header_bytes) = read_header(&mut reader).map_err(|e| fail(e.0))?;
        let pixels = covered_pixels(header.region().map_err(|e| fail(e.0))?, header.share().map_err(|e| fail(e.0))?).len() as u64;
        if records.pixels != pixels {
            return Err(fail(format!("bad header: 'records {}' where part {}/{} covers {pixels} pixels", records.pixels, header.index, header.count)));
        }
        let region = header.region().map_err(|e| fail(e.0))?;
        let splat_bytes = if header.has_splats() { region.w as u64 * region.h as u64 * SplatSums::BYTES as u64 } else { 0 };
        let payload_bytes = pixels * PixelSums::BYTES as u64 + splat_bytes;
        if len - header_bytes != payload_bytes {
            return Err(fail(format!(
                "{} bytes of records where part {}/{} has {payload_bytes} ({pixels} pixels{}): the file is cut short or damaged",
                len - header_bytes,
                header.index,
                header.count,
                if splat_bytes > 0 { " and the film of splats" } else { "" }
            )));
        }
        Ok(Partial { header, records, reader })
    }

    /// Add this partial's records into `sums` (one per region pixel). The
    /// records are checked as they are read: on damage (checksum mismatch)
    /// or an impossible sample count this returns an error naming the file
    /// and `sums` holds a part of them, so the caller must discard it
    /// (`merge` writes nothing then).
    /// `splats` (one per region pixel) takes the film of splats, when the
    /// part has one.
    pub fn add_into(mut self, path: &Path, sums: &mut [PixelSums], splats: &mut [SplatSums]) -> Result<()> {
        self.read_records(path, |i, r| sums[i].merge(r), |i, s| splats[i].merge(s))
    }

    /// Check this partial's records (checksum and sample counts) alone.
    pub fn verify(mut self, path: &Path) -> Result<()> {
        self.read_records(path, |_, _| {}, |_, _| {})
    }

    fn read_records(&mut self, path: &Path, mut use_record: impl FnMut(usize, &PixelSums), mut use_splat: impl FnMut(usize, &SplatSums)) -> Result<()> {
        let fail = |why: String| Error::new(format!("{}: {why}", path.display()));
        let pixels = covered_pixels(self.header.region()?, self.header.share()?);
        let (samples, exact) = self.header.samples_per_record()?;
        let mut hasher = Xxh3::new();
        let mut inconsistent = None;
        let mut buf = vec![0u8; PixelSums::BYTES * 4096];
        for chunk in pixels.chunks(4096) {
            let b = &mut buf[..chunk.len() * PixelSums::BYTES];
            self.reader.read_exact(b).map_err(|e| fail(format!("cannot read: {e}")))?;
            hasher.update(b);
            for (k, &i) in chunk.iter().enumerate() {
                let r = PixelSums::read_le(&b[k * PixelSums::BYTES..]);
                if r.n == samples || (!exact && r.n <= samples) {
                    use_record(i, &r);
                } else if inconsistent.is_none() {
                    inconsistent = Some((i, r.n));
                }
            }
        }
        if self.header.has_splats() {
            let region = self.header.region()?;
            let n = (region.w * region.h) as usize;
            let mut at = 0;
            while at < n {
                let k = (n - at).min(4096);
                let b = &mut buf[..k * SplatSums::BYTES];
                self.reader.read_exact(b).map_err(|e| fail(format!("cannot read: {e}")))?;
                hasher.update(b);
                for j in 0..k {
                    use_splat(at + j, &SplatSums::read_le(&b[j * SplatSums::BYTES..]));
                }
                at += k;
            }
        }
        if hasher.digest128() != self.records.checksum {
            return Err(fail("records damaged (checksum mismatch)".into()));
        }
        if let Some((i, n)) = inconsistent {
            let w = self.header.region()?.w as usize;
            return Err(fail(format!(
                "records inconsistent: pixel ({}, {}) of the region holds {n} samples where part {}/{} has {}{samples}",
                i % w,
                i / w,
                self.header.index,
                self.header.count,
                if exact { "" } else { "at most " }
            )));
        }
        Ok(())
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn header(split: &str, index: u32, count: u32) -> Header {
        Header {
            settings: vec![
                ("split".into(), split.into()),
                ("spp".into(), "8".into()),
                ("region".into(), "0 0 70 40".into()),
            ],
            index,
            count,
            rays: 12,
            render_seconds: 0.5,
            cpu_seconds: 1.0,
            bad_samples: 0,
        }
    }

    #[test]
    fn tiles_cover_the_region_once() {
        let r = Region { x: 0, y: 0, w: 70, h: 40 };
        let mut seen = vec![0; 70 * 40];
        for i in 0..5 {
            for p in covered_pixels(r, Share::Tiles { index: i, count: 5 }) {
                seen[p] += 1;
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
    }

    fn scratch(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("pt-partial-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// A tile-split part with distinct sums in every covered pixel.
    fn written(dir: &Path) -> (std::path::PathBuf, Header, Vec<PixelSums>) {
        written_as(dir, header("tiles", 1, 3), 8)
    }

    fn written_as(dir: &Path, h: Header, samples: u32) -> (std::path::PathBuf, Header, Vec<PixelSums>) {
        let r = h.region().unwrap();
        let mut sums = vec![PixelSums::default(); (r.w * r.h) as usize];
        for (i, s) in sums.iter_mut().enumerate() {
            for k in 0..samples {
                s.add([i as f32 + k as f32, 1.0, 0.5 * k as f32]);
            }
        }
        let path = dir.join("p.ptp");
        write(&path, &h, &sums, &[]).unwrap();
        (path, h, sums)
    }

    /// Open and read every record; the error, if any.
    fn check(path: &Path) -> Result<()> {
        let p = Partial::open(path)?;
        let region = p.header.region()?;
        let mut back = vec![PixelSums::default(); (region.w * region.h) as usize];
        p.add_into(path, &mut back, &mut [])
    }

    #[test]
    fn round_trip_and_damage() {
        let dir = scratch("round-trip");
        let (path, h, sums) = written(&dir);
        let p = Partial::open(&path).unwrap();
        assert_eq!(p.header, h);
        let mut back = vec![PixelSums::default(); 70 * 40];
        p.add_into(&path, &mut back, &mut []).unwrap();
        for i in covered_pixels(h.region().unwrap(), h.share().unwrap()) {
            assert_eq!(back[i], sums[i]);
        }
        // Cut short, edited, old and foreign files are refused with the reason.
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 1]).unwrap();
        assert!(Partial::open(&path).err().unwrap().0.contains("cut short"));
        let edited = String::from_utf8_lossy(&bytes).replacen("spp 8", "spp 9", 1).into_bytes();
        std::fs::write(&path, &edited).unwrap();
        assert!(Partial::open(&path).err().unwrap().0.contains("header damaged (checksum mismatch)"));
        // Edited and resealed: the settings hash still catches it.
        std::fs::write(&path, reseal(&edited).unwrap()).unwrap();
        assert!(Partial::open(&path).err().unwrap().0.contains("settings_sha256"));
        let old = String::from_utf8_lossy(&bytes).replacen("pathtracer-partial 2", "pathtracer-partial 1", 1).into_bytes();
        std::fs::write(&path, &old).unwrap();
        assert!(Partial::open(&path).err().unwrap().0.contains("a version 1 partial (no checksums)"), "{:?}", Partial::open(&path).err());
        std::fs::write(&path, b"P6\n1 1\n").unwrap();
        assert!(Partial::open(&path).err().unwrap().0.contains("not a pathtracer partial"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_film_of_splats_round_trips_and_its_damage_is_refused() {
        let dir = scratch("splats");
        let mut h = header("samples", 0, 2);
        h.settings[2].1 = "0 0 5 4".into();
        h.settings.push(("integrator".into(), "bdpt".into()));
        // Part 0 of 2 of 8 samples: 4 a pixel.
        let mut sums = vec![PixelSums::default(); 20];
        for s in &mut sums {
            (0..4).for_each(|_| {
                s.add([0.25; 3]);
            });
        }
        let mut splats = vec![SplatSums::default(); 20];
        for (i, s) in splats.iter_mut().enumerate() {
            s.add(glam::Vec3::new(i as f32, 0.5, 1e-3 * i as f32));
        }
        let path = dir.join("s.ptp");
        assert!(write(&path, &h, &sums, &[]).is_err(), "a splatting render's part without its film");
        write(&path, &h, &sums, &splats).unwrap();
        let (mut back, mut film) = (vec![PixelSums::default(); 20], vec![SplatSums::default(); 20]);
        Partial::open(&path).unwrap().add_into(&path, &mut back, &mut film).unwrap();
        assert_eq!(film, splats);
        let bytes = std::fs::read(&path).unwrap();
        for offset in [bytes.len() - 1, bytes.len() - 20 * SplatSums::BYTES, bytes.len() - 7 * SplatSums::BYTES + 30] {
            let mut b = bytes.clone();
            b[offset] ^= 4;
            std::fs::write(&path, &b).unwrap();
            let err = Partial::open(&path).and_then(|p| p.verify(&path)).err().expect("damage accepted").0;
            assert!(err.ends_with("records damaged (checksum mismatch)"), "{err}");
        }
        std::fs::write(&path, &bytes[..bytes.len() - SplatSums::BYTES]).unwrap();
        assert!(Partial::open(&path).err().unwrap().0.contains("and the film of splats"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn resealing_an_intact_partial_changes_nothing() {
        let dir = scratch("reseal");
        let (path, _, _) = written(&dir);
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(reseal(&bytes).unwrap(), bytes);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Every byte of a partial, one bit flipped at a time (bit `offset mod
    /// 8`, and all eight bits in every 7th byte): each flip is refused, and
    /// the reason names the part of the file that was hit.
    #[test]
    fn a_bit_flipped_anywhere_is_refused() {
        let dir = scratch("flips");
        // A small sample-split part (samples [2, 5) of 8, 6x3 pixels), so
        // that every byte can be tried.
        let mut h = header("samples", 1, 3);
        h.settings[2].1 = "0 0 6 3".into();
        let (path, _, _) = written_as(&dir, h, 3);
        let bytes = std::fs::read(&path).unwrap();
        let header_len = bytes.windows(5).position(|w| w == b"\nend\n").unwrap() + 5;
        let text = std::str::from_utf8(&bytes[..header_len]).unwrap();
        let line_of = |offset: usize| text[..offset.min(text.len())].matches('\n').count();
        let lines: Vec<&str> = text.lines().collect();
        let damaged = dir.join("damaged.ptp");
        let mut classes = std::collections::BTreeMap::<String, usize>::new();
        for offset in 0..bytes.len() {
            let bits: Vec<u8> = if offset % 7 == 0 { (0..8).collect() } else { vec![(offset % 8) as u8] };
            for bit in bits {
                let mut b = bytes.clone();
                b[offset] ^= 1 << bit;
                std::fs::write(&damaged, &b).unwrap();
                let err = check(&damaged).err().unwrap_or_else(|| panic!("a flip of bit {bit} at byte {offset} was accepted")).0;
                assert!(err.starts_with(&format!("{}: ", damaged.display())), "{err}");
                let class = if offset >= header_len {
                    // Records: n, then six 24-byte sums.
                    let at = (offset - header_len) % PixelSums::BYTES;
                    assert!(err.ends_with("records damaged (checksum mismatch)"), "byte {offset} (record byte {at}): {err}");
                    match at {
                        0..=3 => "record sample count",
                        4..=75 => "record sum",
                        _ => "record sum of squares",
                    }
                    .to_string()
                } else {
                    let line = lines[line_of(offset)];
                    let key = line.split(' ').next().unwrap();
                    let ok = if line_of(offset) == 0 {
                        err.contains("not a pathtracer partial") || err.contains("partial format")
                    } else {
                        err.contains("header damaged")
                    };
                    assert!(ok, "byte {offset} in header line '{line}': {err}");
                    format!("header line '{key}'")
                };
                *classes.entry(class).or_default() += 1;
            }
        }
        // Every kind of byte was hit: each header line (the settings, the
        // part's own, both checksums, end) and each field of a record.
        for class in ["record sample count", "record sum", "record sum of squares", "header line 'pathtracer-partial'", "header line 'spp'", "header line 'settings_sha256'", "header line 'part'", "header line 'rays'", "header line 'records'", "header line 'header'", "header line 'end'"] {
            assert!(classes.get(class).is_some_and(|&n| n > 0), "no flip in {class}: {classes:?}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn records_with_impossible_sample_counts_are_refused() {
        let dir = scratch("counts");
        let (path, h, mut sums) = written(&dir);
        let i = covered_pixels(h.region().unwrap(), h.share().unwrap())[5];
        sums[i].n = 9;
        write(&path, &h, &sums, &[]).unwrap();
        let err = check(&path).err().unwrap().0;
        assert!(err.contains("records inconsistent: pixel") && err.contains("holds 9 samples where part 1/3 has 8"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
