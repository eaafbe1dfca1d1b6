//! The repository is the whole product: a clone with nothing beside it
//! carries its scenes, maps and license, never reads a folder outside
//! itself, and speaks of the product only (no working rounds, numbered
//! issues or borrowed machines: a measurement names its date, commit and
//! CPU). The documented commands run from a fresh clone in `tests/docs.rs`.

mod common;

use regex::Regex;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every file git tracks that is in the working tree, with its text (None
/// for binary files).
fn tracked_files() -> Vec<(PathBuf, Option<String>)> {
    let out = Command::new("git").args(["ls-files", "-z", "--cached"]).current_dir(root()).output().expect("git ls-files (these tests need git)");
    assert!(out.status.success(), "git ls-files: {}", String::from_utf8_lossy(&out.stderr));
    let mut v = Vec::new();
    for name in out.stdout.split(|&b| b == 0).filter(|n| !n.is_empty()) {
        let rel = PathBuf::from(std::str::from_utf8(name).unwrap());
        let Ok(bytes) = std::fs::read(root().join(&rel)) else { continue };
        let text = if bytes.contains(&0) { None } else { String::from_utf8(bytes).ok() };
        v.push((rel, text));
    }
    assert!(v.len() > 100, "only {} tracked files found", v.len());
    v
}

/// The folder a development checkout once had beside it, spelled so that
/// this file does not name it.
fn outside_folder() -> String {
    format!("{}/{}", "..", "shared")
}

#[test]
fn no_file_names_a_folder_beside_the_repository() {
    let needle = outside_folder();
    let bad: Vec<String> = tracked_files()
        .into_iter()
        .filter_map(|(p, t)| t.filter(|t| t.contains(&needle)).map(|_| p.display().to_string()))
        .collect();
    assert!(bad.is_empty(), "these files name {needle}, which a clone does not have: {bad:?}");
}

/// Words that tie a line to how the project was made rather than to the
/// product: working rounds, numbered issues, borrowed machines.
fn diary_patterns() -> Vec<(Regex, &'static str)> {
    [
        (r"(?i)\bsessions?\b", "a working round"),
        (r"(?i)\bworking rounds?\b", "a working round"),
        (r"(?i)\bstop \d+\b", "a working round"),
        (r"(?i)\ba turn ago\b", "a working round"),
        (r"(?i)\bissues?\s*#?\d+", "a numbered issue"),
        (r"(?i)\b(the|this|that|its|an) issue\b", "an issue"),
        (r"(?i)\blent\b", "a borrowed machine"),
        (r"(?i)\bborrowed\b", "a borrowed machine"),
        (r"(?i)\bdevice machine", "a borrowed machine"),
    ]
    .into_iter()
    .map(|(p, why)| (Regex::new(p).unwrap(), why))
    .collect()
}

/// The lines of `text` that match a diary pattern, with the reason.
fn diary_lines(text: &str) -> Vec<(usize, &'static str)> {
    let pats = diary_patterns();
    text.lines().enumerate().filter_map(|(n, l)| pats.iter().find(|(r, _)| r.is_match(l)).map(|(_, why)| (n + 1, *why))).collect()
}

#[test]
fn the_diary_check_catches_what_it_should_and_nothing_else() {
    let s = "session";
    let caught = [
        format!("measured in {s} 32"),
        format!("re-run this {s}"),
        format!("as {} 14's item 3 asks", "issue"),
        format!("on the {}{} Xeon", "len", "t"),
        format!("a {} machine", "borrowed"),
        format!("the {} machine's 16 cores", "device"),
        format!("the {}'s goal", "issue"),
    ];
    for line in &caught {
        assert_eq!(diary_lines(line).len(), 1, "not caught: {line}");
    }
    for line in ["2026-11-27, commit 948abe6, 2-vCPU Intel Xeon", "a silent pass", "each ray in turn", "the prevalent case", "known issues with Cycles 3.4"] {
        assert!(diary_lines(line).is_empty(), "caught, wrongly: {line}");
    }
}

#[test]
fn the_repository_speaks_of_the_product_only() {
    let mut bad = Vec::new();
    for (p, text) in tracked_files() {
        let Some(text) = text else { continue };
        // The lock file is generated; this file names the patterns it checks.
        if p == Path::new("Cargo.lock") || p == Path::new("tests/repository.rs") {
            continue;
        }
        for (n, why) in diary_lines(&text) {
            bad.push(format!("{}:{n}: names {why}: {}", p.display(), text.lines().nth(n - 1).unwrap().trim()));
        }
    }
    assert!(bad.is_empty(), "{} lines speak of how the project was made (name a measurement by its date, commit and CPU instead):\n{}", bad.len(), bad.join("\n"));
}

#[test]
fn license_is_mit_and_names_the_third_party_data() {
    let text = std::fs::read_to_string(root().join("LICENSE")).expect("LICENSE missing");
    assert!(text.starts_with("MIT License"), "LICENSE is not the MIT license");
    assert!(text.contains("scenes/README.md"));
    let cargo = std::fs::read_to_string(root().join("Cargo.toml")).unwrap();
    assert!(cargo.contains("license = \"MIT\""));
}

/// Every file under scenes/ is listed on scenes/README.md with the SHA-256
/// it has, and every listed file is there.
#[test]
fn the_scenes_are_the_files_their_provenance_page_names() {
    let page = std::fs::read_to_string(root().join("scenes/README.md")).expect("scenes/README.md missing");
    let row = Regex::new(r"^\| `([^`]+)` \|.*\| `([0-9a-f]{64})` \| `([0-9a-f]{40})` \|$").unwrap();
    let mut listed = BTreeSet::new();
    for line in page.lines() {
        let Some(c) = row.captures(line) else { continue };
        let rel = Path::new("scenes").join(&c[1]);
        let bytes = std::fs::read(root().join(&rel)).unwrap_or_else(|e| panic!("{}: {e} (listed on scenes/README.md)", rel.display()));
        let sha = pathtracer::partial::sha256_hex(&bytes);
        assert_eq!(sha, &c[2], "{}: its SHA-256 is not the one scenes/README.md gives", rel.display());
        listed.insert(rel);
    }
    assert_eq!(listed.iter().filter(|p| p.extension().is_some_and(|x| x == "dae")).count(), 20, "the 20 CS184 scenes");
    assert_eq!(listed.iter().filter(|p| p.extension().is_some_and(|x| x == "exr")).count(), 4, "the 4 environment maps");
    for p in common::files_under(&root().join("scenes")) {
        let rel = p.strip_prefix(root()).unwrap().to_path_buf();
        let name = rel.file_name().unwrap().to_string_lossy();
        if name == "README.md" || name.starts_with("LICENSE") {
            continue;
        }
        assert!(listed.contains(&rel), "{} is not on scenes/README.md", rel.display());
    }
}


/// The "Measured DATE at commit X on CPU." sentences of the README's three
/// generated tables (bench, error at equal time, verdicts), in that order;
/// `None` for a table missing its markers or its sentence.
/// The text from `<!-- NAME:start` to `<!-- NAME:end -->` (the generated tables' markers).
fn marked<'a>(text: &'a str, name: &str) -> Option<&'a str> {
    let start = text.find(&format!("<!-- {name}:start"))?;
    let len = text[start..].find(&format!("<!-- {name}:end -->"))?;
    Some(&text[start..start + len])
}

