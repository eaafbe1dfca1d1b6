//! One `pathtracer bench` run: the plan (contenders, thread counts), each
//! scene timed in turn into the run's tables, then the report.

use super::tables::{best_call_table, ratio_table, scaling_table, BestCall, Sample};
use super::timing::{labels, throughput, throughputs, TIMED};
use super::ray_sets::RaySets;
use super::resume::{exact, parse_exact, Checkpoints};
use super::{cpu_model, embree_sah, load_bench_scene, path_render_rows, peers, seed_timing, thread_counts, BenchArgs, Contender};
use super::{BRUTE_LIMIT, BUILD_REPS, DEFAULT_SCENES, RENDER_SCENES};
use crate::accel::workloads::camera_rays;
use crate::accel::{self, BackendKind, Traversal};
use crate::camera::Camera;
use crate::error::Result;
use crate::render::{self, normals::NormalShading, RenderSettings};
use crate::scene::Scene;
use serde_json::{json, Value};
use std::collections::HashMap;
use std::fmt::Write as _;

/// What a run times.
struct Plan {
    /// The machine's threads (builds use them all).
    all: usize,
    backends: Vec<BackendKind>,
    /// Ours first, then the peers, brute force last.
    contenders: Vec<Contender>,
    thread_counts: Vec<usize>,
    /// The Embree majors timed: their SAH costs and batch calls are tabled.
    majors: Vec<accel::embree::Major>,
    /// The rays each contender traces on a scene (every kind, pass and
    /// thread count), which the native build weighs its spatial splits
    /// against (`NativeOptions::expected_rays`).
    expected_rays: u64,
}

const BRUTE: Contender = Contender::Backend(BackendKind::Brute);

impl Plan {
    fn new(args: &BenchArgs) -> Result<Plan> {
        let all = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
        let backends: Vec<BackendKind> = if args.backends.is_empty() {
            let mut v = vec![BackendKind::Native];
            if accel::embree::available(accel::embree::Major::V3) {
                v.extend([BackendKind::Embree3, BackendKind::Embree3High]);
            }
            if accel::embree::available(accel::embree::Major::V4) {
                v.extend([BackendKind::Embree4, BackendKind::Embree4High]);
            }
            v.push(BackendKind::Brute);
            v
        } else {
            args.backends.clone()
        };
        let mut contenders: Vec<Contender> = backends.iter().filter(|&&k| k != BackendKind::Brute).map(|&k| Contender::Backend(k)).collect();
        if !args.no_peers {
            contenders.extend(peers());
        }
        if backends.contains(&BackendKind::Brute) {
            contenders.push(BRUTE);
        }
        let majors = accel::embree::Major::ALL
            .into_iter()
            .filter(|&m| backends.iter().any(|b| b.embree().and_then(|r| r.ok()).is_some_and(|(mm, _)| mm == m)))
            .collect();
        let thread_counts = thread_counts(&args.threads, all)?;
        let expected_rays = (args.rays * TIMED.len() * (args.passes + 1) * thread_counts.len()) as u64;
        Ok(Plan { all, thread_counts, backends, contenders, majors, expected_rays })
    }

    /// Everything that changes what a part measures, for `--resume`'s key.
    fn describe(&self, args: &BenchArgs) -> String {
        let contenders: Vec<String> = self.contenders.iter().map(|c| c.to_string()).collect();
        format!(
            "{}, {} threads; rays {}, passes {}, threads {:?}, contenders [{}], throughput-only {}, no-render {}",
            cpu_model(),
            self.all,
            args.rays,
            args.passes,
            self.thread_counts,
            contenders.join(" "),
            args.throughput_only,
            args.no_render
        )
    }
}

/// What the run's scenes fill in, scene by scene: each scene's part, then
/// the run's (`append`).
#[derive(Default)]
struct Tables {
    /// The throughput table's rows.
    throughput: String,
    samples: Vec<Sample>,
    sah: String,
    /// Each Embree's batch calls, and its fastest call per ray kind.
    modes: String,
    embree_best: Vec<BestCall>,
    /// Normal shading with and without the BVH.
    normals: String,
    /// The path-traced renders' rows.
    renders: String,
}

