//! The application built on the library: the command line (`cli`), the
//! benchmark (`bench`), split renders' merge and check (`merge`), the
//! reference renderers' export (`export`) and the fuzzer (`fuzz`). Options
//! are read here, once — from the command line and the environment — and
//! passed into the library as values; nothing below `app` reads either.

pub mod bench;
pub mod cli;
pub mod export;
pub mod fuzz;
pub mod images;
pub mod merge;
pub mod validate;

/// The backends' build options the environment asks for
/// (`PATHTRACER_NATIVE_*`, `PATHTRACER_EMBREE_CONFIG`; a bad value is
/// refused naming the variable), with `threads` for any pool a backend
/// owns: the one place the application reads them.
pub fn build_options(threads: usize) -> crate::Result<crate::accel::BuildOptions> {
    crate::accel::BuildOptions::from_lookup(threads, |k| std::env::var(k).ok())
}
