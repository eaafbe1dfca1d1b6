//! Documentation that cannot rot: every `pathtracer …` command shown in
//! README.md and docs/ runs (at small sizes), every relative link resolves,
//! the generated command-line reference is the program's, and every
//! `PATHTRACER_*` switch the code reads is documented.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// README.md and every Markdown file under docs/, sorted.
fn markdown_files() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "md") {
                out.push(p);
            }
        }
    }
    let mut v = vec![root().join("README.md")];
    walk(&root().join("docs"), &mut v);
    v.sort();
    v
}

fn read(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter_map(|c| if c.is_alphanumeric() || c == '-' || c == '_' { Some(c) } else if c == ' ' { Some('-') } else { None })
        .collect()
}

/// The anchors a Markdown file has (its headings'), outside code blocks.
fn anchors(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut in_code = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            in_code = !in_code;
            continue;
        }
        if !in_code && line.starts_with('#') {
            out.insert(slug(line.trim_start_matches('#')));
        }
    }
    out
}

/// Every `[text](target)` and `![alt](target)` outside code, with its line.
fn links(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut in_code = false;
    for (n, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            in_code = !in_code;
            continue;
        }
        if in_code {
            continue;
        }
        // Inline code spans are not links.
        let mut clean = String::new();
        for (i, part) in line.split('`').enumerate() {
            if i % 2 == 0 {
                clean.push_str(part);
            }
        }
        let mut rest = clean.as_str();
        while let Some(i) = rest.find("](") {
            let after = &rest[i + 2..];
            let Some(end) = after.find(')') else { break };
            out.push((n + 1, after[..end].to_string()));
            rest = &after[end..];
        }
    }
    out
}

#[test]
fn every_relative_link_resolves() {
    let mut bad = Vec::new();
    let mut checked = 0;
    for file in markdown_files() {
        let text = read(&file);
        for (line, target) in links(&text) {
            if target.starts_with("http://") || target.starts_with("https://") || target.starts_with("mailto:") {
                continue;
            }
            checked += 1;
            let (path, anchor) = target.split_once('#').map_or((target.as_str(), None), |(p, a)| (p, Some(a)));
            let resolved = if path.is_empty() { file.clone() } else { file.parent().unwrap().join(path) };
            if !resolved.exists() {
                bad.push(format!("{}:{line}: {target}: no such file", file.display()));
                continue;
            }
            if let Some(a) = anchor {
                if resolved.extension().is_some_and(|x| x == "md") && !anchors(&read(&resolved)).contains(a) {
                    bad.push(format!("{}:{line}: {target}: no heading '#{a}' in {}", file.display(), resolved.display()));
                }
            }
        }
    }
    assert!(checked > 50, "only {checked} links found: is the link parser broken?");
    assert!(bad.is_empty(), "{} broken links:\n{}", bad.len(), bad.join("\n"));
}

/// A link checker that cannot fail proves nothing: these must be caught.
#[test]
fn the_link_checker_catches_broken_links() {
    let text = "see [a](missing.md) and `[not](a-link.md)` and\n```\n[nor](this.md)\n```\n## A Heading, here\n";
    let found: Vec<String> = links(text).into_iter().map(|(_, t)| t).collect();
    assert_eq!(found, vec!["missing.md"]);
    assert!(anchors(text).contains("a-heading-here"));
}

#[test]
fn the_cli_reference_is_the_programs() {
    let out = Command::new(env!("CARGO_BIN_EXE_pathtracer")).arg("cli-reference").output().unwrap();
    assert!(out.status.success());
    let generated = String::from_utf8(out.stdout).unwrap();
    let file = root().join("docs/reference/cli.md");
    let committed = read(&file);
    assert!(
        generated == committed,
        "{} is stale: regenerate it with `cargo run --release -- cli-reference > docs/reference/cli.md`",
        file.display()
    );
    // Every subcommand, integrator and backend is in it.
    for word in ["## pathtracer bench", "## pathtracer export", "## pathtracer merge", "## pathtracer verify", "## pathtracer compare", "## pathtracer completions", "## pathtracer man", "`depth`", "`object-id`", "`embree-high`", "`brute`"] {
        assert!(committed.contains(word), "{word} missing from the CLI reference");
    }
}

