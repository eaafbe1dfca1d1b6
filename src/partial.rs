//! Partials: one part of a split render, as a file (`--part I/N --partial FILE`).
//!
//! A split render divides the work of one render between processes (Slurm
//! array tasks, say): by sample range — sample indices `[I·S/N, (I+1)·S/N)`
//! of every pixel — or, with adaptive sampling, by tiles. Each part writes
//! its pixels' exact sums (`render::sums`); `merge` adds them and writes
//! exactly the images the one-machine render writes.
//!
//! Format (version 1): a text header of `key value` lines, from the line
//! `pathtracer-partial 1` to the line `end`, then one binary record per pixel
//! the part covers (`PixelSums::BYTES`: n as u32, then Σx and Σx² as 192-bit
//! fixed point, all little-endian), in row-major order over the region,
//! skipping pixels outside the part's tiles. The header has two groups:
//! *settings* — everything that changes the image (scene and environment
//! file hashes, camera, flags, seed, backend, version, the split kind),
//! which every part of one render must share, hashed into `settings_sha256`
//! — and this part's own lines (which part, its samples, rays, times).

use crate::error::{Error, Result};
use crate::render::sums::PixelSums;
use crate::render::{tile_grid, Region, Share, TILE};
use sha2::{Digest, Sha256};
use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;

const MAGIC: &str = "pathtracer-partial 1";

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

    fn to_text(&self) -> String {
        let mut t = format!("{MAGIC}\n");
        for (k, v) in &self.settings {
            t += &format!("{k} {v}\n");
        }
        t += &format!("settings_sha256 {}\n", self.settings_hash());
        t += &format!("part {} {}\n", self.index, self.count);
        t += &format!("rays {}\nrender_seconds {}\ncpu_seconds {}\nbad_samples {}\nend\n", self.rays, self.render_seconds, self.cpu_seconds, self.bad_samples);
        t
    }

    fn parse(lines: &[String]) -> Result<Header> {
        let mut h = Header { settings: Vec::new(), index: 0, count: 0, rays: 0, render_seconds: 0.0, cpu_seconds: 0.0, bad_samples: 0 };
        let mut hash = None;
        let mut part = None;
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
                "rays" => h.rays = num(k, v)? as u64,
                "render_seconds" => h.render_seconds = num(k, v)?,
                "cpu_seconds" => h.cpu_seconds = num(k, v)?,
                "bad_samples" => h.bad_samples = num(k, v)? as u64,
                _ => h.settings.push((k.to_string(), v.to_string())),
            }
        }
        (h.index, h.count) = part.ok_or_else(|| Error::new("no 'part' line"))?;
        if hash.as_deref() != Some(h.settings_hash().as_str()) {
            crate::bail!("the header's settings do not match its settings_sha256 (edited or damaged)");
        }
        h.share()?;
        Ok(h)
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

/// Write a partial: `sums` has one entry per region pixel; only the covered
/// ones are stored. Written to a temporary name and renamed into place, so a
/// retried task simply replaces an identical file.
pub fn write(path: &Path, header: &Header, sums: &[PixelSums]) -> Result<()> {
    let region = header.region()?;
    let pixels = covered_pixels(region, header.share()?);
    crate::image_io::atomically(path, |tmp| {
        let f = std::fs::File::create(tmp).map_err(|e| e.to_string())?;
        let mut w = std::io::BufWriter::with_capacity(1 << 20, f);
        w.write_all(header.to_text().as_bytes()).map_err(|e| e.to_string())?;
        let mut buf = Vec::with_capacity(PixelSums::BYTES * 4096);
        for chunk in pixels.chunks(4096) {
            buf.clear();
            for &i in chunk {
                sums[i].write_le(&mut buf);
            }
            w.write_all(&buf).map_err(|e| e.to_string())?;
        }
        w.into_inner().map_err(|e| e.to_string())?.sync_all().map_err(|e| e.to_string())
    })
}

/// An open partial: its header, and a reader at its first record.
pub struct Partial {
    pub header: Header,
    reader: BufReader<std::fs::File>,
    payload_bytes: u64,
}

