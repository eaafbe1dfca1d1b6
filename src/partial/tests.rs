//! Round trips, damage anywhere refused, resealing, impossible sample counts.

use super::*;
use crate::error::Result;
use crate::render::splat::SplatSums;
use crate::render::sums::PixelSums;
use std::path::Path;

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
