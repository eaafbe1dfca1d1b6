//! The long fuzz run, and the corpus's generator (`pathtracer::app::fuzz`).
//!
//! ```sh
//! cargo run --release --example fuzz -- --cases 1000000            # every reader
//! cargo run --release --example fuzz -- --cases 100000 --kind ply-binary,exr --seed 7
//! cargo run --release --example fuzz -- --write-corpus tests/fuzz/corpus
//! cargo run --release --example fuzz -- --cases 1050000 --paste   # and the table into docs/reliability.md
//! ```
//!
//! Cases run in child processes of this program, `--chunk` cases each, so
//! that a crash (an abort, a stack overflow) is counted instead of ending
//! the run: the cases a dead child did not report are run again one per
//! child, and the one that dies is the crash. Prints counts by input kind
//! and outcome; every failing input is written to `--findings DIR` (default
//! `target/fuzz-findings`), named by kind, class, seed input and case, to be
//! made a regression test (`tests/fuzz/regressions/<kind>/`).

/// Every allocation counted per thread, so a case's memory is its own.
#[global_allocator]
static ALLOC: pathtracer::app::fuzz::alloc::CountingAlloc = pathtracer::app::fuzz::alloc::CountingAlloc::new();

use pathtracer::app::fuzz::{self, Kind, Outcome, Report};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

struct Args {
    cases: u64,
    first: u64,
    seed: u64,
    kinds: Vec<Kind>,
    workers: usize,
    hang_secs: f64,
    chunk: u64,
    corpus: PathBuf,
    findings: PathBuf,
    scratch: PathBuf,
    child: bool,
    show_refusals: usize,
    paste: bool,
    write_corpus: Option<PathBuf>,
}

fn usage(why: &str) -> ! {
    eprintln!("fuzz: {why}\nusage: fuzz [--cases N] [--seed S] [--kind K,K...] [--workers W] [--hang-secs T] [--chunk C] [--corpus DIR] [--findings DIR]\n       fuzz --write-corpus DIR\nkinds: {}", Kind::ALL.map(|k| k.name()).join(", "));
    std::process::exit(2)
}

fn parse_args() -> Args {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut a = Args {
        cases: 10_000,
        first: 0,
        seed: 1,
        kinds: Kind::ALL.to_vec(),
        workers: std::thread::available_parallelism().map_or(1, |n| n.get()),
        hang_secs: 10.0,
        chunk: 20_000,
        corpus: root.join("tests/fuzz/corpus"),
        findings: root.join("target/fuzz-findings"),
        scratch: std::env::temp_dir().join(format!("pathtracer-fuzz-{}", std::process::id())),
        child: false,
        show_refusals: 0,
        paste: false,
        write_corpus: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().unwrap_or_else(|| usage(&format!("{flag} needs a value")));
        let num = |v: String| v.parse::<u64>().unwrap_or_else(|_| usage(&format!("{flag}: '{v}' is not a whole number")));
        match flag.as_str() {
            "--cases" => a.cases = num(value()),
            "--first" => a.first = num(value()),
            "--seed" => a.seed = num(value()),
            "--workers" => a.workers = num(value()).max(1) as usize,
            "--chunk" => a.chunk = num(value()).max(1),
            "--hang-secs" => a.hang_secs = value().parse().unwrap_or_else(|_| usage("--hang-secs: not a number")),
            "--kind" => {
                a.kinds = value().split(',').map(|k| Kind::from_name(k).unwrap_or_else(|| usage(&format!("unknown kind '{k}'")))).collect()
            }
            "--corpus" => a.corpus = value().into(),
            "--findings" => a.findings = value().into(),
            "--scratch" => a.scratch = value().into(),
            "--child" => a.child = true,
            "--paste" => a.paste = true,
            "--show-refusals" => a.show_refusals = num(value()) as usize,
            "--write-corpus" => a.write_corpus = Some(value().into()),
            other => usage(&format!("unknown flag '{other}'")),
        }
    }
    a
}