impl Tables {
    fn append(&mut self, part: Tables) {
        self.throughput.push_str(&part.throughput);
        self.samples.extend(part.samples);
        self.sah.push_str(&part.sah);
        self.modes.push_str(&part.modes);
        self.embree_best.extend(part.embree_best);
        self.normals.push_str(&part.normals);
        self.renders.push_str(&part.renders);
    }

    /// Every field, the measurements exactly (`resume::exact`).
    fn to_json(&self) -> Value {
        json!({
            "throughput": self.throughput,
            "samples": self.samples.iter().map(|s| json!([s.scene, s.rays, s.threads, s.backend.to_string(), exact(s.mrays_per_s)])).collect::<Vec<_>>(),
            "sah": self.sah,
            "modes": self.modes,
            "embree_best": self
                .embree_best
                .iter()
                .map(|b| json!([b.scene, b.rays, b.embree.to_string(), b.call, b.paired.map(|(n, e)| [exact(n), exact(e)])]))
                .collect::<Vec<_>>(),
            "normals": self.normals,
            "renders": self.renders,
        })
    }

    /// What `to_json` wrote, its ray kinds and contenders this plan's;
    /// `None` where anything is missing or unknown.
    fn from_json(v: &Value, plan: &Plan) -> Option<Tables> {
        let text = |k: &str| v[k].as_str().map(str::to_string);
        let rays = |v: &Value| labels().find(|l| v.as_str() == Some(*l));
        let contender = |v: &Value| plan.contenders.iter().copied().find(|c| v.as_str() == Some(c.to_string().as_str()));
        let mut samples = Vec::new();
        for s in v["samples"].as_array()? {
            let threads = usize::try_from(s[2].as_u64()?).ok()?;
            samples.push(Sample { scene: s[0].as_str()?.to_string(), rays: rays(&s[1])?, threads, backend: contender(&s[3])?, mrays_per_s: parse_exact(&s[4])? });
        }
        let mut embree_best = Vec::new();
        for b in v["embree_best"].as_array()? {
            let paired = match &b[4] {
                Value::Null => None,
                p => Some((parse_exact(&p[0])?, parse_exact(&p[1])?)),
            };
            embree_best.push(BestCall { scene: b[0].as_str()?.to_string(), rays: rays(&b[1])?, embree: contender(&b[2])?, call: b[3].as_str()?.to_string(), paired });
        }
        Some(Tables {
            throughput: text("throughput")?,
            samples,
            sah: text("sah")?,
            modes: text("modes")?,
            embree_best,
            normals: text("normals")?,
            renders: text("renders")?,
        })
    }
}

/// A part of the run, measuring the scene `scene`: taken from `--resume`'s
/// folder where an earlier run of the same binary, machine and options left
/// it from the same scene files, else measured (and kept there).
fn part(store: Option<&Checkpoints>, plan: &Plan, name: &str, scene: &str, measure: impl FnOnce() -> Result<Tables>) -> Result<Tables> {
    let Some(store) = store else { return measure() };
    let key = store.part_key(&super::scene_files(scene));
    if let Some(kept) = store.load(name, &key) {
        if let Some(t) = Tables::from_json(&kept, plan) {
            eprintln!("bench: {name}: measured by an earlier run, taken from {}", store.dir().display());
            return Ok(t);
        }
        eprintln!("bench: {name}: the kept part in {} is incomplete; measuring it again", store.dir().display());
    }
    let t = measure()?;
    store.save(name, &key, t.to_json())?;
    Ok(t)
}

