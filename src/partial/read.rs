//! Reading a partial: the header checked on opening, the records checked
//! (checksum, sample counts) as they are added into a merge.

use super::covered_pixels;
use super::header::{read_header, Header, Records};
use crate::error::{Error, Result};
use crate::render::splat::SplatSums;
use crate::render::sums::PixelSums;
use std::io::{BufReader, Read};
use std::path::Path;
use xxhash_rust::xxh3::Xxh3;

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