fn options(a: &Args, first: u64, cases: u64, scratch: PathBuf) -> fuzz::Options {
    fuzz::Options {
        corpus: a.corpus.clone(),
        kinds: a.kinds.clone(),
        seed: a.seed,
        first,
        cases,
        workers: a.workers,
        hang_after: Duration::from_secs_f64(a.hang_secs),
        scratch,
    }
}

/// The child: run the cases and report each on stdout, one line each
/// (`case class`, then the detail of a failure, newlines removed).
fn child(a: &Args) {
    // Renders print summary lines on stdout: keep them out of the protocol.
    let protocol = std::io::stdout();
    // SAFETY: dup/dup2 on the process's own standard descriptors, before any thread starts.
    let out_fd = unsafe { libc::dup(1) };
    let null = std::fs::OpenOptions::new().write(true).open("/dev/null").expect("/dev/null");
    unsafe { libc::dup2(std::os::fd::AsRawFd::as_raw_fd(&null), 1) };
    drop(protocol);
    // SAFETY: out_fd is a fresh duplicate of stdout that nothing else owns.
    let mut out = std::io::BufWriter::new(unsafe { <std::fs::File as std::os::fd::FromRawFd>::from_raw_fd(out_fd) });
    let opts = options(a, a.first, a.cases, a.scratch.clone());
    let result = fuzz::run(&opts, &mut |case, _, outcome| {
        let _ = writeln!(out, "{case} {} {}", outcome.class(), outcome.detail().replace('\n', " "));
        let _ = out.flush();
    });
    if let Err(e) = result {
        eprintln!("fuzz child: {e}");
        std::process::exit(3);
    }
    let _ = std::fs::remove_dir_all(&a.scratch);
}

fn parse_outcome(class: &str, detail: String) -> Outcome {
    match class {
        "rendered" => Outcome::Rendered,
        "refused" => Outcome::Refused(detail),
        "panic" => Outcome::Panicked(detail),
        "hang" => Outcome::Hung,
        "left-output" => Outcome::LeftOutput(detail),
        "unnamed-error" => Outcome::Unnamed(detail),
        "memory" => Outcome::Memory(detail),
        _ => Outcome::Crashed(detail),
    }
}

/// Run cases `first .. first + cases` in one child; the outcomes it
/// reported, and how it ended when it did not exit cleanly.
fn run_child(a: &Args, first: u64, cases: u64, workers: usize) -> (Vec<(u64, Outcome)>, Option<String>) {
    let exe = std::env::current_exe().expect("own path");
    let scratch = a.scratch.join(format!("c{first}"));
    let mut cmd = Command::new(exe);
    cmd.args(["--child", "--first", &first.to_string(), "--cases", &cases.to_string(), "--seed", &a.seed.to_string()])
        .args(["--workers", &workers.to_string(), "--hang-secs", &a.hang_secs.to_string()])
        .args(["--kind", &a.kinds.iter().map(|k| k.name()).collect::<Vec<_>>().join(",")])
        .arg("--corpus")
        .arg(&a.corpus)
        .arg("--scratch")
        .arg(&scratch)
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    let mut child = cmd.spawn().expect("start a fuzz child");
    let mut got = Vec::new();
    for line in BufReader::new(child.stdout.take().unwrap()).lines().map_while(|l| l.ok()) {
        let mut w = line.splitn(3, ' ');
        let (Some(case), Some(class)) = (w.next().and_then(|c| c.parse().ok()), w.next()) else { continue };
        got.push((case, parse_outcome(class, w.next().unwrap_or("").to_string())));
    }
    let status = child.wait().expect("wait for a fuzz child");
    let _ = std::fs::remove_dir_all(&scratch);
    use std::os::unix::process::ExitStatusExt;
    let died = match (status.code(), status.signal()) {
        (Some(0), _) => None,
        (_, Some(sig)) => Some(format!("killed by signal {sig}")),
        (Some(code), _) => Some(format!("exited with status {code}")),
        (None, None) => Some("ended without a status".into()),
    };
    (got, died)
}

