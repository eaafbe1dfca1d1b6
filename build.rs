//! Finds Embree 3 and Embree 4 headers, compiles the C shim in `native/` once
//! per major found (each build loads its library at run time, see
//! `native/shim.c`), and generates the shim's Rust bindings with bindgen.
//! Without a major's headers (or without libclang for bindgen) the crate still
//! builds: that backend then reports why it is missing. Nothing is downloaded.
//!
//! Search order per major: `PATHTRACER_NO_EMBREE` disables (`1` or `all`:
//! both; `3` or `4`: that major); `EMBREE3_DIR` / `EMBREE4_DIR` (with
//! `include/` and `lib/`), or `EMBREE_DIR` for whichever major its headers
//! are; for Embree 4, `third_party/embree4` (what `scripts/install-deps.sh`
//! installs); pkg-config `embree3` / `embree4`; the standard include folders
//! (Debian ships no .pc file for Embree 3).

use std::env;
use std::path::{Path, PathBuf};
use std::process::Command;

struct Found {
    include: Option<PathBuf>,
    lib_dir: Option<PathBuf>,
}

fn has_header(include: &Path, major: u32) -> bool {
    include.join(format!("embree{major}/rtcore.h")).exists()
}

fn header_version(include: Option<&Path>, major: u32) -> String {
    let inc = include.map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("/usr/include"));
    let config = std::fs::read_to_string(inc.join(format!("embree{major}/rtcore_config.h"))).unwrap_or_default();
    config
        .lines()
        .find_map(|l| l.strip_prefix("#define RTC_VERSION_STRING ").map(|v| v.trim().trim_matches('"').to_string()))
        .unwrap_or_else(|| format!("{major}.x"))
}

fn pkg_config(name: &str) -> Option<(Option<PathBuf>, Option<PathBuf>)> {
    let out = Command::new("pkg-config").args(["--cflags-only-I", "--libs-only-L", name]).output().ok()?;
    if !out.status.success() {
        return None;
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let mut inc = None;
    let mut lib = None;
    for w in text.split_whitespace() {
        if let Some(p) = w.strip_prefix("-I") {
            inc = Some(PathBuf::from(p));
        } else if let Some(p) = w.strip_prefix("-L") {
            lib = Some(PathBuf::from(p));
        }
    }
    Some((inc, lib))
}

fn disabled(major: u32) -> bool {
    env::var("PATHTRACER_NO_EMBREE").is_ok_and(|v| v == "1" || v == "all" || v.split(',').any(|m| m.trim() == major.to_string()))
}

fn find(major: u32) -> Result<Found, String> {
    if disabled(major) {
        return Err("disabled at build time by PATHTRACER_NO_EMBREE".into());
    }
    let from_dir = |dir: PathBuf| Found { include: Some(dir.join("include")), lib_dir: Some(dir.join("lib")) };
    if let Some(dir) = env::var_os(format!("EMBREE{major}_DIR")) {
        let dir = PathBuf::from(dir);
        if !has_header(&dir.join("include"), major) {
            return Err(format!("EMBREE{major}_DIR={} has no include/embree{major}/rtcore.h", dir.display()));
        }
        return Ok(from_dir(dir));
    }
    if let Some(dir) = env::var_os("EMBREE_DIR").map(PathBuf::from).filter(|d| has_header(&d.join("include"), major)) {
        return Ok(from_dir(dir));
    }
    if major == 4 {
        let local = PathBuf::from(env::var("CARGO_MANIFEST_DIR").unwrap()).join("third_party/embree4");
        if has_header(&local.join("include"), 4) {
            return Ok(from_dir(local));
        }
    }
    if let Some((include, lib_dir)) = pkg_config(&format!("embree{major}")) {
        if include.as_deref().is_none_or(|i| has_header(i, major)) {
            return Ok(Found { include, lib_dir });
        }
    }
    for inc in ["/usr/include", "/usr/local/include", "/opt/homebrew/include"] {
        if has_header(Path::new(inc), major) {
            let include = if inc == "/usr/include" { None } else { Some(PathBuf::from(inc)) };
            let lib_dir = include.as_ref().map(|i| i.with_file_name("lib"));
            return Ok(Found { include, lib_dir });
        }
    }
    Err(if major == 3 {
        "Embree 3 headers not found; install them (Debian/Ubuntu: apt-get install libembree-dev, or scripts/install-deps.sh) and rebuild".into()
    } else {
        "Embree 4 headers not found; run scripts/install-deps.sh (Embree 4 from PyPI's embreex4 wheel and the embree4-sys crate's headers into third_party/embree4) and rebuild".into()
    })
}

fn bindings(out: &Path) -> Result<(), String> {
    let bindings = std::panic::catch_unwind(|| {
        bindgen::Builder::default()
            .header("native/shim.h")
            .allowlist_function("pt_.*")
            .allowlist_type("pt_.*")
            .allowlist_var("PT_.*")
            .layout_tests(false)
            .generate()
    })
    .map_err(|_| "bindgen could not load libclang; install libclang-dev (Debian/Ubuntu) and rebuild".to_string())?
    .map_err(|e| format!("bindgen failed on native/shim.h ({e}); install libclang-dev and rebuild"))?;
    bindings.write_to_file(out.join("embree_shim.rs")).map_err(|e| format!("writing bindings: {e}"))
}

/// Compile the shim for `major`; returns the header version.
fn compile(major: u32, found: &Found) -> Result<String, String> {
    // The library files dlopen tries: the folder found first (absolute, so
    // a project-local Embree needs no LD_LIBRARY_PATH), then the system's.
    let soname = format!("libembree{major}.so.{major}");
    let mut libs = Vec::new();
    if let Some(dir) = &found.lib_dir {
        let dir = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.clone());
        libs.push(dir.join(&soname).display().to_string());
    }
    libs.push(soname);
    let mut cc = cc::Build::new();
    cc.file("native/shim.c")
        .flag_if_supported("-std=gnu11")
        .opt_level(2)
        .define("PT_EMBREE_MAJOR", major.to_string().as_str())
        .define("PT_API_FN", format!("pt_embree{major}_api").as_str())
        .define("PT_EMBREE_LIBS", format!("\"{}\"", libs.join(":")).as_str());
    if let Some(inc) = &found.include {
        cc.include(inc);
    }
    cc.try_compile(&format!("pt_embree{major}_shim")).map_err(|e| format!("compiling native/shim.c for Embree {major} failed: {e}"))?;
    Ok(header_version(found.include.as_deref(), major))
}