fn headline_provenance(readme: &str) -> Vec<Option<String>> {
    let sentence = Regex::new(r"Measured \d{4}-\d{2}-\d{2} at commit ([^ ]+) on ([^.\n]+)\.").unwrap();
    ["bench", "speed-vs-error", "verdicts"]
        .iter()
        .map(|name| {
            let found: Vec<String> = sentence.captures_iter(marked(readme, name)?).map(|c| format!("commit {} on {}", &c[1], &c[2])).collect();
            (found.len() == 1).then(|| found[0].clone())
        })
        .collect()
}

/// Why the headline tables' provenance fails, or `None`: each of the three
/// names one commit and CPU, the same for all, and a commit that reproduces
/// them (not "+changes").
fn headline_problem(readme: &str) -> Option<String> {
    let p = headline_provenance(readme);
    if let Some(i) = p.iter().position(|s| s.is_none()) {
        return Some(format!("the README's {} table has no single \"Measured DATE at commit X on CPU.\" sentence", ["bench", "error", "verdicts"][i]));
    }
    let p: Vec<String> = p.into_iter().flatten().collect();
    if p.iter().any(|s| s.contains("+changes")) {
        return Some(format!("a headline table was measured on a dirty tree: {p:?}"));
    }
    (p.iter().any(|s| *s != p[0])).then(|| format!("the headline tables come from different commits or CPUs: {p:?} (run scripts/refresh-headlines.sh)"))
}