fn long_run(a: &Args) {
    let seeds: Vec<fuzz::Seeds> = a.kinds.iter().map(|&k| fuzz::Seeds::load(&a.corpus, k).unwrap_or_else(|e| usage(&e.0))).collect();
    let start = Instant::now();
    let mut report = Report::default();
    // The refusals' messages, by kind, without the file's path: how often each.
    let mut refusals: std::collections::BTreeMap<(Kind, String), u64> = Default::default();
    let mut record = |report: &mut Report, case: u64, outcome: Outcome| {
        let (k, pick, input) = fuzz::case_input(&seeds, a.seed, case);
        report.add(seeds[k].kind, &outcome);
        if let Outcome::Refused(m) = &outcome {
            if a.show_refusals > 0 {
                let m = m.rsplit_once("case.").map_or(m.as_str(), |(_, r)| r).chars().filter(|c| !c.is_ascii_digit()).collect::<String>();
                *refusals.entry((seeds[k].kind, m)).or_default() += 1;
            }
        }
        if outcome.is_failure() {
            report.findings.push(fuzz::Finding { case, kind: seeds[k].kind, seed_name: seeds[k].files[pick].0.clone(), outcome, input });
        }
    };
    let mut first = a.first;
    let end = a.first + a.cases;
    let mut last_print = Instant::now();
    while first < end {
        let n = a.chunk.min(end - first);
        let (got, died) = run_child(a, first, n, a.workers);
        let mut seen = vec![false; n as usize];
        for (case, outcome) in got {
            if (first..first + n).contains(&case) && !std::mem::replace(&mut seen[(case - first) as usize], true) {
                record(&mut report, case, outcome);
            }
        }
        if let Some(how) = died {
            // Each case the child did not report, alone: the one that dies is the crash.
            for i in (0..n).filter(|&i| !seen[i as usize]) {
                let (got, died) = run_child(a, first + i, 1, 1);
                let outcome = match (got.into_iter().next(), died) {
                    (Some((_, o)), None) => o,
                    (_, Some(how1)) => Outcome::Crashed(how1),
                    (None, None) => Outcome::Crashed(format!("no report ({how})")),
                };
                record(&mut report, first + i, outcome);
            }
        }
        first += n;
        if last_print.elapsed() > Duration::from_secs(30) || first == end {
            let done = report.total();
            eprintln!(
                "fuzz: {done} cases in {:.0} s ({:.0}/s): {} failures",
                start.elapsed().as_secs_f64(),
                done as f64 / start.elapsed().as_secs_f64(),
                report.findings.len()
            );
            last_print = Instant::now();
        }
    }
    report.seconds = start.elapsed().as_secs_f64();
    drop(record);
    for kind in &a.kinds {
        let mut v: Vec<(&String, &u64)> = refusals.iter().filter(|((k, _), _)| k == kind).map(|((_, m), n)| (m, n)).collect();
        v.sort_by(|x, y| y.1.cmp(x.1));
        for (m, n) in v.into_iter().take(a.show_refusals) {
            println!("{} {n:6}  {}", kind.name(), m.chars().take(160).collect::<String>());
        }
    }
    std::fs::create_dir_all(&a.findings).expect("findings folder");
    for f in &report.findings {
        let name = format!("{}-{}-{}-case{}.{}", f.kind.name(), f.outcome.class(), f.seed_name.replace('.', "_"), f.case, f.kind.extension());
        std::fs::write(a.findings.join(&name), &f.input).expect("write a finding");
        eprintln!("finding: {} case {} ({}, seed {}): {} -> {}", f.kind.name(), f.case, f.outcome.class(), f.seed_name, f.outcome.detail(), a.findings.join(&name).display());
    }
    let cpu = std::fs::read_to_string("/proc/cpuinfo").ok().and_then(|t| t.lines().find(|l| l.starts_with("model name")).map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())).unwrap_or_default();
    println!(
        "fuzz: seed {}, cases {}..{}, {} workers, hang bound {} s, {:.0} s on {} ({:.0} cases/s)\n",
        a.seed,
        a.first,
        end,
        a.workers,
        a.hang_secs,
        report.seconds,
        cpu,
        report.total() as f64 / report.seconds
    );
    print!("{}", report.table());
    if a.paste {
        paste_table(a, &report, &cpu, end);
    }
    let failures = report.findings.len();
    println!("\n{failures} failing cases{}", if failures > 0 { format!(" (inputs in {})", a.findings.display()) } else { String::new() });
    let _ = std::fs::remove_dir_all(&a.scratch);
    if failures > 0 {
        std::process::exit(1);
    }
}