/// The files the binary is built from: a change to any of them makes the
/// build differ from its commit.
const BINARY_INPUTS: [&str; 6] = ["src", "native", "build.rs", "Cargo.toml", "Cargo.lock", "scenes/cs184/sky/CBspheres_lambertian.dae"];

/// The commit the binary is built from, for `--version`: "commit X", with
/// "+ changes" where the binary's inputs differ from it, or "built outside
/// git". Reruns when the commit, the index or an input changes.
fn git_commit() -> String {
    let root = PathBuf::from(env::var("CARGO_MANIFEST_DIR").unwrap());
    let git = |args: &[&str]| Command::new("git").arg("-C").arg(&root).args(args).output().ok().filter(|o| o.status.success()).map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string());
    let (Some(commit), Some(git_dir), Some(common_dir)) =
        (git(&["rev-parse", "--short=12", "HEAD"]), git(&["rev-parse", "--absolute-git-dir"]), git(&["rev-parse", "--path-format=absolute", "--git-common-dir"]))
    else {
        return "built outside git".into();
    };
    // HEAD and the index are the checkout's own (a worktree's are under
    // .git/worktrees/NAME); the refs are the repository's. Only files that
    // exist are watched: cargo takes a missing one as changed and would run
    // this script, and compile the crate, on every build. The folder of
    // branch refs catches a branch's first loose ref beside packed-refs.
    let (git_dir, common_dir) = (PathBuf::from(git_dir), PathBuf::from(common_dir));
    let watched = [git_dir.join("HEAD"), git_dir.join("index"), common_dir.join("packed-refs"), common_dir.join("refs/heads")];
    for f in watched.iter().filter(|f| f.exists()) {
        println!("cargo:rerun-if-changed={}", f.display());
    }
    for input in BINARY_INPUTS {
        println!("cargo:rerun-if-changed={input}");
    }
    let mut status = vec!["status", "--porcelain", "--untracked-files=no", "--"];
    status.extend(BINARY_INPUTS);
    match git(&status) {
        Some(s) if s.is_empty() => format!("commit {commit}"),
        _ => format!("commit {commit} + changes"),
    }
}

fn main() {
    println!("cargo:rustc-env=PATHTRACER_GIT_COMMIT={}", git_commit());
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=native/shim.c");
    println!("cargo:rerun-if-changed=native/shim.h");
    println!("cargo:rerun-if-changed=third_party/embree4/VERSIONS");
    for v in ["PATHTRACER_NO_EMBREE", "EMBREE_DIR", "EMBREE3_DIR", "EMBREE4_DIR", "PKG_CONFIG_PATH", "LIBCLANG_PATH"] {
        println!("cargo:rerun-if-env-changed={v}");
    }
    for cfg in ["has_embree", "has_embree3", "has_embree4"] {
        println!("cargo:rustc-check-cfg=cfg({cfg})");
    }
    let out = PathBuf::from(env::var("OUT_DIR").unwrap());
    let found = [3, 4].map(|major| (major, find(major)));
    let mut status = [String::new(), String::new()];
    let any = found.iter().any(|(_, f)| f.is_ok());
    // Bindings only where a shim will be built; libclang is needed for them.
    let bound = if any { bindings(&out) } else { Err(String::new()) };
    let mut built = 0;
    for (k, (major, f)) in found.into_iter().enumerate() {
        status[k] = match (f, &bound) {
            (Err(why), _) => why,
            (Ok(_), Err(why)) => why.clone(),
            (Ok(found), Ok(())) => match compile(major, &found) {
                Ok(version) => {
                    println!("cargo:rustc-cfg=has_embree{major}");
                    built += 1;
                    format!("headers {version}")
                }
                Err(why) => why,
            },
        };
        if !status[k].starts_with("headers") {
            println!("cargo:warning=embree{major} backend disabled: {}", status[k]);
        }
    }
    if built > 0 {
        println!("cargo:rustc-cfg=has_embree");
        println!("cargo:rustc-link-lib=dylib=dl");
        println!("cargo:rustc-link-lib=dylib=pthread");
    }
    println!("cargo:rustc-env=PATHTRACER_EMBREE3_STATUS={}", status[0]);
    println!("cargo:rustc-env=PATHTRACER_EMBREE4_STATUS={}", status[1]);
}
