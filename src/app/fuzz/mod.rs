//! A mutation fuzzer of every reader, on stable Rust (no `cargo fuzz`,
//! which needs nightly): seeds from a corpus in the repository
//! (`tests/fuzz/corpus/`), mutated (`mutate`), run through the command
//! line (`targets`), each case classified.
//!
//! Case `i` of a run with seed `s` is fully determined by `(s, i)`: its
//! kind (`kinds[i mod len]`), its seed input and its mutations, so a
//! finding can be regenerated and a run split across processes. Cases run
//! on worker threads; a panic is caught and counted (the panic hook is
//! silenced while a run lasts); a case still running after `hang_after` is
//! counted as a hang, its worker abandoned and replaced. A crash (abort,
//! stack overflow) ends the process: `examples/fuzz.rs` runs cases in
//! child processes to count those too. `cargo test` runs a few thousand
//! cases with a fixed seed (`tests/fuzz.rs`) and every input that ever
//! failed (`tests/fuzz/regressions/`).

pub mod alloc;
pub mod mutate;
pub mod targets;

pub use targets::{Kind, Seeds, Workspace};

use crate::rng::Rng;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::time::{Duration, Instant};

/// What one case did.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// Loaded and rendered (or merged): exactly the expected files written.
    Rendered,
    /// Refused with a message naming the input, nothing written.
    Refused(String),
    /// A panic, with its message.
    Panicked(String),
    /// Still running after the bound.
    Hung,
    /// Files left behind, or not the expected ones.
    LeftOutput(String),
    /// Refused with a message that does not name the input.
    Unnamed(String),
    /// The case's thread had more than [`MEMORY_BOUND`] live at once (a
    /// size read from the input and believed); needs [`alloc::CountingAlloc`].
    Memory(String),
    /// The process died (counted by `examples/fuzz.rs`'s child processes).
    Crashed(String),
}

impl Outcome {
    pub const CLASSES: [&'static str; 8] = ["rendered", "refused", "panic", "hang", "memory", "left-output", "unnamed-error", "crash"];

    pub fn class(&self) -> &'static str {
        match self {
            Outcome::Rendered => "rendered",
            Outcome::Refused(_) => "refused",
            Outcome::Panicked(_) => "panic",
            Outcome::Hung => "hang",
            Outcome::LeftOutput(_) => "left-output",
            Outcome::Unnamed(_) => "unnamed-error",
            Outcome::Memory(_) => "memory",
            Outcome::Crashed(_) => "crash",
        }
    }

    pub fn is_failure(&self) -> bool {
        !matches!(self, Outcome::Rendered | Outcome::Refused(_))
    }

    pub fn detail(&self) -> &str {
        match self {
            Outcome::Refused(s) | Outcome::Panicked(s) | Outcome::LeftOutput(s) | Outcome::Unnamed(s) | Outcome::Memory(s) | Outcome::Crashed(s) => s,
            Outcome::Hung => "still running after the bound",
            _ => "",
        }
    }
}

/// The most memory a case may hold at once on its thread: inputs are
/// small, renders 8x6 pixels, so more means a size in the input was believed.
pub const MEMORY_BOUND: i64 = 1 << 30;

/// A panic's message, from its payload.
pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    let msg = payload.downcast_ref::<&str>().map(|s| s.to_string()).or_else(|| payload.downcast_ref::<String>().cloned()).unwrap_or_else(|| "(no message)".into());
    // The hook saw where it happened; add that when it is known.
    let at = PANIC_PLACES.lock().map(|p| p.iter().rev().find(|(m, _)| *m == msg).map(|(_, at)| at.clone())).ok().flatten();
    match at {
        Some(at) => format!("{msg} at {at}"),
        None => msg,
    }
}

/// Where recent panics happened, by message (the hook's view; the payload
/// caught by `catch_unwind` has only the message).
static PANIC_PLACES: Mutex<Vec<(String, String)>> = Mutex::new(Vec::new());

/// A fuzz run's settings.
#[derive(Clone, Debug)]
pub struct Options {
    pub corpus: PathBuf,
    pub kinds: Vec<Kind>,
    pub seed: u64,
    /// Cases `first .. first + cases`.
    pub first: u64,
    pub cases: u64,
    pub workers: usize,
    pub hang_after: Duration,
    /// Where the workers' folders go (emptied first).
    pub scratch: PathBuf,
}

