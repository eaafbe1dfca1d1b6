//! The layout keeps its shape: the library's modules import one another
//! without circles, nothing in the library reaches the application (`app`)
//! or reads the environment, and no function outside the SIMD traversal
//! kernels grows past 120 lines. Read from the source text: a module's
//! imports are its `use crate::…`/`use super::…` lines and the `crate::…`
//! paths in its code, test modules left out.

mod common;

use regex::Regex;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

type Module = Vec<String>;

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// Every module file of the library (test-only files and the binary's
/// `main.rs` aside), by module path: `src/a/b.rs` and `src/a/b/mod.rs` are
/// `a::b`, `src/lib.rs` the crate root.
fn modules() -> BTreeMap<Module, PathBuf> {
    let mut out = BTreeMap::new();
    for p in common::files_under(&src()) {
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        if !name.ends_with(".rs") || name == "tests.rs" || name.ends_with("_tests.rs") {
            continue;
        }
        let rel = p.strip_prefix(src()).unwrap().with_extension("");
        let mut parts: Module = rel.components().map(|c| c.as_os_str().to_string_lossy().to_string()).collect();
        if parts == ["main"] {
            continue;
        }
        if parts.last().is_some_and(|l| l == "mod" || l == "lib") {
            parts.pop();
        }
        out.insert(parts, p);
    }
    out
}

/// The text without `#[cfg(test)] mod … { … }` blocks and `//` comments.
fn code(text: &str) -> String {
    let test_mod = Regex::new(r"#\[cfg\(test\)\]\s*(pub(\([^)]*\))?\s+)?mod\s+\w+\s*\{").unwrap();
    let mut out = String::new();
    let mut rest = text;
    while let Some(m) = test_mod.find(rest) {
        out.push_str(&rest[..m.start()]);
        let mut depth = 1;
        let bytes = rest.as_bytes();
        let mut j = m.end();
        while depth > 0 && j < bytes.len() {
            match bytes[j] {
                b'{' => depth += 1,
                b'}' => depth -= 1,
                _ => {}
            }
            j += 1;
        }
        rest = &rest[j..];
    }
    out.push_str(rest);
    out.lines().map(|l| l.split("//").next().unwrap()).collect::<Vec<_>>().join("\n")
}

/// The paths a `use` group names: `a::{b, c::{d, e}}` is `a::b`, `a::c::d`, `a::c::e`.
fn expand(prefix: &[String], body: &str) -> Vec<Vec<String>> {
    let mut items = Vec::new();
    let (mut depth, mut cur) = (0, String::new());
    for ch in body.chars() {
        match ch {
            '{' => depth += 1,
            '}' => depth -= 1,
            _ => {}
        }
        if ch == ',' && depth == 0 {
            items.push(std::mem::take(&mut cur));
        } else {
            cur.push(ch);
        }
    }
    items.push(cur);
    let mut out = Vec::new();
    for it in items.iter().map(|i| i.trim()).filter(|i| !i.is_empty()) {
        if let Some(open) = it.find('{') {
            let head: Vec<String> = it[..open].split("::").filter(|x| !x.is_empty()).map(String::from).collect();
            let inner = &it[open + 1..it.rfind('}').unwrap()];
            out.extend(expand(&[prefix, &head[..]].concat(), inner));
        } else {
            let name = it.split(" as ").next().unwrap();
            out.push([prefix.to_vec(), name.split("::").filter(|x| !x.is_empty()).map(String::from).collect()].concat());
        }
    }
    out
}

/// The module a path starting with `crate`, `super` or `self` lands in,
/// seen from module `base`: the longest prefix that is a module file.
fn resolve(mods: &BTreeMap<Module, PathBuf>, base: &Module, path: &[String]) -> Option<Module> {
    let (mut cur, mut rest): (Module, &[String]) = match path.first().map(String::as_str) {
        Some("crate") => (Vec::new(), &path[1..]),
        Some("super" | "self") => (base.clone(), path),
        _ => return None,
    };
    while let Some(first) = rest.first() {
        match first.as_str() {
            "super" => {
                cur.pop();
            }
            "self" => {}
            _ => break,
        }
        rest = &rest[1..];
    }
    let full: Module = [cur, rest.to_vec()].concat();
    (0..=full.len()).rev().map(|k| full[..k].to_vec()).find(|m| mods.contains_key(m))
}

