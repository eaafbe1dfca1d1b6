//! A partial's text header: the settings every part of one render shares,
//! this part's own lines, and the integrity lines (`records`, `header`)
//! that seal it; parsed and checked on reading.

use super::{sha256_hex, SplitKind, CHECKSUM, FORMAT_VERSION, MAGIC};
use crate::error::{Error, Result};
use crate::render::{Region, Share};
use std::io::{BufRead, Read};

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
    pub(super) fn to_text(&self, records: Records) -> String {
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
    pub(super) fn samples_per_record(&self) -> Result<(u32, bool)> {
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

pub(super) fn parse_hex128(s: &str) -> Option<u128> {
    if s.len() == 32 && s.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b)) {
        u128::from_str_radix(s, 16).ok()
    } else {
        None
    }
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
pub(super) fn read_header(reader: &mut impl BufRead) -> Result<(Header, Records, u64)> {
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
