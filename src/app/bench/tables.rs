//! The benchmark's derived tables: native ÷ another contender per scene, ray
//! kind and thread count, and throughput against thread count. Both are
//! read off the same run's samples, so every ratio compares speeds measured
//! minutes apart on the same machine, never across runs.

use super::Contender;
use crate::accel::BackendKind;
use std::fmt::Write as _;

/// One row of the CSV: `scene, rays, threads, backend, mrays_per_s`.
pub struct Sample {
    pub scene: String,
    pub rays: &'static str,
    pub threads: usize,
    pub backend: Contender,
    pub mrays_per_s: f64,
}

/// The measured Mrays/s of `backend` on `scene`'s `rays` at `threads`.
fn mrays(samples: &[Sample], scene: &str, rays: &str, threads: usize, backend: Contender) -> Option<f64> {
    samples.iter().find(|s| s.scene == scene && s.rays == rays && s.threads == threads && s.backend == backend).map(|s| s.mrays_per_s)
}

/// The batch kinds compared with each Embree's fastest call.
pub(super) const BEST_CALL_KINDS: [&str; 4] = ["camera", "shadow", "random", "diffuse"];

/// One Embree's fastest batch call for one scene's rays of one kind
/// (`embree_calls`), and native's batch call timed against it.
#[derive(Clone, Debug, PartialEq)]
pub struct BestCall {
    pub scene: String,
    pub rays: &'static str,
    pub embree: Contender,
    /// The call as the batch-call table's columns name it: "packet4 i".
    pub call: String,
    /// Mrays/s of native's batch call and of that call, their passes
    /// alternating on one thread; `None` where native was not benched.
    pub paired: Option<(f64, f64)>,
}

/// native ÷ each Embree's fastest batch call per scene and ray kind, each
/// cell naming the call, as a table.
pub(super) fn best_call_table(best: &[BestCall]) -> String {
    let mut out = String::from("| scene | ÷ |");
    for rays in BEST_CALL_KINDS {
        let _ = write!(out, " {rays} 1T |");
    }
    let _ = writeln!(out, "\n|---|---|{}", "---:|".repeat(BEST_CALL_KINDS.len()));
    let contenders: Vec<Contender> = best.iter().fold(Vec::new(), |mut v, b| {
        if !v.contains(&b.embree) {
            v.push(b.embree);
        }
        v
    });
    for sc in in_order(best.iter().map(|b| b.scene.as_str())) {
        for &c in &contenders {
            let mut row = format!("| {sc} | {c} |");
            for rays in BEST_CALL_KINDS {
                match best.iter().find(|b| b.scene == sc && b.rays == rays && b.embree == c) {
                    Some(BestCall { call, paired: Some((n, e)), .. }) if *e > 0.0 => {
                        let _ = write!(row, " {:.2} ({call}) |", n / e);
                    }
                    _ => row.push_str(" – |"),
                }
            }
            let _ = writeln!(out, "{row}");
        }
    }
    out
}

/// native ÷ `other` throughput per scene, ray kind and thread count.
pub(super) fn ratio_table(samples: &[Sample], threads: &[usize], other: Contender) -> String {
    let mut out = String::new();
    let scenes = in_order(samples.iter().map(|s| s.scene.as_str()));
    let mut header = String::from("| scene |");
    let mut rule = String::from("|---|");
    for rays in super::timing::labels() {
        for &t in threads {
            let _ = write!(header, " {rays} {t}T |");
            rule.push_str("---:|");
        }
    }
    let mut rows = String::new();
    for sc in scenes {
        let mut row = format!("| {sc} |");
        let mut any = false;
        for rays in super::timing::labels() {
            for &t in threads {
                match (mrays(samples, sc, rays, t, Contender::Backend(BackendKind::Native)), mrays(samples, sc, rays, t, other)) {
                    (Some(n), Some(e)) => {
                        any = true;
                        let _ = write!(row, " {:.2} |", n / e);
                    }
                    _ => row.push_str(" – |"),
                }
            }
        }
        if any {
            let _ = writeln!(rows, "{row}");
        }
    }
    if !rows.is_empty() {
        let _ = writeln!(out, "{header}\n{rule}");
        out.push_str(&rows);
    }
    out
}