/// Write the run's table into docs/reliability.md between its fuzz markers.
fn paste_table(a: &Args, report: &Report, cpu: &str, end: u64) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let commit = Command::new("git").args(["-C", &root.display().to_string(), "rev-parse", "--short", "HEAD"]).output().ok().map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string()).unwrap_or_default();
    let date = Command::new("date").arg("+%Y-%m-%d").output().ok().map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string()).unwrap_or_default();
    let text = format!(
        "**{date}, seed {}, {} cases** (commit {commit}'s fuzzer and readers, {} workers, hang bound {} s, {:.0} s on {}, {:.0} cases/s; `cargo run --release --example fuzz -- --cases {} --seed {} --paste`):\n\n{}",
        a.seed,
        end - a.first,
        a.workers,
        a.hang_secs,
        report.seconds,
        cpu,
        report.total() as f64 / report.seconds,
        end - a.first,
        a.seed,
        report.table()
    );
    let path = root.join("docs/reliability.md");
    let doc = std::fs::read_to_string(&path).expect("docs/reliability.md");
    let (start, stop) = ("<!-- fuzz:start -->", "<!-- fuzz:end -->");
    let (Some(i), Some(j)) = (doc.find(start), doc.find(stop)) else {
        eprintln!("fuzz: docs/reliability.md has no fuzz markers; nothing pasted");
        return;
    };
    let out = format!("{}{start}\n{}{}", &doc[..i], text, &doc[j..]);
    std::fs::write(&path, out).expect("write docs/reliability.md");
    eprintln!("fuzz: the table is in docs/reliability.md");
}

fn main() {
    let a = parse_args();
    if let Some(dir) = &a.write_corpus {
        if let Err(e) = corpus::write(dir) {
            eprintln!("fuzz: {e}");
            std::process::exit(1);
        }
        return;
    }
    if a.child {
        child(&a);
    } else {
        long_run(&a);
    }
}

/// The seed corpus: small valid inputs of every kind, covering each
/// reader's variants (light and material kinds, OBJ index forms, PLY
/// property types and byte orders, OpenEXR compressions, split kinds).
mod corpus {
    use pathtracer::Result;
    use std::path::Path;

    fn put(dir: &Path, kind: &str, name: &str, bytes: &[u8]) -> Result<()> {
        let d = dir.join(kind);
        std::fs::create_dir_all(&d).map_err(|e| pathtracer::Error::new(format!("{}: {e}", d.display())))?;
        std::fs::write(d.join(name), bytes).map_err(|e| pathtracer::Error::new(format!("{}: {e}", d.join(name).display())))
    }

    /// A COLLADA file without Blender's `<technique profile="blender">`
    /// blocks (hundreds of lines no reader looks at).
    fn strip_blender(text: &str) -> String {
        let mut s = text.to_string();
        while let Some(a) = s.find("<technique profile=\"blender\">") {
            let Some(b) = s[a..].find("</technique>") else { break };
            s.replace_range(a..a + b + "</technique>".len(), "");
        }
        let lines: Vec<&str> = s.lines().filter(|l| !l.trim().is_empty()).collect();
        let mut s = lines.join("\n") + "\n";
        while let Some(a) = s.find("<extra>\n") {
            let rest = &s[a + 8..];
            let ws = rest.len() - rest.trim_start().len();
            if rest.trim_start().starts_with("</extra>") {
                let end = a + 8 + ws + "</extra>".len();
                s.replace_range(a..end, "");
            } else {
                break;
            }
        }
        s
    }