/// Module → the modules it imports.
fn imports() -> BTreeMap<Module, BTreeSet<Module>> {
    let mods = modules();
    let use_line = Regex::new(r"\buse\s+((?:crate|super|self)(?:::\w+)*)(?:::\{([^;]*)\})?\s*(?:as\s+\w+)?;").unwrap();
    let inline = Regex::new(r"\b((?:crate|super)(?:::\w+)+)").unwrap();
    let mut out: BTreeMap<Module, BTreeSet<Module>> = BTreeMap::new();
    for (m, file) in &mods {
        let text = code(&std::fs::read_to_string(file).unwrap());
        let mut paths: Vec<Vec<String>> = Vec::new();
        for c in use_line.captures_iter(&text) {
            let pre: Vec<String> = c[1].split("::").map(String::from).collect();
            match c.get(2) {
                Some(group) => paths.extend(expand(&pre, group.as_str())),
                None => paths.push(pre),
            }
        }
        for c in inline.captures_iter(&text) {
            paths.push(c[1].split("::").map(String::from).collect());
        }
        let set = out.entry(m.clone()).or_default();
        for p in paths {
            if let Some(r) = resolve(&mods, m, &p).filter(|r| r != m) {
                set.insert(r);
            }
        }
    }
    out
}

/// The circles (strongly connected sets of more than one) of a graph.
fn circles<T: Ord + Clone>(edges: &BTreeSet<(T, T)>) -> Vec<Vec<T>> {
    let nodes: BTreeSet<T> = edges.iter().flat_map(|(a, b)| [a.clone(), b.clone()]).collect();
    let reach = |from: &T| -> BTreeSet<T> {
        let mut seen = BTreeSet::new();
        let mut stack = vec![from.clone()];
        while let Some(n) = stack.pop() {
            for (a, b) in edges {
                if *a == n && seen.insert(b.clone()) {
                    stack.push(b.clone());
                }
            }
        }
        seen
    };
    let reaches: BTreeMap<T, BTreeSet<T>> = nodes.iter().map(|n| (n.clone(), reach(n))).collect();
    let mut out: Vec<Vec<T>> = Vec::new();
    for n in &nodes {
        let mut c: Vec<T> = nodes.iter().filter(|m| *m == n || (reaches[n].contains(*m) && reaches[*m].contains(n))).cloned().collect();
        c.sort();
        if c.len() > 1 && !out.contains(&c) {
            out.push(c);
        }
    }
    out
}

fn is_ancestor(a: &Module, b: &Module) -> bool {
    a.len() < b.len() && b[..a.len()] == a[..]
}

#[test]
fn the_library_has_no_import_circles() {
    let graph = imports();
    assert!(graph.len() > 40, "only {} modules read: is the reader broken?", graph.len());
    // Between top-level modules (scene, accel, light, render, ...).
    let top: BTreeSet<(String, String)> = graph
        .iter()
        .flat_map(|(a, bs)| bs.iter().map(move |b| (a, b)))
        .filter(|(a, b)| !a.is_empty() && !b.is_empty() && a[0] != b[0])
        .map(|(a, b)| (a[0].clone(), b[0].clone()))
        .collect();
    assert!(top.contains(&("render".to_string(), "light".to_string())), "the reader missed render's imports of light");
    assert!(circles(&top).is_empty(), "top-level modules import one another in a circle: {:?}", circles(&top));
    // Between the files of one folder (a parent's mod.rs aside: it declares its files).
    let siblings: BTreeSet<(Module, Module)> = graph
        .iter()
        .flat_map(|(a, bs)| bs.iter().map(move |b| (a.clone(), b.clone())))
        .filter(|(a, b)| !is_ancestor(a, b) && !is_ancestor(b, a) && a[..a.len().saturating_sub(1)] == b[..b.len().saturating_sub(1)])
        .collect();
    let found: Vec<String> = circles(&siblings).iter().map(|c| c.iter().map(|m| m.join("::")).collect::<Vec<_>>().join(" <-> ")).collect();
    assert!(found.is_empty(), "files of one folder import one another in a circle: {found:?}");
}

#[test]
fn the_circle_finder_finds_circles() {
    let e: BTreeSet<(u8, u8)> = [(1, 2), (2, 3), (3, 1), (3, 4), (5, 5)].into_iter().collect();
    assert_eq!(circles(&e), vec![vec![1, 2, 3]]);
    let mods: BTreeMap<Module, PathBuf> = [vec![], vec!["a".to_string()], vec!["a".to_string(), "b".to_string()]].into_iter().map(|m| (m, PathBuf::new())).collect();
    let base = vec!["a".to_string(), "b".to_string()];
    let p = |s: &str| s.split("::").map(String::from).collect::<Vec<_>>();
    assert_eq!(resolve(&mods, &base, &p("super::Thing")), Some(vec!["a".to_string()]));
    assert_eq!(resolve(&mods, &base, &p("crate::a::b::f")), Some(base.clone()));
    assert_eq!(expand(&p("crate::a"), "b::{c, d as e}, f").len(), 3);
}