/// Throughput against thread count: one row per scene, contender and ray
/// kind with Mrays/s at each count, then the largest count's speed-up over
/// one thread and that speed-up divided by the ratio of thread counts
/// (parallel efficiency). Brute force is left out: its single pass over a
/// 1/32 subset is too short to time scaling.
pub(super) fn scaling_table(samples: &[Sample], threads: &[usize]) -> String {
    let (Some(&lo), Some(&hi)) = (threads.first(), threads.last()) else { return String::new() };
    let mut out = String::new();
    let _ = write!(out, "| scene | backend | rays |");
    for t in threads {
        let _ = write!(out, " {t}T |");
    }
    let _ = writeln!(out, " {hi}T ÷ {lo}T | efficiency |");
    let _ = writeln!(out, "|---|---|---|{}---:|---:|", "---:|".repeat(threads.len()));
    let brute = Contender::Backend(BackendKind::Brute);
    for sc in in_order(samples.iter().map(|s| s.scene.as_str())) {
        let contenders = in_order(samples.iter().filter(|s| s.scene == sc && s.backend != brute).map(|s| s.backend));
        for b in contenders {
            for rays in super::timing::labels() {
                let at = |t: usize| mrays(samples, sc, rays, t, b);
                let _ = write!(out, "| {sc} | {b} | {rays} |");
                for &t in threads {
                    match at(t) {
                        Some(m) => {
                            let _ = write!(out, " {m:.1} |");
                        }
                        None => out.push_str(" – |"),
                    }
                }
                match (at(lo), at(hi)) {
                    (Some(a), Some(z)) if a > 0.0 => {
                        let speedup = z / a;
                        let _ = writeln!(out, " {speedup:.2} | {:.0} % |", 100.0 * speedup * lo as f64 / hi as f64);
                    }
                    _ => out.push_str(" – | – |\n"),
                }
            }
        }
    }
    out
}

/// The distinct items in first-seen order (the order the run measured them).
fn in_order<T: PartialEq>(items: impl Iterator<Item = T>) -> Vec<T> {
    let mut v = Vec::new();
    for x in items {
        if !v.contains(&x) {
            v.push(x);
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(scene: &str, rays: &'static str, threads: usize, backend: BackendKind, m: f64) -> Sample {
        Sample { scene: scene.into(), rays, threads, backend: Contender::Backend(backend), mrays_per_s: m }
    }

    #[test]
    fn scaling_rows_give_speed_up_and_efficiency_and_leave_out_brute() {
        let mut s = Vec::new();
        for (t, m) in [(1, 10.0), (2, 19.0), (4, 30.0)] {
            s.push(sample("cow", "camera", t, BackendKind::Native, m));
            s.push(sample("cow", "camera", t, BackendKind::Brute, m / 100.0));
        }
        let table = scaling_table(&s, &[1, 2, 4]);
        let row = table.lines().find(|l| l.starts_with("| cow | native | camera |")).expect("native camera row");
        assert_eq!(row, "| cow | native | camera | 10.0 | 19.0 | 30.0 | 3.00 | 75 % |");
        // Kinds not measured show dashes rather than vanishing.
        assert!(table.contains("| cow | native | shadow | – | – | – | – | – |"), "{table}");
        assert!(!table.contains("brute"), "{table}");
    }

    #[test]
    fn ratios_follow_the_thread_counts_given() {
        let mut s = Vec::new();
        for t in [1, 8] {
            s.push(sample("arch", "shadow", t, BackendKind::Native, 10.0 * t as f64));
            s.push(sample("arch", "shadow", t, BackendKind::Embree4, 20.0 * t as f64));
        }
        let table = ratio_table(&s, &[1, 8], Contender::Backend(BackendKind::Embree4));
        assert!(table.contains("shadow 8T"), "{table}");
        let row = table.lines().find(|l| l.starts_with("| arch |")).unwrap();
        assert_eq!(row, "| arch | – | – | 0.50 | 0.50 | – | – | – | – | – | – | – | – |");
    }

    #[test]
    fn best_call_cells_divide_the_paired_speeds_and_name_the_call() {
        let e4 = Contender::Backend(BackendKind::Embree4);
        let call = |rays, call: &str, paired| BestCall { scene: "arch".into(), rays, embree: e4, call: call.into(), paired };
        let best = [call("shadow", "packet8 c", Some((30.0, 20.0))), call("diffuse", "packet4 i", Some((9.0, 10.0))), call("random", "loop i", None)];
        let table = best_call_table(&best);
        let row = table.lines().find(|l| l.starts_with("| arch |")).expect("arch row");
        assert_eq!(row, "| arch | embree4 | – | 1.50 (packet8 c) | – | 0.90 (packet4 i) |");
    }
}