/// A failing case: enough to regenerate it, and its input.
#[derive(Clone, Debug)]
pub struct Finding {
    pub case: u64,
    pub kind: Kind,
    pub seed_name: String,
    pub outcome: Outcome,
    pub input: Vec<u8>,
}

/// A run's counts by kind and outcome class, and its failures.
#[derive(Clone, Debug, Default)]
pub struct Report {
    pub counts: BTreeMap<(Kind, &'static str), u64>,
    pub findings: Vec<Finding>,
    pub seconds: f64,
}

impl Report {
    pub fn total(&self) -> u64 {
        self.counts.values().sum()
    }

    pub fn count(&self, class: &str) -> u64 {
        self.counts.iter().filter(|((_, c), _)| *c == class).map(|(_, n)| n).sum()
    }

    pub fn add(&mut self, kind: Kind, outcome: &Outcome) {
        *self.counts.entry((kind, outcome.class())).or_default() += 1;
    }

    /// A Markdown table: one row per kind, one column per outcome class.
    pub fn table(&self) -> String {
        let kinds: Vec<Kind> = Kind::ALL.into_iter().filter(|k| self.counts.keys().any(|(kk, _)| kk == k)).collect();
        let mut t = format!("| input | cases | {} |\n|---|---:|{}\n", Outcome::CLASSES.join(" | "), "---:|".repeat(Outcome::CLASSES.len()));
        let row = |name: &str, f: &dyn Fn(&str) -> u64| {
            let cells: Vec<String> = Outcome::CLASSES.iter().map(|c| f(c).to_string()).collect();
            format!("| {name} | {} | {} |\n", Outcome::CLASSES.iter().map(|c| f(c)).sum::<u64>(), cells.join(" | "))
        };
        for k in &kinds {
            t += &row(k.name(), &|c| self.counts.get(&(*k, c)).copied().unwrap_or(0));
        }
        t += &row("**all**", &|c| self.count(c));
        t
    }
}

/// Case `case`'s kind, seed index and input.
pub fn case_input(seeds: &[Seeds], seed: u64, case: u64) -> (usize, usize, Vec<u8>) {
    let k = (case % seeds.len() as u64) as usize;
    let s = &seeds[k];
    let mut rng = Rng::new(seed, case);
    let pick = ((rng.next_u32() as u64 * s.files.len() as u64) >> 32) as usize;
    let others: Vec<&[u8]> = s.files.iter().map(|(_, b)| b.as_slice()).collect();
    let mut input = mutate::mutate(&s.files[pick].1, &others, s.kind.is_text(), &mut rng);
    // Half the partials get valid checksums again, so that the mutation
    // reaches the header's fields and the records' checks behind them.
    if s.kind == Kind::Partial && rng.next_u32() & 1 == 0 {
        if let Some(sealed) = crate::partial::reseal(&input) {
            input = sealed;
        }
    }
    (k, pick, input)
}

/// One worker's state, shared with the watchdog.
struct Slot {
    /// The case running and since when.
    running: Option<(u64, Instant)>,
    /// Set by the watchdog when it counted the running case as a hang.
    abandoned: bool,
}

/// Run cases `first .. first + cases` and report; `on_case` sees every
/// case's outcome as it ends (for progress, or a parent process).
pub fn run(opts: &Options, on_case: &mut dyn FnMut(u64, Kind, &Outcome)) -> crate::Result<Report> {
    let seeds: Arc<Vec<Seeds>> = Arc::new(opts.kinds.iter().map(|&k| Seeds::load(&opts.corpus, k)).collect::<crate::Result<_>>()?);
    if seeds.is_empty() {
        crate::bail!("fuzz: no kinds to run");
    }
    // Renders inside the cases share one pool with as many threads as workers.
    let _ = rayon::ThreadPoolBuilder::new().num_threads(opts.workers.max(1)).build_global();
    let start = Instant::now();
    let previous_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|info| {
        let msg = info.payload().downcast_ref::<&str>().map(|s| s.to_string()).or_else(|| info.payload().downcast_ref::<String>().cloned()).unwrap_or_default();
        let at = info.location().map(|l| format!("{}:{}", l.file(), l.line())).unwrap_or_default();
        if let Ok(mut p) = PANIC_PLACES.lock() {
            if p.len() > 64 {
                p.remove(0);
            }
            p.push((msg, at));
        }
    }));
    let end = opts.first + opts.cases;
    let next = Arc::new(AtomicU64::new(opts.first));
    let (tx, rx) = mpsc::channel::<(u64, Outcome)>();
    let mut slots: Vec<Arc<Mutex<Slot>>> = Vec::new();
    let spawn = |index: usize, slots: &mut Vec<Arc<Mutex<Slot>>>| -> crate::Result<()> {
        let slot = Arc::new(Mutex::new(Slot { running: None, abandoned: false }));
        slots.push(slot.clone());
        let ws = Workspace::new(opts.scratch.join(format!("w{index}"))).map_err(|e| crate::Error::new(format!("{}: {e}", opts.scratch.display())))?;
        let (seeds, next, tx, seed) = (seeds.clone(), next.clone(), tx.clone(), opts.seed);
        // The binary's main thread has 8 MiB of stack; so do the workers.
        std::thread::Builder::new()
            .stack_size(8 << 20)
            .spawn(move || loop {
                let case = next.fetch_add(1, Ordering::SeqCst);
                if case >= end {
                    return;
                }
                let (k, pick, input) = case_input(&seeds, seed, case);
                slot.lock().unwrap().running = Some((case, Instant::now()));
                let outcome = ws.run(&seeds[k], pick, &input);
                let mut s = slot.lock().unwrap();
                if s.abandoned {
                    return;
                }
                s.running = None;
                drop(s);
                if tx.send((case, outcome)).is_err() {
                    return;
                }
            })
            .map(|_| ())
            .map_err(|e| crate::Error::new(format!("fuzz: cannot start a worker: {e}")))
    };
    for w in 0..opts.workers.max(1) {
        spawn(w, &mut slots)?;
    }
    let mut report = Report::default();
    let mut done = 0u64;
    let mut record = |case: u64, outcome: Outcome, report: &mut Report| {
        let (k, pick, input) = case_input(&seeds, opts.seed, case);
        let kind = seeds[k].kind;
        report.add(kind, &outcome);
        on_case(case, kind, &outcome);
        if outcome.is_failure() {
            report.findings.push(Finding { case, kind, seed_name: seeds[k].files[pick].0.clone(), outcome, input });
        }
    };
    while done < opts.cases {
        if let Ok((case, outcome)) = rx.recv_timeout(Duration::from_millis(50)) {
            record(case, outcome, &mut report);
            done += 1;
        }
        // The watchdog: a case past the bound is a hang; its worker is
        // left to itself and another takes its place.
        let mut hung = Vec::new();
        for slot in &slots {
            let mut s = slot.lock().unwrap();
            if let Some((case, t0)) = s.running.filter(|(_, t0)| t0.elapsed() > opts.hang_after) {
                let _ = t0;
                s.abandoned = true;
                s.running = None;
                hung.push(case);
            }
        }
        for case in hung {
            record(case, Outcome::Hung, &mut report);
            done += 1;
            let index = slots.len();
            spawn(index, &mut slots)?;
        }
    }
    std::panic::set_hook(previous_hook);
    report.findings.sort_by_key(|f| f.case);
    report.seconds = start.elapsed().as_secs_f64();
    Ok(report)
}

/// Run one input as a case of `kind` (a regression file, say). For a
/// partial, `seed_name` picks the set whose other half it is merged with
/// (the first set without it).
pub fn run_one(corpus: &std::path::Path, kind: Kind, seed_name: Option<&str>, input: &[u8], scratch: PathBuf) -> crate::Result<Outcome> {
    let seeds = Seeds::load(corpus, kind)?;
    let pick = seed_name.and_then(|n| seeds.files.iter().position(|(f, _)| f == n)).unwrap_or(0);
    let ws = Workspace::new(scratch).map_err(|e| crate::Error::new(e.to_string()))?;
    let previous_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let start = Instant::now();
    let mut outcome = ws.run(&seeds, pick, input);
    // Every case takes milliseconds; a regression that takes seconds again is a hang again.
    if !outcome.is_failure() && start.elapsed() > Duration::from_secs(5) {
        outcome = Outcome::Hung;
    }
    std::panic::set_hook(previous_hook);
    Ok(outcome)
}