#[test]
fn the_library_knows_nothing_of_the_application_or_the_environment() {
    let mods = modules();
    let mut bad = Vec::new();
    for (m, file) in &mods {
        if m.first().is_some_and(|f| f == "app") {
            continue;
        }
        let text = code(&std::fs::read_to_string(file).unwrap());
        for needle in ["crate::app", "std::env::var", "env::var_os", "std::env::args"] {
            if text.contains(needle) {
                bad.push(format!("{}: {needle}", file.display()));
            }
        }
    }
    assert!(bad.is_empty(), "the library reaches the application or reads the environment: {bad:?}");
    assert!(imports().iter().any(|(m, bs)| m.first().is_some_and(|f| f == "app") && bs.iter().any(|b| b.first().is_some_and(|f| f == "render"))), "the reader missed the application's imports");
}

/// The traversal kernels are long SIMD loops kept whole on purpose (every
/// lane the same operations, one frame, no calls in the loop).
const KERNELS: &str = "accel/wide/";

#[test]
fn no_function_outside_the_kernels_passes_120_lines() {
    let fn_start = Regex::new(r"^\s*(pub(\([^)]*\))?\s+)?(const\s+)?(unsafe\s+)?fn\s+(\w+)").unwrap();
    let mut long = Vec::new();
    for file in modules().values() {
        let rel = file.strip_prefix(src()).unwrap().to_string_lossy().replace('\\', "/");
        if rel.starts_with(KERNELS) {
            continue;
        }
        let text = std::fs::read_to_string(file).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        let mut i = 0;
        while i < lines.len() {
            let Some(c) = fn_start.captures(lines[i]) else {
                i += 1;
                continue;
            };
            let (mut depth, mut opened, mut j) = (0i32, false, i);
            while j < lines.len() {
                for ch in lines[j].chars() {
                    match ch {
                        '{' => {
                            depth += 1;
                            opened = true;
                        }
                        '}' => depth -= 1,
                        _ => {}
                    }
                }
                if (opened && depth == 0) || (!opened && lines[j].trim_end().ends_with(';')) {
                    break;
                }
                j += 1;
            }
            if opened && j - i + 1 > 120 {
                long.push(format!("{rel}: {} ({} lines)", &c[5], j - i + 1));
            }
            i = if opened { j + 1 } else { i + 1 };
        }
    }
    assert!(long.is_empty(), "functions past 120 lines: {long:?}");
}

/// The layers picture of docs/design/modules.md, top layer first: each a
/// name and its top-level modules.
fn documented_layers() -> Vec<(String, Vec<String>)> {
    let page = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/design/modules.md")).unwrap();
    let block = page.split("<!-- layers:start -->").nth(1).and_then(|r| r.split("<!-- layers:end -->").next()).expect("the layers markers in docs/design/modules.md");
    block
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with("```"))
        .map(|l| {
            let mut w = l.split_whitespace().map(String::from);
            (w.next().unwrap(), w.collect())
        })
        .collect()
}

#[test]
fn the_layers_picture_is_the_code() {
    let layers = documented_layers();
    let level = |m: &str| layers.iter().position(|(_, ms)| ms.iter().any(|x| x == m));
    let top: BTreeSet<String> = modules().keys().filter_map(|m| m.first().cloned()).collect();
    let missing: Vec<&String> = top.iter().filter(|m| level(m).is_none()).collect();
    assert!(missing.is_empty(), "modules missing from the layers of docs/design/modules.md: {missing:?}");
    let listed: Vec<&String> = layers.iter().flat_map(|(_, ms)| ms).filter(|m| !top.contains(*m)).collect();
    assert!(listed.is_empty(), "docs/design/modules.md lists modules the code has not: {listed:?}");
    let mut upward = Vec::new();
    for (a, bs) in imports() {
        for b in bs {
            let (Some(x), Some(y)) = (a.first(), b.first()) else { continue };
            if level(y) < level(x) {
                upward.push(format!("{} ({}) imports {} ({})", a.join("::"), layers[level(x).unwrap()].0, b.join("::"), layers[level(y).unwrap()].0));
            }
        }
    }
    assert!(upward.is_empty(), "imports that run up the layers of docs/design/modules.md: {upward:?}");
}