#[test]
fn the_headline_check_catches_mixed_provenance() {
    let table = |name: &str, commit: &str, cpu: &str| format!("<!-- {name}:start -->\nA table. Measured 2026-11-29 at commit {commit} on {cpu}.\n| a |\n<!-- {name}:end -->\n");
    let good = [table("bench", "e3ea54833f80", "2-vCPU AMD EPYC 9R14"), table("speed-vs-error", "e3ea54833f80", "2-vCPU AMD EPYC 9R14"), table("verdicts", "e3ea54833f80", "2-vCPU AMD EPYC 9R14")].concat();
    assert_eq!(headline_problem(&good), None);
    let cpu = [table("bench", "e3ea54833f80", "2-vCPU Intel(R) Xeon(R) Processor"), table("speed-vs-error", "e3ea54833f80", "2-vCPU AMD EPYC 9R14"), table("verdicts", "e3ea54833f80", "2-vCPU AMD EPYC 9R14")].concat();
    assert!(headline_problem(&cpu).unwrap().contains("different commits or CPUs"));
    let commit = good.replacen("e3ea54833f80", "948abe6abcde", 1);
    assert!(headline_problem(&commit).unwrap().contains("different commits or CPUs"));
    let dirty = good.replace("e3ea54833f80", "e3ea54833f80+changes");
    assert!(headline_problem(&dirty).unwrap().contains("dirty tree"));
    let missing = good.replacen("Measured", "Timed", 1);
    assert!(headline_problem(&missing).unwrap().contains("bench table"));
}

/// The README's three headline tables were measured together: one commit,
/// one CPU (`scripts/refresh-headlines.sh` writes them).
#[test]
fn the_headline_tables_name_one_commit_and_one_cpu() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    if let Some(problem) = headline_problem(&readme) {
        panic!("README.md: {problem}");
    }
}

/// The rows `validation/speed_vs_error.py` makes of `docs/validation/speed-vs-error.csv`
/// (its `ratio_table`), or why the CSV cannot be read.
fn error_rows_of_csv(csv: &str) -> Result<Vec<String>, String> {
    let mut lines = csv.lines().filter(|l| !l.trim().is_empty());
    lines.next().filter(|l| l.starts_with("# ")).ok_or("no '# date=...' provenance line")?;
    let head: Vec<&str> = lines.next().ok_or("no header")?.split(',').collect();
    let runs = head.iter().filter(|h| h.starts_with("run")).count();
    let number = |s: &str| s.parse::<f64>().map_err(|e| format!("'{s}': {e}"));
    let mut rows = Vec::new();
    for line in lines {
        let c: Vec<&str> = line.split(',').collect();
        if c.len() != 8 + runs {
            return Err(format!("{} fields in '{line}', expected {}", c.len(), 8 + runs));
        }
        let ratios: Vec<String> = c[4..4 + runs].iter().map(|x| if x.is_empty() { Ok("–".to_string()) } else { number(x).map(|v| format!("{v:.2}")) }).collect::<Result<_, _>>()?;
        let costs = &c[4 + runs..];
        let fits = if costs[0].is_empty() {
            "– | –".to_string()
        } else {
            format!("{:.3} / {:.3} | {:.2} / {:.2}", number(costs[0])?, number(costs[1])?, number(costs[2])?, number(costs[3])?)
        };
        rows.push(format!("| {} | {} | {} | {} | {fits} |", c[0], c[1], c[2], ratios.join(" | ")));
    }
    Ok(rows)
}

