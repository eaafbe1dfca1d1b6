//! `pathtracer merge`: the partials of a split render into its images.
//!
//! The set must be one render's (every header's settings equal) and cover
//! its work exactly once: every sample index of every pixel (a sample
//! split) or every tile (a tile split), with nothing missing and nothing
//! twice. Every part must be intact: its header checksum is checked when it
//! is opened, its records' checksum as they are summed, and no image is
//! written unless every part passed. The sums are exact, so the merged
//! images are the one-machine render's, byte for byte, whatever the number
//! of parts.
//!
//! `pathtracer verify` checks parts alone (one line per damaged file), for
//! the Slurm merge job to name every part to render again.

use crate::error::{Error, Result};
use crate::partial::{Header, Partial, SplitKind};
use crate::render::splat::SplatSums;
use crate::render::sums::PixelSums;
use crate::render::{tile_grid, RenderOutput, Share};
use std::path::{Path, PathBuf};

/// What the merge makes: the images, and the parts' summed statistics.
pub struct Merged {
    pub header: Header,
    pub output: RenderOutput,
    /// Sum over parts of rays, render seconds and CPU seconds.
    pub rays: u64,
    pub render_seconds: f64,
    pub cpu_seconds: f64,
    pub bad_samples: u64,
}

fn names(paths: &[&Path]) -> String {
    paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
}

fn list(v: &[u32]) -> String {
    v.iter().map(|i| i.to_string()).collect::<Vec<_>>().join(",")
}

/// Refuse a set whose headers disagree or that does not cover the work
/// exactly once; the message names the files and what is wrong.
pub fn check_set(parts: &[(PathBuf, Header)]) -> Result<()> {
    let (p0, h0) = &parts[0];
    for (p, h) in &parts[1..] {
        if h.settings != h0.settings {
            let key = |h: &Header, k: &str| h.get(k).unwrap_or("(none)").to_string();
            let keys = h0.settings.iter().map(|(k, _)| k.as_str()).chain(h.settings.iter().map(|(k, _)| k.as_str()));
            let differ: Vec<String> = keys
                .filter(|k| key(h0, k) != key(h, k))
                .map(|k| format!("{k} ({} vs {})", key(h0, k), key(h, k)))
                .collect::<std::collections::BTreeSet<_>>()
                .into_iter()
                .collect();
            crate::bail!("{} and {} are not parts of the same render: they differ in {}", p0.display(), p.display(), differ.join(", "));
        }
    }
    let count = h0.count;
    let same_count = parts.iter().all(|(_, h)| h.count == count);
    if same_count {
        // Each part index once: the common case, reported by part.
        let mut by_index: Vec<Vec<&Path>> = vec![Vec::new(); count as usize];
        for (p, h) in parts {
            by_index[h.index as usize].push(p);
        }
        if let Some((i, ps)) = by_index.iter().enumerate().find(|(_, ps)| ps.len() > 1) {
            crate::bail!("part {i}/{count} is given more than once ({}): a set must have each part once", names(ps));
        }
        let missing: Vec<u32> = (0..count).filter(|&i| by_index[i as usize].is_empty()).collect();
        if !missing.is_empty() {
            crate::bail!(
                "incomplete set: {} of {count} parts, missing part{} {} (render {} with --part I/{count})",
                count as usize - missing.len(),
                if missing.len() > 1 { "s" } else { "" },
                list(&missing),
                if missing.len() > 1 { "them" } else { "it" }
            );
        }
        return Ok(());
    }
    // Parts of different splits (re-rendered in finer pieces, say): check
    // what they cover.
    match h0.split()? {
        SplitKind::Samples => {
            let spp = h0.spp()?;
            let mut ranges: Vec<(u32, u32, &Path)> = parts
                .iter()
                .map(|(p, h)| match h.share() {
                    Ok(Share::Samples { lo, hi }) => Ok((lo, hi, p.as_path())),
                    _ => Err(Error::new(format!("{}: not a sample-split part", p.display()))),
                })
                .collect::<Result<_>>()?;
            ranges.sort_by_key(|r| (r.0, r.1));
            let mut at = 0u32;
            let mut last: Option<&Path> = None;
            for &(lo, hi, p) in &ranges {
                if lo > at {
                    crate::bail!("incomplete set: no part has samples [{at}, {lo}) of {spp}");
                }
                if lo < at {
                    crate::bail!("overlapping parts: {} and {} both have samples [{lo}, {})", last.unwrap().display(), p.display(), at.min(hi));
                }
                at = hi;
                last = Some(p);
            }
            if at < spp {
                crate::bail!("incomplete set: no part has samples [{at}, {spp}) of {spp}");
            }
        }
        SplitKind::Tiles => {
            let (cols, rows) = tile_grid(h0.region()?);
            let mut owner: Vec<Option<&Path>> = vec![None; (cols * rows) as usize];
            for (p, h) in parts {
                let share = h.share()?;
                for k in 0..cols * rows {
                    if share.has_tile(k) {
                        if let Some(q) = owner[k as usize] {
                            crate::bail!("overlapping parts: {} and {} both have tile {k}", q.display(), p.display());
                        }
                        owner[k as usize] = Some(p);
                    }
                }
            }
            let missing: Vec<u32> = (0..cols * rows).filter(|&k| owner[k as usize].is_none()).collect();
            if !missing.is_empty() {
                crate::bail!("incomplete set: no part has tile{} {} of {}", if missing.len() > 1 { "s" } else { "" }, list(&missing), cols * rows);
            }
        }
    }
    Ok(())
}

