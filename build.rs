//! Finds Embree, compiles the C shim in `native/` against it and generates its
//! Rust bindings with bindgen. Without Embree (or without libclang for
//! bindgen) the crate still builds: the `embree` backend then reports why it is
//! missing. Nothing is ever downloaded.
//!
//! Search order: `PATHTRACER_NO_EMBREE=1` disables it; `EMBREE_DIR` (with
//! `include/` and `lib/`); pkg-config `embree4`, then `embree3`; then the
//! standard include directories (Debian ships no .pc file for Embree 3).

use std::env;
use std::path::{Path, PathBuf};
use std::process::Command;

struct Found {
    major: u32,
    include: Option<PathBuf>,
    lib_dir: Option<PathBuf>,
}

fn header_major(include: &Path) -> Option<u32> {
    if include.join("embree4/rtcore.h").exists() {
        Some(4)
    } else if include.join("embree3/rtcore.h").exists() {
        Some(3)
    } else {
        None
    }
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

fn find_embree() -> Result<Found, String> {
    if env::var_os("PATHTRACER_NO_EMBREE").is_some_and(|v| v != "0") {
        return Err("disabled at build time by PATHTRACER_NO_EMBREE".into());
    }
    if let Some(dir) = env::var_os("EMBREE_DIR") {
        let dir = PathBuf::from(dir);
        let inc = dir.join("include");
        let major = header_major(&inc).ok_or_else(|| format!("EMBREE_DIR={} has no include/embree{{3,4}}/rtcore.h", dir.display()))?;
        return Ok(Found { major, include: Some(inc), lib_dir: Some(dir.join("lib")) });
    }
    for (name, major) in [("embree4", 4), ("embree3", 3)] {
        if let Some((include, lib_dir)) = pkg_config(name) {
            return Ok(Found { major, include, lib_dir });
        }
    }
    for inc in ["/usr/include", "/usr/local/include", "/opt/homebrew/include"] {
        if let Some(major) = header_major(Path::new(inc)) {
            let include = if inc == "/usr/include" { None } else { Some(PathBuf::from(inc)) };
            let lib_dir = include.as_ref().map(|i| i.with_file_name("lib"));
            return Ok(Found { major, include, lib_dir });
        }
    }
    Err("Embree headers not found; install Embree (Debian/Ubuntu: apt-get install libembree-dev libclang-dev) and rebuild".into())
}

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=native/shim.c");
    println!("cargo:rerun-if-changed=native/shim.h");
    for v in ["PATHTRACER_NO_EMBREE", "EMBREE_DIR", "PKG_CONFIG_PATH", "LIBCLANG_PATH"] {
        println!("cargo:rerun-if-env-changed={v}");
    }
    println!("cargo:rustc-check-cfg=cfg(has_embree)");

    let status = match build_shim() {
        Ok(major) => {
            println!("cargo:rustc-cfg=has_embree");
            format!("Embree {major}")
        }
        Err(reason) => {
            println!("cargo:warning=embree backend disabled: {reason}");
            reason
        }
    };
    println!("cargo:rustc-env=PATHTRACER_EMBREE_STATUS={status}");
}

fn build_shim() -> Result<u32, String> {
    let found = find_embree()?;
    let out = PathBuf::from(env::var("OUT_DIR").unwrap());

    // Bindings first: if libclang is missing we stop before linking anything.
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
    bindings.write_to_file(out.join("embree_shim.rs")).map_err(|e| format!("writing bindings: {e}"))?;

    let mut cc = cc::Build::new();
    cc.file("native/shim.c").flag_if_supported("-std=c11").opt_level(2).define("PT_EMBREE_MAJOR", found.major.to_string().as_str());
    if let Some(inc) = &found.include {
        cc.include(inc);
    }
    cc.try_compile("pt_embree_shim").map_err(|e| format!("compiling native/shim.c failed: {e}"))?;
    // After the static shim library, so the linker resolves its Embree calls.
    if let Some(lib) = &found.lib_dir {
        println!("cargo:rustc-link-search=native={}", lib.display());
    }
    println!("cargo:rustc-link-lib=dylib=embree{}", found.major);
    Ok(found.major)
}