pub fn run(args: &BenchArgs) -> Result<()> {
    let plan = Plan::new(args)?;
    let names: Vec<String> = if args.scenes.is_empty() { DEFAULT_SCENES.iter().map(|s| s.to_string()).collect() } else { args.scenes.clone() };
    let store = match &args.resume {
        Some(dir) => Some(Checkpoints::open(dir, &plan.describe(args))?),
        None => None,
    };
    let mut t = Tables::default();
    for name in &names {
        t.append(part(store.as_ref(), &plan, name, name, || {
            let mut p = Tables::default();
            bench_scene(args, &plan, name, &mut p)?;
            Ok(p)
        })?);
    }
    if !(args.no_render || args.throughput_only) {
        let backends: Vec<BackendKind> = plan.backends.iter().copied().filter(|b| *b != BackendKind::Brute).collect();
        for name in RENDER_SCENES {
            t.append(part(store.as_ref(), &plan, &format!("render {name}"), name, || Ok(Tables { renders: path_render_rows(name, &backends, plan.all)?, ..Tables::default() }))?);
        }
    }
    let md = report(args, &plan, &t);
    print!("{md}");
    if let Some(p) = &args.markdown {
        crate::image_io::write_text(p, &md)?;
    }
    if let Some(p) = &args.csv {
        let mut csv = String::from("scene,rays,threads,backend,mrays_per_s\n");
        for s in &t.samples {
            let _ = writeln!(csv, "{},{},{},{},{:.4}", s.scene, s.rays, s.threads, s.backend, s.mrays_per_s);
        }
        crate::image_io::write_text(p, &csv)?;
    }
    Ok(())
}

/// The frame of camera rays: 1024x768 (repeated up to `rays`), or for
/// fewer rays a smaller image of the whole frame, so that shadow rays
/// still start on what the camera sees.
fn frame_for(rays: usize) -> (u32, u32) {
    if rays >= 1024 * 768 {
        (1024, 768)
    } else {
        let w = ((rays as f64 * 4.0 / 3.0).sqrt() as u32).max(4);
        (w, (rays as u32 / w).max(3))
    }
}

/// Time every contender on one scene into `t`.
fn bench_scene(args: &BenchArgs, plan: &Plan, name: &str, t: &mut Tables) -> Result<()> {
    let scene = load_bench_scene(name)?;
    let camera = Camera::from_scene(&scene);
    let (w, h) = frame_for(args.rays);
    let camera_all = camera_rays(&camera, w, h);
    let build_times = best_builds(plan, &scene);
    // Every contender built and held at once, so that their passes can
    // alternate (`throughputs`).
    let mut built: Vec<(Contender, accel::Built)> = Vec::new();
    for &kind in &plan.contenders {
        if kind == BRUTE && scene.primitive_count() > BRUTE_LIMIT {
            continue;
        }
        match kind.build(&scene, plan.all, plan.expected_rays) {
            Ok(b) => built.push((kind, b)),
            Err(e) => eprintln!("bench: {}: {kind}: {e}", scene.name),
        }
    }
    let Some((_, first)) = built.first() else { return Ok(()) };
    let rays = RaySets::new(&scene, first.accel.as_ref(), &camera_all, w, h, args.rays);
    let cells = time_kinds(args, plan, &scene, &built, &rays, &mut t.samples);
    throughput_rows(args, plan, name, &scene, &built, &build_times, &cells, t);
    // Native's tree stays for the Embree batch calls to be timed against.
    let native = built.into_iter().find(|(k, _)| *k == Contender::Backend(BackendKind::Native)).map(|(_, b)| b);
    #[cfg(has_embree)]
    if !args.throughput_only {
        for &major in &plan.majors {
            super::embree_calls::embree_calls(major, &scene, native.as_ref().map(|b| b.accel.as_ref()), &rays, args.passes, &mut t.modes, &mut t.embree_best)?;
        }
    }
    drop(native);
    if !(args.no_render || args.throughput_only) && !scene.source.starts_with("<generated") {
        t.normals.push_str(&normal_shading_row(&scene, &camera, plan.all)?);
    }
    Ok(())
}