#[test]
fn every_environment_switch_is_documented() {
    let doc = read(&root().join("docs/reference/environment.md"));
    let mut names = BTreeSet::new();
    let mut scan = |dir: &Path| {
        let mut stack = vec![dir.to_path_buf()];
        while let Some(d) = stack.pop() {
            let entries: Vec<PathBuf> = if d.is_dir() { std::fs::read_dir(&d).unwrap().map(|e| e.unwrap().path()).collect() } else { vec![d.clone()] };
            for p in entries {
                if p.is_dir() {
                    stack.push(p);
                } else if p.extension().is_some_and(|x| ["rs", "sh", "py"].contains(&x.to_str().unwrap())) {
                    let text = std::fs::read_to_string(&p).unwrap_or_default();
                    for (i, _) in text.match_indices("PATHTRACER_") {
                        let name: String = text[i..].chars().take_while(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || *c == '_').collect();
                        if name.len() > "PATHTRACER_".len() {
                            names.insert(name);
                        }
                    }
                }
            }
        }
    };
    for d in ["src", "tests", "scripts", "validation", "examples", "build.rs"] {
        scan(&root().join(d));
    }
    assert!(names.contains("PATHTRACER_NO_EMBREE"), "the scan found {names:?}");
    let missing: Vec<&String> = names.iter().filter(|n| !doc.contains(&format!("`{n}")) && !doc.contains(&format!("`{n}`"))).collect();
    assert!(missing.is_empty(), "not in docs/reference/environment.md: {missing:?}");
}

/// One command line found in the documentation.
struct DocCommand {
    file: PathBuf,
    line: usize,
    env: Vec<(String, String)>,
    args: Vec<String>,
}

/// Split a command line into words (double and single quotes group).
fn words(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut quote = None;
    let mut any = false;
    for c in line.chars() {
        match (quote, c) {
            (None, '"' | '\'') => {
                quote = Some(c);
                any = true;
            }
            (Some(q), c) if c == q => quote = None,
            (None, c) if c.is_whitespace() => {
                if any {
                    out.push(std::mem::take(&mut cur));
                    any = false;
                }
            }
            (_, c) => {
                cur.push(c);
                any = true;
            }
        }
    }
    if any {
        out.push(cur);
    }
    out
}

/// The `pathtracer` (or `cargo run --release … --`) commands of every code
/// block, in order, grouped by block: a block's commands share a folder, so
/// a merge finds the parts rendered above it. Usage lines (with `<`, `[`,
/// `...`), other programs and ```text blocks (file contents) are skipped;
/// text after two spaces or ` #` is a comment.
fn doc_commands(file: &Path) -> Vec<Vec<DocCommand>> {
    let text = read(file);
    let mut blocks = Vec::new();
    let mut current: Option<Vec<DocCommand>> = None;
    let mut in_block = false;
    let mut pending = String::new();
    for (n, raw) in text.lines().enumerate() {
        if let Some(lang) = raw.trim_start().strip_prefix("```") {
            match (current.take(), in_block) {
                (Some(b), true) => blocks.push(b),
                (None, true) => {}
                // Shell blocks only: not program output, not a CI file's YAML.
                (_, false) => current = (!matches!(lang.trim(), "text" | "yaml" | "yml" | "json" | "toml")).then(Vec::new),
            }
            in_block = !in_block;
            continue;
        }
        let Some(block) = current.as_mut() else { continue };
        let mut line = raw.trim().trim_start_matches("$ ").to_string();
        if let Some(stripped) = line.strip_suffix('\\') {
            pending += stripped;
            continue;
        }
        line = std::mem::take(&mut pending) + &line;
        let line = line.split(" #").next().unwrap().split("  ").next().unwrap().trim().to_string();
        if line.contains(['<', '[']) || line.contains("...") || line.contains('…') {
            continue;
        }
        let mut w = words(&line);
        let mut env = Vec::new();
        while w.first().is_some_and(|x| x.contains('=') && !x.starts_with('-')) {
            let (k, v) = w.remove(0).split_once('=').map(|(k, v)| (k.to_string(), v.to_string())).unwrap();
            env.push((k, v));
        }
        let args = match w.first().map(String::as_str) {
            Some("pathtracer") => w[1..].to_vec(),
            Some("cargo") if w.get(1).map(String::as_str) == Some("run") && !w.iter().any(|x| x == "--example") => match w.iter().position(|x| x == "--") {
                Some(i) => w[i + 1..].to_vec(),
                None => Vec::new(),
            },
            _ => continue,
        };
        block.push(DocCommand { file: file.to_path_buf(), line: n + 1, env, args });
    }
    blocks.into_iter().filter(|b| !b.is_empty()).collect()
}

