//! The SIMD kernels' intrinsics are inlined in the binary the tests run.
//!
//! An AVX intrinsic left as an out-of-line function means some kernel
//! called it from code compiled without AVX: a closure handed to a generic
//! helper (`std::array::from_fn`, `[_; N]::map`) that the compiler chose not
//! to inline. Each load or multiply is then a call, and the kernel is slow
//! without being wrong, so no other test notices. It happened: a build with
//! `--features peers` (a different split into code-generation units) left
//! the packet set-up's loads out of line, and native camera rays read 56
//! Mrays/s instead of 68 on CBbunny in the benchmark's table (docs/benchmarks/bench.md).
//!
//! The check reads the binary's symbol table with `nm` (binutils, which the
//! Rust toolchain's linker needs anyway); without `nm` it fails, so it can
//! never pass unseen.

#[cfg(target_arch = "x86_64")]
#[test]
fn no_out_of_line_simd_intrinsics() {
    let exe = env!("CARGO_BIN_EXE_pathtracer");
    let out = std::process::Command::new("nm")
        .args(["--demangle", "--defined-only", exe])
        .output()
        .unwrap_or_else(|e| panic!("simd_inlined: cannot run `nm` on {exe} ({e}); install binutils"));
    assert!(out.status.success(), "nm {exe} failed: {}", String::from_utf8_lossy(&out.stderr));
    let syms = String::from_utf8_lossy(&out.stdout);
    assert!(syms.lines().count() > 1000, "nm {exe}: too few symbols ({}): a stripped binary cannot be checked", syms.lines().count());
    // CPU-feature detection's own helpers (`_xgetbv`, `__cpuid`) are called
    // once at start-up and legitimately out of line.
    let bad: Vec<&str> = syms
        .lines()
        .filter_map(|l| l.split_once(" t ").or_else(|| l.split_once(" T ")).map(|(_, name)| name))
        .filter(|name| name.starts_with("core::core_arch::x86") && !name.contains("::xsave::") && !name.contains("::cpuid::"))
        .collect();
    assert!(bad.is_empty(), "SIMD intrinsics compiled out of line in {exe} (some kernel calls them from code built without the feature): {bad:?}");
}
