//! Split renders (`--part I/N --partial FILE`) and `pathtracer merge`: the
//! merged files equal the one-machine render's byte for byte, at any N, with
//! sample and tile splits, with and without adaptive sampling; bad sets and
//! bad flags are refused with one line and leave no output.

mod common;

use std::path::Path;
use std::process::{Command, Output};

fn scratch(name: &str) -> common::Scratch {
    common::Scratch::new("split", name)
}

fn pathtracer(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pathtracer")).args(args).current_dir(dir).env("CI", "true").output().unwrap()
}

fn ok(dir: &Path, args: &[&str]) -> Output {
    let out = pathtracer(dir, args);
    assert!(out.status.success(), "pathtracer {args:?} failed: {}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    out
}

/// The error line of a run that must fail, after checking it is one line.
fn refused(dir: &Path, args: &[&str]) -> String {
    let out = pathtracer(dir, args);
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(!out.status.success(), "pathtracer {args:?} should have failed");
    assert_eq!(err.trim_end().lines().count(), 1, "not one line: {err}");
    assert!(!err.contains("panicked"), "{err}");
    err
}

const OUTPUTS: [&str; 4] = ["img.png", "img_rate.png", "img.exr", "var.exr"];

/// Render `args` on one machine into `dir/one`, then as `n` parts (rendered
/// with alternating thread counts, merged in reverse order) into `dir/n<N>`,
/// and require the four output files to be equal byte for byte.
fn assert_split_equals_whole(dir: &Path, args: &[&str], extra: &[&str], ns: &[u32]) {
    let one = dir.join("one");
    std::fs::create_dir_all(&one).unwrap();
    let mut a: Vec<&str> = args.to_vec();
    a.extend(["-t", "2", "-f", "img.png", "--exr", "img.exr", "--variance-exr", "var.exr"]);
    ok(&one, &a);
    for &n in ns {
        let sub = dir.join(format!("n{n}"));
        std::fs::create_dir_all(&sub).unwrap();
        let mut parts = Vec::new();
        for i in 0..n {
            let part = format!("{i}/{n}");
            let file = format!("part-{i}.ptp");
            let threads = if i % 2 == 0 { "1" } else { "2" };
            let mut a: Vec<&str> = args.to_vec();
            a.extend(["-t", threads, "--part", &part, "--partial", &file]);
            a.extend(extra);
            ok(&sub, &a);
            parts.push(file);
        }
        let mut m: Vec<&str> = vec!["merge"];
        m.extend(parts.iter().rev().map(|s| s.as_str()));
        m.extend(["-f", "img.png", "--exr", "img.exr", "--variance-exr", "var.exr"]);
        let out = ok(&sub, &m);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(stdout.contains(&format!("merged {n} parts")), "{stdout}");
        for f in OUTPUTS {
            // The rate image exists where adaptive sampling ran, in both or neither.
            assert_eq!(one.join(f).exists(), sub.join(f).exists(), "{args:?} {extra:?} N={n}: {f} written by one of the two");
            if !one.join(f).exists() {
                assert!(f.ends_with("_rate.png") && !args.contains(&"-a"), "{f} missing");
                continue;
            }
            let (x, y) = (std::fs::read(one.join(f)).unwrap(), std::fs::read(sub.join(f)).unwrap());
            assert!(x == y, "{args:?} {extra:?} N={n}: {f} differs from the one-machine render");
        }
    }
}

#[test]
fn bidirectional_sample_splits_merge_to_the_one_machine_render_byte_for_byte() {
    // The film of splats travels in the partials and is added exactly: BDPT
    // with a thin lens, and light tracing over a -p cell (whose splats from
    // light subpaths landing outside it are dropped in every part alike).
    let d = scratch("bdpt-samples");
    assert_split_equals_whole(&d, &["--integrator", "bdpt", "-r", "48", "36", "-s", "12", "-m", "4", "-b", "0.05", "-d", "4.5", "--seed", "5"], &[], &[1, 3, 12]);
    let d = scratch("light-samples");
    assert_split_equals_whole(&d, &["--integrator", "light", "-r", "48", "36", "-p", "8", "4", "30", "20", "-s", "8", "-m", "3"], &[], &[2, 5]);
}

#[test]
fn sample_splits_merge_to_the_one_machine_render_byte_for_byte() {
    let d = scratch("samples");
    // Global illumination, a thin lens (two more draws per camera ray) and
    // uneven splits (24 samples in 5 or 7 parts).
    assert_split_equals_whole(&d, &["-r", "96", "72", "-s", "24", "-m", "4", "-b", "0.05", "-d", "4.5", "--seed", "3"], &[], &[1, 2, 5, 7, 24]);
}

#[test]
fn sample_splits_of_an_embree_render_and_of_normals_merge_exactly() {
    let d = scratch("embree");
    let embree = pathtracer(&d, &["--backend", "embree", "-r", "8", "8", "-f", "probe.png"]);
    if embree.status.success() {
        assert_split_equals_whole(&d.join("e"), &["--backend", "embree", "-r", "64", "48", "-s", "8", "-m", "3"], &[], &[3]);
    } else {
        eprintln!("SKIPPED the Embree split: {}", String::from_utf8_lossy(&embree.stderr).trim());
    }
    assert_split_equals_whole(&d.join("n"), &["--integrator", "normals", "-r", "64", "48", "-s", "4"], &[], &[4]);
}

#[test]
fn adaptive_renders_split_by_tiles_merge_exactly() {
    let d = scratch("adaptive");
    // CS184's rule and the unbiased pilot rule: a tile split, chosen for -a
    // without asking; the frame is 5x3 tiles, one cut by the edge.
    let base = ["-r", "150", "90", "-s", "64", "-m", "2", "-a", "8", "0.05"];
    assert_split_equals_whole(&d.join("cs184"), &base, &[], &[2, 5, 15]);
    let mut pilot = base.to_vec();
    pilot.push("--adaptive-pilot");
    assert_split_equals_whole(&d.join("pilot"), &pilot, &[], &[4]);
    // A tile split of a fixed-rate render of a cell (-p), too.
    assert_split_equals_whole(&d.join("cell"), &["-r", "150", "90", "-s", "8", "-p", "20", "10", "70", "50"], &["--split", "tiles"], &[3]);
}

#[test]
fn merge_refuses_incomplete_duplicated_overlapping_and_foreign_sets() {
    let d = scratch("refuse");
    let args = ["-r", "48", "32", "-s", "8", "-m", "2"];
    let part = |i: u32, n: u32, file: &str, more: &[&str]| {
        let p = format!("{i}/{n}");
        let mut a: Vec<&str> = args.to_vec();
        a.extend(["--part", &p, "--partial", file]);
        a.extend(more);
        ok(&d, &a);
    };
    for i in 0..4 {
        part(i, 4, &format!("p{i}.ptp"), &[]);
    }
    let merge = |files: &[&str]| {
        let mut a = vec!["merge"];
        a.extend(files);
        a.extend(["-f", "out.png", "--exr", "out.exr"]);
        refused(&d, &a)
    };
    let e = merge(&["p0.ptp", "p1.ptp", "p3.ptp"]);
    assert!(e.contains("incomplete set") && e.contains("missing part 2"), "{e}");
    let e = merge(&["p0.ptp", "p1.ptp", "p2.ptp", "p3.ptp", "p2.ptp"]);
    assert!(e.contains("part 2/4 is given more than once"), "{e}");
    // Part 0 of an 8-way split has samples 0..1, which part 0/4 has too.
    part(0, 8, "q0.ptp", &[]);
    let e = merge(&["q0.ptp", "p0.ptp", "p1.ptp", "p2.ptp", "p3.ptp"]);
    assert!(e.contains("overlapping parts") && e.contains("q0.ptp") && e.contains("p0.ptp"), "{e}");
    // A gap between finer parts: 0/8 alone cannot stand for 0/4.
    let e = merge(&["q0.ptp", "p1.ptp", "p2.ptp", "p3.ptp"]);
    assert!(e.contains("incomplete set") && e.contains("samples [1, 2)"), "{e}");
    // ...but 0/8 and 1/8 together can: the set covers every sample once.
    part(1, 8, "q1.ptp", &[]);
    ok(&d, &["merge", "q0.ptp", "q1.ptp", "p1.ptp", "p2.ptp", "p3.ptp", "-f", "mixed.png"]);
    // Another render's part: the message names what differs.
    part(2, 4, "seed.ptp", &["--seed", "9"]);
    let e = merge(&["p0.ptp", "p1.ptp", "seed.ptp", "p3.ptp"]);
    assert!(e.contains("not parts of the same render") && e.contains("seed (0 vs 9)"), "{e}");
    part(1, 2, "tiles.ptp", &["--split", "tiles"]);
    let e = merge(&["p0.ptp", "p1.ptp", "tiles.ptp", "p3.ptp"]);
    assert!(e.contains("split (samples vs tiles)"), "{e}");
    // Damaged, foreign and absent files.
    let bytes = std::fs::read(d.join("p3.ptp")).unwrap();
    std::fs::write(d.join("cut.ptp"), &bytes[..bytes.len() - 100]).unwrap();
    let e = merge(&["p0.ptp", "p1.ptp", "p2.ptp", "cut.ptp"]);
    assert!(e.contains("cut.ptp") && e.contains("cut short"), "{e}");
    std::fs::write(d.join("foreign.ptp"), b"hello\n").unwrap();
    let e = merge(&["p0.ptp", "foreign.ptp"]);
    assert!(e.contains("foreign.ptp: not a pathtracer partial"), "{e}");
    let e = merge(&["p0.ptp", "absent.ptp"]);
    assert!(e.contains("absent.ptp: cannot read"), "{e}");
    // No refused merge wrote anything; the complete set does.
    assert!(!d.join("out.png").exists() && !d.join("out.exr").exists());
    ok(&d, &["merge", "p3.ptp", "p2.ptp", "p1.ptp", "p0.ptp", "-f", "out.png"]);
    // Without -a no rate image: every pixel took -s samples.
    assert!(d.join("out.png").exists() && !d.join("out_rate.png").exists());
    let leftovers: Vec<_> = std::fs::read_dir(&d).unwrap().filter_map(|e| e.ok()).filter(|e| e.file_name().to_string_lossy().contains(".partial-")).collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
}

/// Damage after writing: a bit flipped in a part's header or in its pixel
/// records makes `merge` refuse the set naming that part, and write nothing;
/// `verify` names every damaged part and passes the intact ones; an old
/// (version 1) partial is refused as such.
#[test]
fn damaged_partials_are_named_and_nothing_is_written() {
    let d = scratch("damaged");
    let args = ["-r", "40", "24", "-s", "4", "-m", "2", "--seed", "4"];
    for i in 0..2 {
        let p = format!("{i}/2");
        let file = format!("p{i}.ptp");
        let mut a: Vec<&str> = args.to_vec();
        a.extend(["--part", &p, "--partial", &file]);
        ok(&d, &a);
    }
    let intact = std::fs::read(d.join("p1.ptp")).unwrap();
    let header_len = intact.windows(5).position(|w| w == b"\nend\n").unwrap() + 5;
    let seed_line = intact.windows(5).position(|w| w == b"seed ").unwrap();
    for (what, offset, expect) in [
        ("a setting", seed_line + 5, "header damaged (checksum mismatch)"),
        ("a record's sample count", header_len + 1, "records damaged (checksum mismatch)"),
        ("the last record's Σx²", intact.len() - 3, "records damaged (checksum mismatch)"),
    ] {
        let mut b = intact.clone();
        b[offset] ^= 0x10;
        std::fs::write(d.join("p1.ptp"), &b).unwrap();
        let e = refused(&d, &["merge", "p0.ptp", "p1.ptp", "-f", "out.png", "--exr", "out.exr"]);
        assert!(e.contains(&format!("p1.ptp: {expect}")), "{what}: {e}");
        assert!(!d.join("out.png").exists() && !d.join("out_rate.png").exists() && !d.join("out.exr").exists(), "{what}: a refused merge wrote an image");
        let v = pathtracer(&d, &["verify", "p0.ptp", "p1.ptp"]);
        let (out, err) = (String::from_utf8_lossy(&v.stdout), String::from_utf8_lossy(&v.stderr));
        assert!(!v.status.success(), "{what}: verify passed a damaged part");
        assert!(out.contains("p0.ptp: ok (part 0/2") && !out.contains("p1.ptp: ok"), "{what}: {out}");
        assert!(err.contains(&format!("p1.ptp: {expect}")) && err.contains("1 of 2 partials failed the check"), "{what}: {err}");
    }
    // A version 1 partial: refused with the reason, not as damage.
    let mut old = intact.clone();
    old[..20].copy_from_slice(b"pathtracer-partial 1");
    std::fs::write(d.join("p1.ptp"), &old).unwrap();
    let e = refused(&d, &["merge", "p0.ptp", "p1.ptp", "-f", "out.png"]);
    assert!(e.contains("p1.ptp: a version 1 partial (no checksums)"), "{e}");
    std::fs::write(d.join("p1.ptp"), &intact).unwrap();
    let v = ok(&d, &["verify", "p0.ptp", "p1.ptp"]);
    assert_eq!(String::from_utf8_lossy(&v.stdout).matches(": ok (part").count(), 2);
    ok(&d, &["merge", "p0.ptp", "p1.ptp", "-f", "out.png"]);
}

#[test]
fn bad_part_flags_are_refused() {
    let d = scratch("flags");
    let e = refused(&d, &["-s", "4", "--part", "0/2"]);
    assert!(e.contains("--partial"), "{e}");
    for bad in ["2/2", "-1/2", "0/0", "a/b", "3"] {
        let e = refused(&d, &["-s", "4", "--part", bad, "--partial", "x.ptp"]);
        assert!(e.contains("expected I/N"), "{bad}: {e}");
    }
    let e = refused(&d, &["-s", "4", "--part", "0/2", "--partial", "x.ptp", "-f", "a.png"]);
    assert!(e.contains("-f with --part"), "{e}");
    let e = refused(&d, &["-s", "4", "--part", "0/8", "--partial", "x.ptp"]);
    assert!(e.contains("N <= the samples per pixel (4)"), "{e}");
    let e = refused(&d, &["-s", "16", "-a", "4", "0.1", "--part", "0/2", "--partial", "x.ptp", "--split", "samples"]);
    assert!(e.contains("splits by tiles"), "{e}");
    let e = refused(&d, &["-r", "64", "32", "--part", "0/3", "--partial", "x.ptp", "--split", "tiles"]);
    assert!(e.contains("number of 32x32 tiles (2)"), "{e}");
    let e = refused(&d, &["merge", "-f", "a.png"]);
    assert!(e.contains("PARTIAL"), "{e}");
    assert!(!d.join("x.ptp").exists());
}