/// Check and add a set of partials.
pub fn merge(paths: &[PathBuf]) -> Result<Merged> {
    if paths.is_empty() {
        crate::bail!("merge: no partials given");
    }
    let mut opened = Vec::with_capacity(paths.len());
    for p in paths {
        opened.push((p.clone(), Partial::open(p)?));
    }
    let headers: Vec<(PathBuf, Header)> = opened.iter().map(|(p, o)| (p.clone(), o.header.clone())).collect();
    check_set(&headers)?;
    let header = headers[0].1.clone();
    let region = header.region()?;
    let mut sums = vec![PixelSums::default(); (region.w * region.h) as usize];
    let mut splats = if header.has_splats() { vec![SplatSums::default(); sums.len()] } else { Vec::new() };
    // In part order (the sums are exact, so the order changes no bit).
    opened.sort_by_key(|(_, o)| o.header.share().map(|s| match s { Share::Samples { lo, .. } => lo, _ => o.header.index }).unwrap_or(0));
    let (mut rays, mut render_seconds, mut cpu_seconds, mut bad_samples) = (0, 0.0, 0.0, 0);
    for (p, o) in opened {
        rays += o.header.rays;
        render_seconds += o.header.render_seconds;
        cpu_seconds += o.header.cpu_seconds;
        bad_samples += o.header.bad_samples;
        o.add_into(&p, &mut sums, &mut splats)?;
    }
    let frame_pixels = if header.has_splats() { header.frame_pixels()? } else { 0 };
    let output = RenderOutput::from_sums(region.w, region.h, sums, splats, frame_pixels);
    Ok(Merged { header, output, rays, render_seconds, cpu_seconds, bad_samples })
}

/// The `verify` command: check each partial's integrity on its own (header
/// and records checksums, sample counts). Prints a line per partial; fails
/// when any is damaged.
pub fn verify(paths: &[PathBuf]) -> Result<()> {
    let mut bad = 0;
    for p in paths {
        match Partial::open(p).and_then(|o| {
            let h = o.header.clone();
            o.verify(p).map(|()| h)
        }) {
            Ok(h) => println!("{}: ok (part {}/{} of {}, {} split)", p.display(), h.index, h.count, h.get("scene").unwrap_or("?"), h.get("split").unwrap_or("?")),
            Err(e) => {
                eprintln!("{e}");
                bad += 1;
            }
        }
    }
    if bad > 0 {
        crate::bail!("{bad} of {} partials failed the check", paths.len());
    }
    Ok(())
}

/// The `merge` command: write the images the one-machine render writes.
pub fn run(paths: &[PathBuf], png: &Path, exr: Option<&Path>, variance_exr: Option<&Path>) -> Result<()> {
    super::images::check_output_names(Some(png), exr, variance_exr)?;
    let m = merge(paths)?;
    let spp = m.header.spp()?;
    let out = &m.output;
    // The rate image where the parts ran adaptive sampling, as the render does.
    let adaptive = m.header.get("adaptive").is_some_and(|a| a != "none");
    let written = super::images::write_images(out, png, adaptive, exr, variance_exr, spp)?;
    let samples: u64 = out.samples.iter().map(|&n| n as u64).sum();
    if m.bad_samples > 0 {
        eprintln!("warning: {} samples had a NaN or out-of-range value (counted as 0 or ±2^36)", m.bad_samples);
    }
    println!(
        "{} | merged {} parts ({} split) | {samples} samples | {} rays | render {:.3} s, CPU {:.3} s summed over parts | wrote {}",
        m.header.get("scene").unwrap_or("?"),
        paths.len(),
        m.header.get("split").unwrap_or("?"),
        m.rays,
        m.render_seconds,
        m.cpu_seconds,
        written.join(", ")
    );
    Ok(())
}