/// The table rows between `<!-- speed-vs-error:start -->` and its end marker.
fn error_rows_of_page(page: &str) -> Vec<String> {
    let Some(table) = marked(page, "speed-vs-error") else { return Vec::new() };
    table.lines().filter(|l| l.starts_with("| ") && !l.starts_with("| case ")).map(str::to_string).collect()
}

/// The error page's table is its CSV, digit for digit (the script pastes it from a run or
/// from the CSV; both must give the same table), and names the CSV's date, commit and CPU.
#[test]
fn the_error_table_is_its_csv() {
    let csv = std::fs::read_to_string(root().join("docs/validation/speed-vs-error.csv")).unwrap();
    let page = std::fs::read_to_string(root().join("docs/validation/speed-vs-error.md")).unwrap();
    let from_csv = error_rows_of_csv(&csv).unwrap_or_else(|e| panic!("docs/validation/speed-vs-error.csv: {e}"));
    let on_page = error_rows_of_page(&page);
    assert!(!on_page.is_empty(), "docs/validation/speed-vs-error.md: no table between the speed-vs-error markers");
    for (i, (a, b)) in from_csv.iter().zip(&on_page).enumerate() {
        assert_eq!(a, b, "docs/validation/speed-vs-error.md: table row {} is not the CSV's (regenerate with validation/speed_vs_error.py --from-csv docs/validation/speed-vs-error.csv --paste)", i + 1);
    }
    assert_eq!(from_csv.len(), on_page.len(), "docs/validation/speed-vs-error.md: {} table rows, the CSV has {}", on_page.len(), from_csv.len());
    let meta = csv.lines().next().unwrap();
    let field = |k: &str| meta.split("; ").find_map(|kv| kv.trim_start_matches("# ").strip_prefix(&format!("{k}="))).map(str::to_string);
    let sentence = format!("Measured {} at commit {} on {}.", field("date").unwrap(), field("commit").unwrap(), field("cpu").unwrap());
    assert!(page.contains(&sentence), "docs/validation/speed-vs-error.md does not say \"{sentence}\" (the CSV's provenance)");
}

#[test]
fn the_error_table_check_catches_a_changed_digit() {
    let csv = "# date=2026-11-29; commit=abc; cpu=X\ncase,backend,reference,hemisphere,run1,fixed_s_ours,fixed_s_ref,ms_per_spp_ours,ms_per_spp_ref\nA,native,cycles,0,0.4250,0.0500,0.0010,21.9700,18.2500\nB,native,mitsuba,0,0.1200,,,,\n";
    let rows = error_rows_of_csv(csv).unwrap();
    // 0.4250 is stored as 0.42499999…: it rounds down, as Python's format does.
    assert_eq!(rows, ["| A | native | cycles | 0.42 | 0.050 / 0.001 | 21.97 / 18.25 |", "| B | native | mitsuba | 0.12 | – | – |"]);
    let page = format!("<!-- speed-vs-error:start -->\n| case | ours |\n{}\n{}\n<!-- speed-vs-error:end -->", rows[0].replace("0.42", "0.43"), rows[1]);
    assert_ne!(error_rows_of_page(&page), rows);
    assert!(error_rows_of_csv("case,backend\nA,b\n").is_err());
}