/// Build times: the best of `BUILD_REPS` rounds, each building every
/// backend once in turn, so that neither is charged alone for first-touch
/// costs (fresh pages from the OS, Embree starting its TBB threads) or for
/// a noisy stretch of a shared machine. Timed one backend after the other,
/// whichever came first was 5-10 ms slower on the 1M-triangle mesh.
fn best_builds(plan: &Plan, scene: &Scene) -> HashMap<Contender, f64> {
    let mut build_times: HashMap<Contender, f64> = HashMap::new();
    for _ in 0..BUILD_REPS {
        for &kind in plan.contenders.iter().filter(|&&k| k != BRUTE) {
            if let Ok(b) = kind.build(scene, plan.all, plan.expected_rays) {
                let t = build_times.entry(kind).or_insert(f64::INFINITY);
                *t = t.min(b.build_seconds);
            }
        }
    }
    build_times
}

/// Mrays/s of every built contender for every ray kind and thread count
/// (one row of cells per contender, in `built`'s order), recorded in
/// `samples` too. Brute force: one pass over every 32nd ray.
fn time_kinds(args: &BenchArgs, plan: &Plan, scene: &Scene, built: &[(Contender, accel::Built)], rays: &RaySets, samples: &mut Vec<Sample>) -> Vec<Vec<f64>> {
    let timed: Vec<&dyn Traversal> = built.iter().filter(|(k, _)| *k != BRUTE).map(|(_, b)| b.accel.as_ref()).collect();
    let mut cells: Vec<Vec<f64>> = vec![Vec::new(); built.len()];
    for (label, set, kind) in TIMED {
        let set = rays.get(set);
        for &t in &plan.thread_counts {
            let mut speeds = throughputs(&timed, set, kind, t, args.passes).into_iter();
            for (i, (contender, b)) in built.iter().enumerate() {
                let m = if *contender == BRUTE {
                    throughput(b.accel.as_ref(), &set.iter().step_by(32).copied().collect::<Vec<_>>(), kind, t, 1)
                } else {
                    speeds.next().expect("one speed per timed contender")
                };
                samples.push(Sample { scene: scene.name.clone(), rays: label, threads: t, backend: *contender, mrays_per_s: m });
                cells[i].push(m);
            }
        }
    }
    cells
}

/// The scene's rows of the throughput table, and of the SAH table where a
/// contender reports its tree's cost.
#[allow(clippy::too_many_arguments)]
fn throughput_rows(args: &BenchArgs, plan: &Plan, name: &str, scene: &Scene, built: &[(Contender, accel::Built)], build_times: &HashMap<Contender, f64>, cells: &[Vec<f64>], t: &mut Tables) {
    let prims = scene.primitive_count();
    for &kind in &plan.contenders {
        if kind == BRUTE && prims > BRUTE_LIMIT {
            let _ = writeln!(t.throughput, "| {} | {} | brute | – | – | – | skipped above {} primitives |{}", scene.name, prims, BRUTE_LIMIT, " |".repeat(TIMED.len() * plan.thread_counts.len() - 1));
            continue;
        }
        let Some(i) = built.iter().position(|(k, _)| *k == kind) else { continue };
        let a = built[i].1.accel.as_ref();
        let best_build = build_times.get(&kind).copied().unwrap_or(built[i].1.build_seconds);
        if let Some((nodes, leaves)) = a.sah_cost() {
            let total = nodes + leaves;
            let mut row = String::new();
            for major in accel::embree::Major::ALL {
                let e = if plan.majors.contains(&major) && !args.throughput_only { embree_sah(name, major) } else { None };
                let (e, r) = e.map_or(("–".to_string(), "–".to_string()), |e| (format!("{e:.3}"), format!("{:.3}", total / e)));
                let _ = write!(row, " {e} | {r} |");
            }
            let choices = a.choices().unwrap_or_else(|| "–".into());
            let _ = writeln!(t.sah, "| {} | {} | {:.3} | {:.3} | {:.3} |{row} {choices} |", scene.name, kind, nodes, leaves, total);
        }
        let mem = a.memory_bytes() as f64;
        let _ = writeln!(
            t.throughput,
            "| {} | {} | {} | {:.1} | {:.1} | {:.1} | {} |",
            scene.name,
            prims,
            kind,
            best_build * 1e3,
            mem / (1024.0 * 1024.0),
            mem / prims.max(1) as f64,
            cells[i].iter().map(|c| if *c < 0.1 { format!("{c:.4}") } else { format!("{c:.2}") }).collect::<Vec<_>>().join(" | ")
        );
    }
}