impl Partial {
    /// Open `path` and read its header (not the records).
    pub fn open(path: &Path) -> Result<Partial> {
        let fail = |why: String| Error::new(format!("{}: {why}", path.display()));
        let f = std::fs::File::open(path).map_err(|e| fail(format!("cannot read: {e}")))?;
        let len = f.metadata().map_err(|e| fail(format!("cannot read: {e}")))?.len();
        let mut reader = BufReader::with_capacity(1 << 20, f);
        let mut lines = Vec::new();
        let mut header_bytes = 0u64;
        loop {
            let mut line = Vec::new();
            let n = (&mut reader).take(4096).read_until(b'\n', &mut line).map_err(|e| fail(format!("cannot read: {e}")))?;
            header_bytes += n as u64;
            let text = String::from_utf8(line).ok().filter(|l| l.ends_with('\n'));
            let Some(text) = text else {
                return Err(fail(if lines.is_empty() { "not a pathtracer partial (no header)".into() } else { "the header is cut short".into() }));
            };
            let text = text.trim_end_matches('\n').to_string();
            if lines.is_empty() && text != MAGIC {
                return Err(fail(if text.starts_with("pathtracer-partial ") {
                    format!("partial format '{text}' is not the one this pathtracer reads ('{MAGIC}')")
                } else {
                    "not a pathtracer partial (no 'pathtracer-partial 1' line)".into()
                }));
            }
            if text == "end" {
                break;
            }
            lines.push(text);
            if lines.len() > 1000 {
                return Err(fail("the header has no 'end' line".into()));
            }
        }
        let header = Header::parse(&lines[1..]).map_err(|e| fail(format!("bad header: {}", e.0)))?;
        let pixels = covered_pixels(header.region().map_err(|e| fail(e.0))?, header.share().map_err(|e| fail(e.0))?).len() as u64;
        let payload_bytes = pixels * PixelSums::BYTES as u64;
        if len - header_bytes != payload_bytes {
            return Err(fail(format!(
                "{} bytes of pixel records where part {}/{} has {payload_bytes} ({pixels} pixels): the file is cut short or damaged",
                len - header_bytes,
                header.index,
                header.count
            )));
        }
        Ok(Partial { header, reader, payload_bytes })
    }

    /// Add this partial's records into `sums` (one per region pixel).
    pub fn add_into(mut self, path: &Path, sums: &mut [PixelSums]) -> Result<()> {
        let pixels = covered_pixels(self.header.region()?, self.header.share()?);
        debug_assert_eq!(pixels.len() as u64 * PixelSums::BYTES as u64, self.payload_bytes);
        let mut buf = vec![0u8; PixelSums::BYTES * 4096];
        for chunk in pixels.chunks(4096) {
            let b = &mut buf[..chunk.len() * PixelSums::BYTES];
            self.reader.read_exact(b).map_err(|e| Error::new(format!("{}: cannot read: {e}", path.display())))?;
            for (k, &i) in chunk.iter().enumerate() {
                sums[i].merge(&PixelSums::read_le(&b[k * PixelSums::BYTES..]));
            }
        }
        Ok(())
    }
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

    #[test]
    fn round_trip_and_damage() {
        let dir = std::env::temp_dir().join(format!("pt-partial-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let h = header("tiles", 1, 3);
        let mut sums = vec![PixelSums::default(); 70 * 40];
        for (i, s) in sums.iter_mut().enumerate() {
            s.add([i as f32, 1.0, 0.5]);
        }
        let path = dir.join("p.ptp");
        write(&path, &h, &sums).unwrap();
        let p = Partial::open(&path).unwrap();
        assert_eq!(p.header, h);
        let mut back = vec![PixelSums::default(); 70 * 40];
        p.add_into(&path, &mut back).unwrap();
        for i in covered_pixels(h.region().unwrap(), h.share().unwrap()) {
            assert_eq!(back[i], sums[i]);
        }
        // Cut short, edited and foreign files are refused with the reason.
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 1]).unwrap();
        assert!(Partial::open(&path).err().unwrap().0.contains("cut short"));
        let edited = String::from_utf8_lossy(&bytes).replacen("spp 8", "spp 9", 1).into_bytes();
        std::fs::write(&path, &edited).unwrap();
        assert!(Partial::open(&path).err().unwrap().0.contains("settings_sha256"));
        std::fs::write(&path, b"P6\n1 1\n").unwrap();
        assert!(Partial::open(&path).err().unwrap().0.contains("not a pathtracer partial"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