/// A fresh clone of the repository with nothing beside it: every file git
/// tracks, as the working tree holds it, copied into an empty temporary
/// folder (so an uncommitted change is tried as its commit will be).
fn fresh_clone(tag: &str) -> PathBuf {
    let out = Command::new("git").args(["ls-files", "-z", "--cached"]).current_dir(root()).output();
    let out = out.unwrap_or_else(|e| panic!("git ls-files: {e} (the documentation tests need git to make a fresh clone)"));
    assert!(out.status.success(), "git ls-files: {}", String::from_utf8_lossy(&out.stderr));
    let base = std::env::temp_dir().join(format!("pt-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&base);
    let clone = base.join("pathtracer");
    let mut copied = 0;
    for name in out.stdout.split(|&b| b == 0).filter(|n| !n.is_empty()) {
        let rel = Path::new(std::str::from_utf8(name).unwrap());
        let from = root().join(rel);
        if !from.is_file() {
            continue; // deleted in the working tree, not yet committed
        }
        let to = clone.join(rel);
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::copy(&from, &to).unwrap_or_else(|e| panic!("{}: {e}", from.display()));
        copied += 1;
    }
    assert!(copied > 100, "only {copied} tracked files: is this a git checkout?");
    assert!(!base.join("shared").exists());
    clone
}

/// The command at test size: frames of 40×30, at most 8 samples, bench on
/// 8192 rays of small scenes, and the help text's placeholder names bound
/// to files of the clone. Paths in the documentation stay as written: the
/// commands run from the clone's root, as the README says.
fn small(args: &[String]) -> Vec<String> {
    let bind = |a: &str| -> String {
        match a {
            "scene.dae" | "my-scene.dae" => "scenes/cs184/sky/CBempty.dae".into(),
            "bunny_unlit.dae" => "scenes/cs184/sky/bunny_unlit.dae".into(),
            "studio.exr" => "scenes/envmaps/studio.exr".into(),
            _ => a.to_string(),
        }
    };
    let mut a: Vec<String> = args.iter().map(|x| bind(x)).collect();
    if a.is_empty() {
        return a; // the demo render: as documented
    }
    let value_after = |a: &Vec<String>, flag: &str| a.iter().position(|x| x == flag);
    match a[0].as_str() {
        "bench" => {
            for w in a.iter_mut().skip(1) {
                // Generated scenes at 20k triangles: arch:2M -> arch:20k.
                if let Some((kind, _)) = w.rsplit_once(':').filter(|(_, n)| n.ends_with(['M', 'k']) || n.chars().all(|c| c.is_ascii_digit())) {
                    *w = format!("{kind}:20k");
                }
            }
            if let Some(i) = value_after(&a, "--threads") {
                a[i + 1] = "1".into();
            } else {
                a.extend(["--threads".into(), "1".into()]);
            }
            // A scene is a word that is neither a flag nor a flag's value.
            let takes_value = ["--backends", "--rays", "--passes", "--threads", "--csv", "--markdown", "--resume"];
            if !a.iter().enumerate().skip(1).any(|(i, x)| !x.starts_with('-') && !takes_value.contains(&a[i - 1].as_str())) {
                a.push("cow".into());
            }
            a.extend(["--rays".into(), "8192".into(), "--passes".into(), "1".into()]);
            if !a.iter().any(|x| x == "--no-render") {
                a.push("--no-render".into());
            }
        }
        "merge" | "verify" | "compare" | "man" | "completions" | "cli-reference" | "help" => {}
        "validate" => {
            // A short budget, no references (the harness is another test's):
            // every check runs, and may stay undecided (exit 2, accepted
            // below); whether the checks pass is tests/validate.rs's to say.
            match value_after(&a, "--budget") {
                Some(i) => a[i + 1] = "5s".into(),
                None => a.extend(["--budget".into(), "5s".into()]),
            }
            if !a.iter().any(|x| x == "--references") {
                a.extend(["--references".into(), "none".into()]);
            }
        }
        first if first.starts_with("--version") || first == "-V" || first == "--help" || first == "-h" => {}
        _ => {
            // A render (or export): small frame, few samples.
            let parts = value_after(&a, "--part").and_then(|i| a[i + 1].split_once('/').and_then(|(_, n)| n.parse::<u32>().ok())).unwrap_or(1);
            match value_after(&a, "-r") {
                Some(i) => {
                    a[i + 1] = "40".into();
                    a[i + 2] = "30".into();
                }
                None => a.extend(["-r".into(), "40".into(), "30".into()]),
            }
            if let Some(i) = value_after(&a, "-p") {
                a.splice(i + 1..i + 5, ["0", "0", "8", "8"].map(String::from));
            }
            if let Some(i) = value_after(&a, "-s") {
                let s: u32 = a[i + 1].parse().unwrap_or(1);
                a[i + 1] = s.min(8.max(parts)).to_string();
            }
        }
    }
    a
}

/// The entries of a folder, sorted.
fn entries(dir: &Path) -> BTreeSet<PathBuf> {
    std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect()
}

/// Every documented command runs in a fresh clone of the repository with
/// nothing beside it, from the clone's root; each code block's outputs are
/// removed before the next block runs, so no block lives off another's.
#[test]
fn every_documented_command_runs_from_a_fresh_clone() {
    let exe = env!("CARGO_BIN_EXE_pathtracer");
    let clone = fresh_clone("doc-commands");
    let pristine = entries(&clone);
    use pathtracer::accel::embree::{available, Major};
    let mut ran = 0;
    let mut failures = Vec::new();
    for file in markdown_files() {
        for block in doc_commands(&file) {
            for new in entries(&clone).difference(&pristine) {
                if new.is_dir() { std::fs::remove_dir_all(new).unwrap() } else { std::fs::remove_file(new).unwrap() }
            }
            let dir = &clone;
            for c in block {
                let missing = c.args.iter().any(|a| match a.as_str() {
                    "embree3" | "embree3-high" => !available(Major::V3),
                    "embree4" | "embree4-high" => !available(Major::V4),
                    "embree" | "embree-high" => !available(Major::V3) && !available(Major::V4),
                    _ => false,
                });
                if missing {
                    eprintln!("SKIPPED (that Embree cannot be used here): {}:{}", c.file.display(), c.line);
                    continue;
                }
                let args = small(&c.args);
                let out = Command::new(exe).args(&args).envs(c.env.iter().map(|(k, v)| (k, v))).env("CI", "true").env_remove("PATHTRACER_SCENES").current_dir(dir).output().unwrap();
                ran += 1;
                // validate at a test's budget may leave a check undecided (exit 2), never failed.
                let undecided = args.first().is_some_and(|a| a == "validate") && out.status.code() == Some(2) && String::from_utf8_lossy(&out.stderr).contains("could not be decided");
                if !out.status.success() && !undecided {
                    failures.push(format!(
                        "{}:{}: pathtracer {} (run as: {})\n  {}",
                        c.file.display(),
                        c.line,
                        c.args.join(" "),
                        args.join(" "),
                        String::from_utf8_lossy(&out.stderr).trim()
                    ));
                }
            }
        }
    }
    let _ = std::fs::remove_dir_all(clone.parent().unwrap());
    assert!(ran >= 30, "only {ran} documented commands found: is the extractor broken?");
    assert!(failures.is_empty(), "{} of {ran} documented commands failed:\n{}", failures.len(), failures.join("\n"));
    eprintln!("{ran} documented commands ran");
}