    fn read(path: &Path) -> Result<String> {
        std::fs::read_to_string(path).map_err(|e| pathtracer::Error::new(format!("{}: {e}", path.display())))
    }

    pub fn write(dir: &Path) -> Result<()> {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let sky = root.join("scenes/cs184/sky");
        // COLLADA: the point-lit cube, the same cube under the hemisphere
        // light and a directional light, the emissive plane, and Cornell
        // boxes with an area light, CGL spheres, mirror, glass, microfacet.
        let cube = strip_blender(&read(&root.join("scenes/cs184/simple/cube.dae"))?);
        put(dir, "dae", "cube.dae", cube.as_bytes())?;
        let point = cube.find("<point>").zip(cube.find("</point>")).map(|(a, b)| a..b + "</point>".len()).expect("cube.dae has a point light");
        let mut hemi = cube.clone();
        hemi.replace_range(point.clone(), "<ambient>\n          <color>1 1 1</color>\n        </ambient>");
        put(dir, "dae", "cube_hemisphere.dae", hemi.as_bytes())?;
        let mut sun = cube.clone();
        sun.replace_range(point, "<directional>\n          <color>2 2 2</color>\n        </directional>");
        put(dir, "dae", "cube_directional.dae", sun.as_bytes())?;
        put(dir, "dae", "plane.dae", strip_blender(&read(&root.join("scenes/cs184/simple/plane.dae"))?).as_bytes())?;
        for name in ["CBspheres.dae", "CBspheres_microfacet_al_ag.dae", "CBspheres_refract.dae"] {
            put(dir, "dae", name, strip_blender(&read(&sky.join(name))?).as_bytes())?;
        }
        // OBJ: positions, texture coordinates and normals in every face
        // form, quads, negative indices, groups, comments, a material line.
        put(dir, "obj", "cube.obj", b"# a unit cube\no cube\nv -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\nvt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 -1\nvn 0 0 1\nusemtl grey\nf 1/1/1 2/2/1 3/3/1 4/1/1\nf 5//2 6//2 7//2\nf 5//2 7//2 8//2\ng sides\nf 1 5 8 4\nf 2 3 7 6\nf 1 2 6 5\nf 4 8 7 3\n")?;
        put(dir, "obj", "negative.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf -4 -3 -2\nf -4/-1 -2 -1\nvt 0.5 0.5\n\\\nv 2 2 2\nf 1 2 5\n")?;
        // PLY, ASCII: normals, colours, an extra element, both list index names.
        put(dir, "ply-ascii", "tetra.ply", b"ply\nformat ascii 1.0\ncomment a tetrahedron\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n0 0 0 0 0 -1\n1 0 0 0 0 -1\n0 1 0 0 0 -1\n0 0 1 1 1 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n")?;
        put(dir, "ply-ascii", "quad_colours.ply", b"ply\nformat ascii 1.0\nelement vertex 4\nproperty double x\nproperty double y\nproperty double z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nelement face 1\nproperty list uchar uint vertex_index\nelement edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n-1 0 -1 255 0 0\n1 0 -1 0 255 0\n1 0 1 0 0 255\n-1 0 1 9 9 9\n4 0 1 2 3\n0 1\n")?;
        // PLY, binary: both byte orders, float and double positions, int and uint indices.
        let tetra = [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]];
        let faces = [[0u32, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let mut le = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
        for v in tetra {
            v.iter().for_each(|c| le.extend_from_slice(&c.to_le_bytes()));
        }
        for f in faces {
            le.push(3);
            f.iter().for_each(|i| le.extend_from_slice(&(*i as i32).to_le_bytes()));
        }
        put(dir, "ply-binary", "tetra_le.ply", &le)?;
        let mut be = b"ply\nformat binary_big_endian 1.0\nelement vertex 4\nproperty double x\nproperty double y\nproperty double z\nproperty float nx\nproperty float ny\nproperty float nz\nelement face 4\nproperty list uchar uint vertex_index\nend_header\n".to_vec();
        for v in tetra {
            v.iter().for_each(|c| be.extend_from_slice(&(*c as f64).to_be_bytes()));
            [0f32, 0., 1.].iter().for_each(|c| be.extend_from_slice(&c.to_be_bytes()));
        }
        for f in faces {
            be.push(3);
            f.iter().for_each(|i| be.extend_from_slice(&i.to_be_bytes()));
        }
        put(dir, "ply-binary", "tetra_be.ply", &be)?;
        exr_maps(dir)?;
        // Camera files: the built-in scene's camera, and with a thin lens.
        let scene = pathtracer::scene::builtin::load()?;
        let mut cam = pathtracer::camera::Camera::from_scene(&scene);
        put(dir, "camera", "builtin.cam", cam.to_settings().as_bytes())?;
        cam.lens_radius = 0.05;
        cam.focal_distance = 3.5;
        put(dir, "camera", "lens.cam", cam.to_settings().as_bytes())?;
        partials(dir)
    }

    /// 8×4 latitude-longitude maps, one per OpenEXR compression the exr
    /// crate writes, in f32 and f16, scan lines and tiles, RGB and RGBA.
    fn exr_maps(dir: &Path) -> Result<()> {
        use exr::prelude::*;
        let d = dir.join("exr");
        std::fs::create_dir_all(&d).map_err(|e| pathtracer::Error::new(e.to_string()))?;
        let texel = |x: usize, y: usize| (0.2 + 0.1 * x as f32, 0.5 + 0.05 * y as f32, 1.0 - 0.1 * x as f32);
        let encodings = [
            ("uncompressed", Compression::Uncompressed, false),
            ("rle_tiles", Compression::RLE, true),
            ("zip1", Compression::ZIP1, false),
            ("zip16", Compression::ZIP16, false),
            ("piz", Compression::PIZ, false),
            ("pxr24", Compression::PXR24, false),
            ("b44_half", Compression::B44, false),
        ];
        for (name, compression, tiled) in encodings {
            let blocks = if tiled { Blocks::Tiles(Vec2(4, 4)) } else { Blocks::ScanLines };
            let encoding = Encoding { compression, blocks, line_order: LineOrder::Increasing };
            let path = d.join(format!("{name}.exr"));
            let result = if name.ends_with("half") {
                let ch = SpecificChannels::rgba(|Vec2(x, y): Vec2<usize>| {
                    let (r, g, b) = texel(x, y);
                    (f16::from_f32(r), f16::from_f32(g), f16::from_f32(b), f16::ONE)
                });
                Image::from_encoded_channels((8, 4), encoding, ch).write().to_file(&path)
            } else {
                let ch = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| texel(x, y));
                Image::from_encoded_channels((8, 4), encoding, ch).write().to_file(&path)
            };
            result.map_err(|e| pathtracer::Error::new(format!("{}: {e}", path.display())))?;
        }
        Ok(())
    }

    /// Two-part sets of the built-in scene: a sample split, a tile split,
    /// and a tile split of an adaptive render.
    fn partials(dir: &Path) -> Result<()> {
        let d = dir.join("partial");
        std::fs::create_dir_all(&d).map_err(|e| pathtracer::Error::new(e.to_string()))?;
        let sets: [(&str, &[&str]); 3] = [
            ("samples", &["-r", "12", "8", "-s", "4", "-m", "2"]),
            ("tiles", &["-r", "40", "8", "-s", "2", "--split", "tiles"]),
            ("adaptive", &["-r", "40", "8", "-s", "8", "-a", "2", "0.5"]),
        ];
        for (name, args) in sets {
            for i in 0..2 {
                let file = d.join(format!("{name}-{i}.ptp"));
                let mut a: Vec<String> = vec!["pathtracer".into()];
                a.extend(args.iter().map(|s| s.to_string()));
                a.extend(["-t".into(), "1".into(), "--part".into(), format!("{i}/2"), "--partial".into(), file.to_string_lossy().into_owned()]);
                let cli = pathtracer::app::cli::parse(&a)?.expect("render arguments");
                pathtracer::app::run(cli)?;
            }
        }
        Ok(())
    }
}