/// CS184's normal-shading render with and without the BVH: the scene's row.
fn normal_shading_row(scene: &Scene, camera: &Camera, all: usize) -> Result<String> {
    let mut times = Vec::new();
    for kind in [BackendKind::Native, BackendKind::Brute] {
        let built = accel::build(kind, &scene.shapes, all)?;
        let mut cam = camera.clone();
        cam.set_screen_size(480, 360);
        let integ = NormalShading { scene };
        let settings = RenderSettings::new(480, 360, 1, 0);
        let out = render::render(&cam, built.accel.as_ref(), &integ, &settings);
        times.push(out.seconds);
    }
    let (seed_bvh, seed_brute) = seed_timing(&scene.name);
    Ok(format!("| {} | {} | {:.3} | {:.2} | {:.0}x | {} | {} |\n", scene.name, scene.primitive_count(), times[0], times[1], times[1] / times[0], seed_bvh, seed_brute))
}

/// The printed tables: throughput, then what is read off it, then the
/// renders.
fn report(args: &BenchArgs, plan: &Plan, t: &Tables) -> String {
    let all = plan.all;
    let mut md = String::new();
    let threads_said = plan.thread_counts.iter().map(|t| t.to_string()).collect::<Vec<_>>().join(", ");
    let _ = writeln!(md, "Machine: {}, {all} threads.\n", cpu_model());
    let _ = writeln!(md, "Throughput in Mrays/s (best of {} passes after an untimed one, the contenders' passes alternating; brute: one pass on a 1/32 subset). Threads: {threads_said}. Build: best of {BUILD_REPS} builds on {all} threads.\n", args.passes);
    let _ = write!(md, "| scene | prims | backend | build ms | MiB | B/prim |");
    for rays in labels() {
        for th in &plan.thread_counts {
            let _ = write!(md, " {rays} {th}T |");
        }
    }
    let _ = writeln!(md, "\n|---|---:|---|---:|---:|---:|{}", "---:|".repeat(TIMED.len() * plan.thread_counts.len()));
    md.push_str(&t.throughput);
    for other in plan.contenders.iter().copied().filter(|&c| c != BRUTE && c != Contender::Backend(BackendKind::Native)) {
        let ratios = ratio_table(&t.samples, &plan.thread_counts, other);
        if !ratios.is_empty() {
            let _ = writeln!(md, "\nnative ÷ {other} throughput, from this run:\n");
            md.push_str(&ratios);
        }
    }
    if plan.thread_counts.len() > 2 {
        let _ = writeln!(md, "\nThroughput against threads, Mrays/s, from this run (efficiency: speed-up ÷ thread ratio):\n");
        md.push_str(&scaling_table(&t.samples, &plan.thread_counts));
    }
    if !t.sah.is_empty() {
        let _ = writeln!(
            md,
            "\nSAH cost of the native tree, counted as Embree's BVH statistics count it: \
             expected node visits + expected 4-triangle block tests per ray through the root box. Embree's total is read from its own \
             statistics (a child `pathtracer bench` run with PATHTRACER_EMBREE_CONFIG=verbose=2, line `total : sah = ...`); \
             the traversal choices the native build made for the tree:\n"
        );
        let _ = writeln!(md, "| scene | backend | nodes | leaves | total | Embree 3 total | native ÷ Embree 3 | Embree 4 total | native ÷ Embree 4 | choices |");
        let _ = writeln!(md, "|---|---|---:|---:|---:|---:|---:|---:|---:|---|");
        md.push_str(&t.sah);
    }
    if !t.modes.is_empty() {
        md.push_str(&modes_table(t));
    }
    if !t.normals.is_empty() {
        let _ = writeln!(md, "\nNormal-shading render, 480x360, 1 spp, {all} threads (seconds; seed: CS184 write-up, settings unknown):\n");
        let _ = writeln!(md, "| scene | prims | with BVH | without BVH | speed-up | seed with BVH | seed without |");
        let _ = writeln!(md, "|---|---:|---:|---:|---:|---:|---:|");
        md.push_str(&t.normals);
    }
    if !(args.no_render || args.throughput_only) {
        let _ = writeln!(
            md,
            "\nPath-traced render, 480x360 (CS184 crop), 64 spp, -m 5, seed 1, {all} threads: rays traced in batches (the renderer's \
             default: each sample round of a tile traces its camera rays as one coherent batch, then bounce by bounce its shadow rays \
             as one batch (coherent from the camera rays' hits, incoherent after) and its other rays as another) or one at a time. Image: compared with the scene's first row, pixel by pixel:\n"
        );
        let _ = writeln!(md, "| scene | backend | rays traced | render s | rays | Mrays/s | image |");
        let _ = writeln!(md, "|---|---|---|---:|---:|---:|---|");
        md.push_str(&t.renders);
    }
    md
}

