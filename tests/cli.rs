//! Whole-program behaviour of the `pathtracer` binary.

mod common;

use pathtracer::image_io::read_exr;
use std::path::Path;
use std::process::{Command, Output};

fn scratch(name: &str) -> common::Scratch {
    common::Scratch::new("cli", name)
}

fn run(dir: &Path, args: &[&str]) -> Output {
    let out = Command::new(env!("CARGO_BIN_EXE_pathtracer")).args(args).current_dir(dir).env("CI", "true").output().unwrap();
    assert!(
        out.status.success(),
        "pathtracer {args:?} failed: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

#[test]
fn no_arguments_renders_the_builtin_scene_into_the_current_directory() {
    let d = scratch("default");
    let out = run(&d, &[]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    // Notices go to standard error, the summary line to standard output.
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("merged area light 'Area'") && !stdout.contains("merged area light"), "{stdout}{stderr}");
    let png = d.join("CBspheres_lambertian.png");
    assert!(png.exists(), "no image written; stdout: {stdout}");
    assert!(stdout.contains("wrote CBspheres_lambertian.png"), "{stdout}");
    for field in ["primitives", "backend native", "spatial splits", "BVH build", "render", "rays", "Mrays/s"] {
        assert!(stdout.contains(field), "summary lacks '{field}': {stdout}");
    }
    let img = image::open(&png).unwrap().to_rgba8();
    assert_eq!(img.dimensions(), (800, 600));
    // The box fills the middle of the frame; the corners look past it (black).
    assert_ne!(img.get_pixel(400, 300).0, [0, 0, 0, 255]);
    assert_eq!(img.get_pixel(0, 0).0, [0, 0, 0, 255]);
}

fn render_exr(dir: &Path, name: &str, args: &[&str]) -> pathtracer::image_io::Rgb {
    let exr = dir.join(format!("{name}.exr"));
    let png = dir.join(format!("{name}.png"));
    let mut all: Vec<&str> = args.to_vec();
    all.extend(["--exr", exr.to_str().unwrap(), "-f", png.to_str().unwrap()]);
    run(dir, &all);
    read_exr(&exr).unwrap()
}

#[test]
fn cow_normals_are_identical_with_and_without_the_bvh() {
    let d = scratch("cow");
    let cow = common::scene_path("meshedit", "cow");
    let cow = cow.to_str().unwrap();
    let native = render_exr(&d, "native", &["--integrator", "normals", "-r", "480", "360", "--backend", "native", cow]);
    let brute = render_exr(&d, "brute", &["--integrator", "normals", "-r", "480", "360", "--backend", "brute", cow]);
    assert_eq!((native.width, native.height), (480, 360));
    let lit = native.pixels.iter().filter(|p| p.length() > 0.0).count();
    assert!(lit > 20_000, "cow covers only {lit} pixels");
    assert!(native == brute, "native and brute normal images differ");
}

#[test]
fn same_seed_same_image_at_any_thread_count() {
    let d = scratch("threads");
    let a = render_exr(&d, "t1", &["-t", "1", "-s", "4", "-r", "160", "120", "--seed", "9"]);
    let b = render_exr(&d, "t2", &["-t", "2", "-s", "4", "-r", "160", "120", "--seed", "9"]);
    assert!(a == b, "-t 1 and -t 2 differ");
    let c = render_exr(&d, "seed", &["-t", "2", "-s", "4", "-r", "160", "120", "--seed", "10"]);
    assert!(a != c, "the seed changes nothing");
}

#[test]
fn cell_is_a_crop_of_the_full_frame_and_no_rate_image_without_adaptive_sampling() {
    let d = scratch("cell");
    let full = render_exr(&d, "full", &["-r", "64", "48"]);
    // CS184 frame coordinates: y counts up from the bottom row.
    let cell = render_exr(&d, "cell", &["-r", "64", "48", "-p", "10", "5", "20", "16"]);
    assert_eq!((cell.width, cell.height), (20, 16));
    for y in 0..16 {
        for x in 0..20 {
            // Cell row y (top first) is frame row 5 + 15 - y from the bottom,
            // which is image row 47 - (20 - y) from the top.
            assert_eq!(cell.get(x, y), full.get(10 + x, 47 - (5 + 15 - y)), "pixel {x},{y}");
        }
    }
    assert!(!d.join("cell_rate.png").exists(), "a rate image without -a");
}

#[test]
fn camera_settings_round_trip_through_a_file() {
    let d = scratch("camera");
    let cam = d.join("cam.txt");
    let a = render_exr(&d, "a", &["-r", "64", "48", "--write-camera", cam.to_str().unwrap()]);
    let text = std::fs::read_to_string(&cam).unwrap();
    assert_eq!(text.lines().count(), 6, "{text}");
    let b = render_exr(&d, "b", &["-r", "64", "48", "-c", cam.to_str().unwrap()]);
    assert!(a == b, "rendering with the written camera file changed the image");
}

#[test]
fn lighting_flags_are_refused_with_normal_shading() {
    let d = scratch("normals-flags");
    let out = Command::new(env!("CARGO_BIN_EXE_pathtracer")).args(["--integrator", "normals", "-m", "3"]).current_dir(&d).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("-m") && err.contains("no effect"), "{err}");
}

#[test]
fn unsupported_materials_are_refused_by_name() {
    // Rough glass is parsed but not modelled: refused, naming the material.
    let d = scratch("rough-glass");
    let text = std::fs::read_to_string(common::scene_path("sky", "CBspheres")).unwrap();
    assert!(text.contains("<roughness>0</roughness>"), "CBspheres.dae changed: no smooth glass to roughen");
    let scene = d.join("rough.dae");
    std::fs::write(&scene, text.replace("<roughness>0</roughness>", "<roughness>0.2</roughness>")).unwrap();
    let out_dir = d.join("out");
    std::fs::create_dir_all(&out_dir).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_pathtracer")).arg(&scene).args(["-r", "8", "8"]).current_dir(&out_dir).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("glass") && err.contains("roughness 0.2"), "{err}");
    assert!(err.contains("rough.dae") && err.trim_end().lines().count() == 1, "{err}");
    assert!(std::fs::read_dir(&out_dir).unwrap().next().is_none(), "output written");
}

#[test]
fn path_tracing_is_identical_across_thread_counts_and_backends() {
    let d = scratch("pt-determinism");
    identical_everywhere(&d, "builtin", &["-s", "4", "-m", "3", "-r", "64", "48", "--seed", "3"]);
    // Glass meshes, an environment map and a thin lens: more draws per path.
    let gems = common::scene_path("sky", "CBgems");
    let env = d.join("sky.exr");
    let texels = (0..128).map(|i| glam::Vec3::new(0.2 + (i % 16) as f32 * 0.1, 0.5, if i == 37 { 40.0 } else { 0.3 })).collect();
    pathtracer::image_io::write_exr(&env, &pathtracer::image_io::Rgb { width: 16, height: 8, pixels: texels }).unwrap();
    identical_everywhere(&d, "gems", &[gems.to_str().unwrap(), "-e", env.to_str().unwrap(), "-b", "0.05", "-d", "4", "-s", "4", "-m", "6", "-r", "64", "48", "--keep-fov", "--seed", "3"]);
}

fn identical_everywhere(d: &Path, tag: &str, base: &[&str]) {
    let with = |extra: &[&str]| -> Vec<String> { base.iter().chain(extra).map(|s| s.to_string()).collect() };
    let args_ref = with(&["-t", "1", "--backend", "native"]);
    let reference = render_exr(d, &format!("{tag}_ref"), &args_ref.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(reference.pixels.iter().all(|p| p.is_finite()));
    assert!(reference.pixels.iter().any(|p| *p != glam::Vec3::ZERO), "{tag}: black image");
    let mut variants = vec![("t2", vec!["-t", "2", "--backend", "native"]), ("brute", vec!["-t", "2", "--backend", "brute"])];
    for kind in common::embree_backends() {
        let name: &'static str = if kind == pathtracer::accel::BackendKind::Embree3 { "embree3" } else { "embree4" };
        variants.push((name, vec!["-t", "2", "--backend", name]));
    }
    for (name, extra) in variants {
        let args = with(&extra);
        let img = render_exr(d, &format!("{tag}_{name}"), &args.iter().map(String::as_str).collect::<Vec<_>>());
        let differing = img.pixels.iter().zip(&reference.pixels).filter(|(a, b)| a != b).count();
        assert_eq!(differing, 0, "{tag} {name}: {differing} pixels differ from -t 1 native");
    }
}

#[test]
fn adaptive_sampling_writes_a_rate_image_and_stops_early() {
    let d = scratch("adaptive");
    for (name, extra) in [("cs184", vec![]), ("pilot", vec!["--adaptive-pilot"])] {
        let png = d.join(format!("{name}.png"));
        let var = d.join(format!("{name}_var.exr"));
        // A cell over the box's top-left corner: background, wall and ceiling.
        let mut args = vec!["-s", "256", "-a", "32", "0.05", "-m", "2", "-p", "140", "420", "64", "48", "-f", png.to_str().unwrap(), "--variance-exr", var.to_str().unwrap()];
        args.extend(extra);
        let out = run(&d, &args);
        let rate = image::open(d.join(format!("{name}_rate.png"))).unwrap().to_rgba8();
        assert_eq!(rate.dimensions(), (64, 48));
        let red = rate.pixels().filter(|p| p.0 == [255, 0, 0, 255]).count();
        let blueish = rate.pixels().filter(|p| p.0[2] > 0).count();
        // Background pixels (black, sigma = 0) stop after the first batch;
        // the noisy box needs more, some all 256.
        assert!(blueish > 0 && red < 64 * 48, "{name}: rate image has no early stops: {}", String::from_utf8_lossy(&out.stdout));
        assert!(pathtracer::image_io::read_exr(&var).unwrap().pixels.iter().all(|p| p.is_finite() && p.min_element() >= 0.0));
    }
}

#[test]
fn adaptive_batches_are_powers_of_two_with_sobol() {
    // Sobol points are nets in aligned power-of-two blocks: -a 48 checks every
    // 64 samples (and says so), so every pixel keeps a multiple of 64; with
    // independent numbers the batch stays 48.
    let d = scratch("adaptive_pow2");
    for (sampler, batch) in [("sobol", 64u64), ("independent", 48)] {
        let png = d.join(format!("{sampler}.png"));
        let out = run(&d, &["-s", "192", "-a", "48", "0.05", "-m", "1", "-r", "32", "24", "--sampler", sampler, "-f", png.to_str().unwrap()]);
        let text = String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
        assert_eq!(text.contains("-a 48: Sobol samples are stratified in blocks of powers of two; checking every 64 samples"), sampler == "sobol", "{text}");
        let kept: u64 = text.split(" samples kept").next().unwrap().rsplit(' ').next().unwrap().parse().unwrap();
        assert!(kept > 0 && kept % batch == 0, "{sampler}: {kept} samples kept is not a multiple of {batch}");
        assert!(kept < 192 * 32 * 24, "{sampler}: no pixel stopped early");
    }
}

#[test]
fn depth_and_object_id_images_describe_the_first_hit() {
    // One ray through each pixel centre: every object-id pixel is black or one exported
    // id colour, depth is positive exactly where something was hit, and on the back wall it
    // is the distance along the ray (not the planar z), from the exported camera.
    let d = scratch("aov");
    let view = ["-r", "64", "48", "--keep-fov"];
    run(&d, &["export", view[0], view[1], view[2], view[3], "--out", d.join("scene").to_str().unwrap()]);
    let spec: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(d.join("scene/scene.json")).unwrap()).unwrap();
    let v3 = |v: &serde_json::Value| glam::Vec3::new(v[0].as_f64().unwrap() as f32, v[1].as_f64().unwrap() as f32, v[2].as_f64().unwrap() as f32);
    let colours: Vec<(String, glam::Vec3)> = spec["shapes"].as_array().unwrap().iter().map(|s| (s["name"].as_str().unwrap().to_string(), v3(&s["id_colour"]))).collect();
    let ids = render_exr(&d, "ids", &["--integrator", "object-id", "-s", "1", view[0], view[1], view[2], view[3]]);
    let depth = render_exr(&d, "depth", &["--integrator", "depth", "-s", "1", view[0], view[1], view[2], view[3]]);
    for (p, z) in ids.pixels.iter().zip(&depth.pixels) {
        assert!(*p == glam::Vec3::ZERO || colours.iter().any(|(_, c)| c == p), "pixel colour {p} is no object's id colour");
        assert_eq!(*p == glam::Vec3::ZERO, z.x == 0.0, "depth {z} where the id is {p}");
    }
    let back = colours.iter().find(|(n, _)| n == "backWall").unwrap().1;
    let cam = &spec["camera"];
    let (o, right, up, fwd) = (v3(&cam["origin"]), v3(&cam["right"]), v3(&cam["up"]), v3(&cam["forward"]));
    let tx = (cam["fov_x_deg"].as_f64().unwrap().to_radians() / 2.0).tan() as f32;
    let ty = tx * 48.0 / 64.0;
    // The back wall's plane from the exported mesh.
    let shape = spec["shapes"].as_array().unwrap().iter().find(|s| s["name"] == "backWall").unwrap();
    let obj = std::fs::read_to_string(d.join("scene").join(shape["file"].as_str().unwrap())).unwrap();
    let zb: f32 = obj.lines().find(|l| l.starts_with("v ")).unwrap().split_whitespace().nth(3).unwrap().parse().unwrap();
    let mut checked = 0;
    for y in 0..48 {
        for x in 0..64 {
            if ids.pixels[y * 64 + x] != back {
                continue;
            }
            let dir = (fwd + right * (((x as f32 + 0.5) / 64.0 * 2.0 - 1.0) * tx) + up * ((1.0 - (y as f32 + 0.5) / 48.0 * 2.0) * ty)).normalize();
            let expected = (zb - o.z) / dir.z;
            let got = depth.pixels[y * 64 + x].x;
            assert!((got - expected).abs() <= 1e-5 * expected, "pixel ({x}, {y}): depth {got}, expected {expected}");
            checked += 1;
        }
    }
    assert!(checked > 100, "only {checked} back-wall pixels");
}

/// `bench --resume DIR`: a run cut short leaves its finished parts in DIR;
/// the next run of the same binary and options takes them (its rows are the
/// first run's, to the last digit) and measures only the rest; other
/// options, an edited scene file, or a damaged file, are measured again,
/// saying why.
#[test]
fn bench_resume_takes_the_parts_a_cut_run_kept() {
    let d = scratch("bench-resume");
    // A copy of cow, to edit later.
    let cow_file = d.join("cow.dae");
    std::fs::copy(common::scene_path("meshedit", "cow"), &cow_file).unwrap();
    let cow = cow_file.to_str().unwrap();
    let opts = ["bench", "--rays", "2048", "--no-render", "--no-peers", "--backends", "native,brute", "--resume", "kept"];
    let bench = |scenes: &[&str], more: &[&str], csv: &str| {
        let out = run(&d, &[&opts[..], scenes, more, &["--csv", csv]].concat());
        let rows: Vec<String> = std::fs::read_to_string(d.join(csv)).unwrap().lines().skip(1).map(str::to_string).collect();
        (String::from_utf8_lossy(&out.stderr).into_owned(), rows)
    };
    let of = |rows: &[String], scene: &str| -> Vec<String> { rows.iter().filter(|r| r.starts_with(&format!("{scene},"))).cloned().collect() };

    // Cut short after cow: its part is kept.
    let (err, first) = bench(&[cow], &[], "a.csv");
    assert!(!err.contains("taken from"), "{err}");
    assert_eq!(std::fs::read_dir(d.join("kept")).unwrap().count(), 1);
    let cow_rows = of(&first, "cow");
    assert_eq!(cow_rows.len(), 6 * 2 * if std::thread::available_parallelism().map_or(1, |n| n.get()) > 1 { 2 } else { 1 }, "{first:?}");

    // Run again with the rest: cow taken, to the last digit; the sphere measured.
    let (err, second) = bench(&[cow, "sphere:2000"], &[], "b.csv");
    assert!(err.contains(&format!("bench: {cow}: measured by an earlier run, taken from kept")), "{err}");
    assert_eq!(of(&second, "cow"), cow_rows);
    assert_eq!(of(&second, "sphere_2000").len(), cow_rows.len(), "{second:?}");

    // Other options: measured again (throughputs never repeat to four decimals).
    let (err, third) = bench(&[cow], &["--passes", "2"], "c.csv");
    assert!(err.contains("measured by another build, machine or options, or from other scene files; measuring"), "{err}");
    assert_ne!(of(&third, "cow"), cow_rows);
    let (err, _) = bench(&[cow], &["--passes", "2"], "c2.csv");
    assert!(err.contains("taken from kept"), "{err}");

    // The scene file edited (a comment after its root element): measured again.
    let mut text = std::fs::read_to_string(&cow_file).unwrap();
    text.push_str("<!-- edited -->\n");
    std::fs::write(&cow_file, text).unwrap();
    let (err, _) = bench(&[cow], &["--passes", "2"], "c3.csv");
    assert!(err.contains("from other scene files; measuring"), "{err}");

    // A damaged part: measured again, not trusted, and kept anew.
    for f in std::fs::read_dir(d.join("kept")).unwrap() {
        let f = f.unwrap().path();
        let text = std::fs::read_to_string(&f).unwrap();
        std::fs::write(&f, &text[..text.len() / 2]).unwrap();
    }
    let (err, _) = bench(&[cow], &["--passes", "2"], "d.csv");
    assert!(err.contains("damaged"), "{err}");
    let (err, _) = bench(&[cow], &["--passes", "2"], "e.csv");
    assert!(err.contains("taken from kept"), "{err}");
}

/// `pathtracer bench` writes the CSV and Markdown the documentation's tables
/// are generated from: one CSV row per scene, ray kind, thread count and backend, and the
/// native ÷ Embree and SAH tables when Embree is built in. Checks the shape
/// of the output, not speeds.
#[test]
fn bench_writes_csv_and_markdown_tables() {
    let d = scratch("bench");
    let cow = common::scene_path("meshedit", "cow");
    let out = run(&d, &["bench", cow.to_str().unwrap(), "--rays", "4096", "--no-render", "--csv", "b.csv", "--markdown", "b.md"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let csv = std::fs::read_to_string(d.join("b.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("scene,rays,threads,backend,mrays_per_s"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    let embrees: Vec<String> = common::embree_backends().iter().map(|k| k.to_string()).collect();
    let embree = !embrees.is_empty();
    // Every contender: ours, each Embree at both qualities, the peers built in.
    let mut backends: Vec<String> = vec!["native".into()];
    for e in &embrees {
        backends.push(e.clone());
        backends.push(format!("{e}-high"));
    }
    if cfg!(feature = "peers") {
        backends.push("obvhs".into());
        backends.push("tinybvh".into());
        backends.push("tinybvh-hq".into());
    }
    backends.push("brute".into());
    let threads = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    let thread_counts = if threads > 1 { 2 } else { 1 };
    let kinds = ["camera", "shadow", "random", "random single", "diffuse", "diffuse single"];
    assert_eq!(rows.len(), kinds.len() * backends.len() * thread_counts, "{csv}");
    for b in &backends {
        for kind in kinds {
            let row = rows.iter().find(|r| r[0] == "cow" && r[1] == kind && r[3] == b.as_str() && r[2] == "1");
            let row = row.unwrap_or_else(|| panic!("no 1-thread {kind} row for {b}: {csv}"));
            let m: f64 = row[4].parse().unwrap();
            assert!(m.is_finite() && m > 0.0, "{row:?}");
        }
    }
    let md = std::fs::read_to_string(d.join("b.md")).unwrap();
    assert!(stdout.contains("| cow | 5856 | native |"), "{stdout}");
    assert!(md.contains("| cow | 5856 | native |") && md.contains("| scene | backend | nodes | leaves | total |"), "{md}");
    if embree {
        for e in &embrees {
            assert!(md.contains(&format!("native ÷ {e} throughput")) && md.contains(&format!("native ÷ {e}-high throughput")), "{md}");
        }
        // Each Embree's own SAH statistics were read back for the comparison.
        let sah = md.lines().find(|l| l.starts_with("| cow | native | ")).unwrap();
        let cells: Vec<&str> = sah.split('|').map(str::trim).collect();
        for (e, col) in [("embree3", 7), ("embree4", 9)] {
            if embrees.iter().any(|x| x == e) {
                let ratio: f64 = cells[col].parse().unwrap_or_else(|_| panic!("no native ÷ {e} SAH ratio: {sah}"));
                assert!(ratio > 0.5 && ratio < 2.0, "{sah}");
            }
        }
        // Each Embree's batch calls were timed, and native against the
        // fastest per ray kind, each cell naming the call.
        let header = md.lines().find(|l| l.starts_with("| scene | embree | rays |")).unwrap_or_else(|| panic!("no batch-call table: {md}"));
        let columns: Vec<&str> = header.split(" | ").collect();
        for e in &embrees {
            assert!(md.contains(&format!("| cow | {e} | camera |")), "no batch-call row for {e}: {md}");
            // Every row has the header's cells; Embree 4 has no streams.
            for row in md.lines().filter(|l| l.starts_with(&format!("| cow | {e} | ")) && !l.contains(" i) |")) {
                let cells: Vec<&str> = row.split(" | ").collect();
                assert_eq!(cells.len(), columns.len(), "{header}\n{row}");
                // Dashes: Embree 4's streams, and the coherent calls for
                // random and diffuse rays, which have none.
                let incoherent_rays = row.contains("| random |") || row.contains("| diffuse |");
                for (name, cell) in columns.iter().zip(&cells).skip(3) {
                    let none = (name.starts_with("stream") && e == "embree4") || (name.ends_with(" c") && incoherent_rays);
                    assert_eq!(*cell == "–", none, "{name}: {row}");
                }
            }
            let row = md.lines().find(|l| l.starts_with(&format!("| cow | {e} | ")) && l.contains(" i) |")).unwrap_or_else(|| panic!("no native ÷ fastest call row for {e}: {md}"));
            let cells: Vec<&str> = row.split(" | ").skip(2).collect();
            assert_eq!(cells.len(), 4, "{row}");
            for cell in cells {
                let (ratio, call) = cell.split_once(" (").unwrap_or_else(|| panic!("{row}"));
                assert!(ratio.parse::<f64>().is_ok_and(|r| r > 0.0 && r.is_finite()), "{row}");
                assert!(["loop", "stream", "packet4", "packet8", "packet16"].iter().any(|c| call.starts_with(c)), "{row}");
            }
        }
    } else {
        eprintln!("note: Embree is not built in; the bench's Embree columns were not checked");
    }
    if cfg!(feature = "peers") {
        assert!(md.contains("native ÷ obvhs throughput") && md.contains("native ÷ tinybvh throughput"), "{md}");
    } else {
        eprintln!("note: built without --features peers; the obvhs rows were not checked");
    }
}

#[test]
fn lens_zero_is_the_pinhole_bit_for_bit_and_the_camera_file_carries_the_lens() {
    let d = scratch("lens");
    let base = ["-s", "4", "-m", "2", "-r", "48", "36", "--keep-fov", "--seed", "5"];
    fn with<'a>(base: &[&'a str], extra: &[&'a str]) -> Vec<&'a str> {
        base.iter().chain(extra).copied().collect()
    }
    let pinhole = render_exr(&d, "pinhole", &with(&base, &[]));
    let b0 = render_exr(&d, "b0", &with(&base, &["-b", "0", "-d", "3"]));
    assert!(pinhole == b0, "-b 0 changed the image");
    let lens = render_exr(&d, "lens", &with(&base, &["-b", "0.2", "-d", "4.5"]));
    assert!(lens != pinhole, "-b 0.2 left the image unchanged");
    // The written camera file ends with CS184's "focal_distance lens_radius" line,
    // and rendering with it (-c) gives the same image.
    let cam = d.join("lens.cam");
    let _ = render_exr(&d, "lens2", &with(&base, &["-b", "0.2", "-d", "4.5", "--write-camera", cam.to_str().unwrap()]));
    let text = std::fs::read_to_string(&cam).unwrap();
    assert_eq!(text.lines().last().unwrap().trim(), "4.5 0.2", "{text}");
    let again = render_exr(&d, "lens3", &with(&base, &["-c", cam.to_str().unwrap()]));
    assert!(again == lens, "rendering with the camera file changed the image");
    for (flags, needle) in [(["-b", "-1"], "-b -1"), (["-d", "0"], "-d 0"), (["-b", "nan"], "-b")] {
        let out = Command::new(env!("CARGO_BIN_EXE_pathtracer")).args(flags).args(["-r", "8", "8"]).current_dir(&d).output().unwrap();
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle) && err.trim_end().lines().count() == 1, "{err}");
    }
}

/// A small latitude-longitude map written by the test itself.
fn write_env(path: &Path, value: glam::Vec3) {
    let img = pathtracer::image_io::Rgb { width: 16, height: 8, pixels: vec![value; 128] };
    pathtracer::image_io::write_exr(path, &img).unwrap();
}

#[test]
fn environment_light_lights_an_unlit_scene_and_bad_maps_are_refused() {
    let d = scratch("env");
    let unlit = common::scene_path("sky", "bunny_unlit");
    let unlit = unlit.to_str().unwrap();
    // Without -e: black, with one warning line saying there is no light.
    let out = run(&d, &[unlit, "-r", "32", "24", "--keep-fov", "-f", "black.png", "--exr", "black.exr"]);
    let text = String::from_utf8_lossy(&out.stderr);
    assert_eq!(text.lines().filter(|l| l.contains("warning")).count(), 1, "{text}");
    assert!(text.contains("no light"), "{text}");
    assert!(read_exr(&d.join("black.exr")).unwrap().pixels.iter().all(|p| *p == glam::Vec3::ZERO));
    // With a uniform map of radiance 1: lit; every escaping camera ray sees exactly 1.
    let env = d.join("white.exr");
    write_env(&env, glam::Vec3::ONE);
    let lit = render_exr(&d, "lit", &[unlit, "-e", env.to_str().unwrap(), "-r", "32", "24", "--keep-fov", "-s", "4", "-m", "2"]);
    assert!(lit.pixels.contains(&glam::Vec3::ONE), "no pixel sees the environment");
    assert!(lit.pixels.iter().all(|p| p.is_finite() && p.min_element() >= 0.0));
    // A missing map and a file that is not OpenEXR: one line naming the file, no output.
    let junk = d.join("junk.exr");
    std::fs::write(&junk, b"not an exr").unwrap();
    for (file, needle) in [(d.join("missing.exr"), "not found"), (junk, "OpenEXR")] {
        let out_dir = d.join("bad");
        let _ = std::fs::remove_dir_all(&out_dir);
        std::fs::create_dir_all(&out_dir).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_pathtracer")).args([unlit, "-e", file.to_str().unwrap(), "-r", "8", "8"]).current_dir(&out_dir).output().unwrap();
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(file.file_name().unwrap().to_str().unwrap()) && err.contains(needle) && err.trim_end().lines().count() == 1, "{err}");
        assert!(std::fs::read_dir(&out_dir).unwrap().next().is_none(), "output written");
    }
}

#[test]
fn shared_dwab_environment_maps_load() {
    // The CC0 maps in scenes/envmaps are DWAB-compressed (lossy, with a few
    // negative texels from ringing, which we clamp to 0).
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/envmaps");
    assert!(dir.join("studio.exr").exists(), "test data missing: {}", dir.display());
    for name in ["studio.exr", "courtyard.exr"] {
        let env = pathtracer::light::EnvMap::load(&dir.join(name)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((env.width, env.height), (1024, 512), "{name}");
        assert!(env.texels.iter().all(|t| t.is_finite() && t.min_element() >= 0.0));
        assert!(!env.is_black());
    }
}

/// A run that must fail: its exit status, and its standard error after
/// checking that it is one line, without a panic, hint or usage block.
fn mistake(dir: &Path, args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_pathtracer")).args(args).current_dir(dir).env("CI", "true").output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(!out.status.success(), "pathtracer {args:?} should have failed");
    assert_eq!(err.trim_end().lines().count(), 1, "pathtracer {args:?}: not one line: {err}");
    assert!(err.starts_with("pathtracer: error: "), "{err}");
    for noise in ["panicked", "For more information", "tip:", "Usage:", "-- -1"] {
        assert!(!err.contains(noise), "pathtracer {args:?}: '{noise}' in {err}");
    }
    assert_eq!(err.matches("--help").count(), err.contains("--help") as usize, "the hint twice: {err}");
    (out.status.code().unwrap(), err)
}

#[test]
fn each_command_line_mistake_gets_one_line_saying_what_is_accepted_and_exit_status_2() {
    let d = scratch("mistakes");
    let cases: &[(&[&str], &[&str])] = &[
        (&["-s", "abc"], &["-s abc", "whole number"]),
        (&["--backend", "foo"], &["--backend foo", "native", "embree4", "brute"]),
        (&["-m", "-1"], &["-m -1", "0 or more"]),
        (&["-s", "99999999999"], &["-s 99999999999", "too large"]),
        (&["merg", "p0.ptp", "p1.ptp", "-f", "x.png"], &["'merg' is not a command", "did you mean 'merge'?"]),
        (&["benhc"], &["did you mean 'bench'?"]),
        (&["nothing"], &["'nothing' is neither a command", ".dae", ".obj", ".ply"]),
        (&["--backnd", "native"], &["unknown option '--backnd'", "did you mean '--backend'?"]),
        (&["--integrator", "nrmals"], &["--integrator nrmals", "did you mean 'normals'?"]),
        (&["-r", "8"], &["-r", "2 values"]),
        (&["-t", "0"], &["-t 0", "at least 1"]),
        (&["-s", "0"], &["-s 0", "between 1 and"]),
        (&["-f", "out.bmp"], &["out.bmp", "'.bmp'", ".png, .jpg or .jpeg"]),
        (&["-f", "out"], &["no file extension", ".png, .jpg or .jpeg"]),
        (&["--exr", "out.png"], &["--exr out.png", ".exr"]),
        (&["--integrator", "normals", "-m", "3"], &["-m", "no effect"]),
    ];
    for (args, needles) in cases {
        let (code, err) = mistake(&d, args);
        assert_eq!(code, 2, "pathtracer {args:?}: {err}");
        for n in *needles {
            assert!(err.contains(n), "pathtracer {args:?}: '{n}' not in {err}");
        }
    }
    assert!(std::fs::read_dir(&*d).unwrap().next().is_none(), "a refused command wrote a file");
}

#[test]
fn a_scene_with_no_or_an_unknown_extension_is_answered_with_the_formats_read() {
    let d = scratch("scene-ext");
    let text = std::fs::read_to_string(common::scene_path("sky", "CBempty")).unwrap();
    for name in ["noext", "scene.abc"] {
        std::fs::write(d.join(name), &text).unwrap();
        let (code, err) = mistake(&d, &[name, "-r", "8", "8"]);
        assert_eq!(code, 1, "{err}");
        assert!(err.contains(name) && err.contains(".dae") && err.contains(".obj") && err.contains(".ply"), "{err}");
        assert!(!err.contains("''"), "{err}");
    }
}

#[test]
fn the_image_format_follows_the_extension_and_the_rate_image_only_adaptive_sampling() {
    let d = scratch("formats");
    let scene = common::scene_path("sky", "CBempty");
    let scene = scene.to_str().unwrap();
    run(&d, &[scene, "-r", "16", "12", "-f", "a.jpg"]);
    run(&d, &[scene, "-r", "16", "12", "-f", "b.JPEG"]);
    run(&d, &[scene, "-r", "16", "12", "-f", "c.png"]);
    assert_eq!(image::ImageFormat::from_path(d.join("a.jpg")).unwrap(), image::ImageFormat::Jpeg);
    assert_eq!(image::guess_format(&std::fs::read(d.join("a.jpg")).unwrap()).unwrap(), image::ImageFormat::Jpeg);
    assert_eq!(image::guess_format(&std::fs::read(d.join("b.JPEG")).unwrap()).unwrap(), image::ImageFormat::Jpeg);
    assert_eq!(image::guess_format(&std::fs::read(d.join("c.png")).unwrap()).unwrap(), image::ImageFormat::Png);
    for name in ["a_rate.png", "b_rate.png", "c_rate.png"] {
        assert!(!d.join(name).exists(), "{name} written without adaptive sampling");
    }
    run(&d, &[scene, "-r", "16", "12", "--integrator", "normals", "-f", "n.png"]);
    assert!(!d.join("n_rate.png").exists(), "normal shading wrote a rate image");
    run(&d, &[scene, "-r", "16", "12", "-s", "8", "-a", "2", "0.5", "-f", "ad.jpg"]);
    assert!(d.join("ad.jpg").exists() && d.join("ad_rate.png").exists());
}

#[test]
fn help_wraps_to_the_terminal_and_speaks_in_users_words() {
    for cols in [80usize, 100] {
        for args in [&["-h"][..], &["--help"], &["bench", "--help"], &["merge", "--help"], &["export", "--help"]] {
            let out = Command::new(env!("CARGO_BIN_EXE_pathtracer")).args(args).env("COLUMNS", cols.to_string()).output().unwrap();
            assert!(out.status.success());
            let text = String::from_utf8_lossy(&out.stdout);
            let wide: Vec<&str> = text.lines().filter(|l| l.chars().count() > cols).collect();
            assert!(wide.is_empty(), "{args:?} at {cols} columns: {} lines wider: {wide:?}", wide.len());
            assert!(!text.contains("::"), "{args:?} names a module: {text}");
        }
    }
}

#[test]
fn the_man_pages_have_a_synopsis_examples_exit_status_and_environment() {
    let d = scratch("man");
    run(&d, &["man", "--out", "."]);
    let root = std::fs::read_to_string(d.join("pathtracer.1")).unwrap();
    for section in [".SH SYNOPSIS", ".SH EXAMPLES", ".SH \"EXIT STATUS\"", ".SH ENVIRONMENT", ".SH \"SEE ALSO\"", "pathtracer\\-merge"] {
        let alt = section.replace('"', "");
        assert!(root.contains(section) || root.contains(&alt), "pathtracer.1 lacks {section}");
    }
    let synopsis = root.split(".SH SYNOPSIS").nth(1).unwrap().split(".SH").next().unwrap();
    assert!(synopsis.contains("OPTIONS") && synopsis.contains("SCENE") && synopsis.contains("COMMAND"), "{synopsis}");
    assert!(!synopsis.contains("\\-t \\fR]"), "a flag without its value: {synopsis}");
    let merge = std::fs::read_to_string(d.join("pathtracer-merge.1")).unwrap();
    let title = merge.lines().find(|l| l.starts_with(".TH")).unwrap();
    assert!(title.starts_with(".TH PATHTRACER-MERGE 1") && title.contains("pathtracer manual") && !title.contains('<'), "{title}");
    let synopsis = merge.split(".SH SYNOPSIS").nth(1).unwrap().split(".SH").next().unwrap();
    assert!(synopsis.contains("FILE") && synopsis.contains("PARTIAL"), "{synopsis}");
    for code in ["\\fB0\\fR", "\\fB1\\fR", "\\fB2\\fR"] {
        assert!(merge.contains(code), "exit status {code} missing from pathtracer-merge.1");
    }
    assert!(!root.contains(".SH EXTRA"));
}

#[test]
fn version_names_the_commit_the_binary_was_built_from() {
    let out = Command::new(env!("CARGO_BIN_EXE_pathtracer")).arg("--version").output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    let first = text.lines().next().unwrap();
    assert!(first.contains("(commit ") || first.contains("(built outside git)"), "{first}");
    let short = Command::new(env!("CARGO_BIN_EXE_pathtracer")).arg("-V").output().unwrap();
    assert!(String::from_utf8_lossy(&short.stdout).contains(first.trim_start_matches("pathtracer ")), "-V and --version disagree");
}