/// Each Embree's batch calls, and native against each Embree's fastest.
fn modes_table(t: &Tables) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "\nEmbree batch calls, 1 thread, Mrays/s: each call with the coherent flag (camera and shadow rays) and with the incoherent \
         flag (c / i); the loop of rtcIntersect1, Embree 3's rtcIntersect1M stream (Embree 4 has none: –), rtcIntersect4/8/16 packets:\n"
    );
    // Every major's rows have a cell pair for each (`embree_calls`).
    let modes = accel::embree::BatchMode::EVERY;
    let calls: String = modes.iter().map(|m| format!(" {0} c | {0} i |", m.name())).collect();
    let _ = writeln!(md, "| scene | embree | rays |{calls}");
    let _ = writeln!(md, "|---|---|---|{}", "---:|".repeat(2 * modes.len()));
    md.push_str(&t.modes);
    let _ = writeln!(
        md,
        "\nnative's batch call ÷ each Embree's fastest batch call above (the best of its columns, named in each cell), 1 thread: \
         the two timed again, their passes alternating as in the throughput table:\n"
    );
    md.push_str(&best_call_table(&t.embree_best));
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A part kept by `--resume` reads back as it was measured, the Embree
    /// calls' paired speeds included.
    #[test]
    fn kept_parts_read_back_exactly() {
        let e4 = Contender::Backend(BackendKind::Embree4);
        let native = Contender::Backend(BackendKind::Native);
        let plan = Plan { all: 2, backends: vec![BackendKind::Native, BackendKind::Embree4], contenders: vec![native, e4], thread_counts: vec![1], majors: vec![], expected_rays: 0 };
        let t = Tables {
            throughput: "| rows |\n".into(),
            samples: vec![Sample { scene: "cow".into(), rays: "diffuse", threads: 1, backend: native, mrays_per_s: 0.1 + 0.2 }],
            modes: "| cow | embree4 | diffuse |\n".into(),
            embree_best: vec![
                BestCall { scene: "cow".into(), rays: "diffuse", embree: e4, call: "packet4 i".into(), paired: Some((1.0 / 3.0, 7.25)) },
                BestCall { scene: "cow".into(), rays: "camera", embree: e4, call: "loop c".into(), paired: None },
            ],
            ..Tables::default()
        };
        let back = Tables::from_json(&t.to_json(), &plan).expect("reads back");
        assert_eq!(back.embree_best, t.embree_best);
        assert_eq!(back.samples[0].mrays_per_s.to_bits(), (0.1f64 + 0.2).to_bits());
        assert_eq!((back.throughput, back.modes), (t.throughput, t.modes));
    }
}
