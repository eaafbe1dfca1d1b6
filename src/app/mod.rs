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

/// Entry point for the binary: one line on error, non-zero exit, no panic.
pub fn main() -> std::process::ExitCode {
    // Die quietly on a closed pipe (`pathtracer ... | head`), as Unix tools do,
    // instead of panicking in println!.
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of one signal before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    match cli::parse(std::env::args_os()) {
        Ok(Some(cli)) => match run(cli) {
            Ok(()) => std::process::ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("pathtracer: error: {e}");
                std::process::ExitCode::from(if e.is_usage() { 2 } else { 1 })
            }
        },
        Ok(None) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("pathtracer: error: {e}");
            std::process::ExitCode::from(2)
        }
    }
}

/// Run a parsed command line: `validate` here (it is built on the command
/// line's render flags), every other command by `cli::run`.
pub fn run(cli: cli::Cli) -> crate::Result<()> {
    if let Some(cli::Command::Validate(v)) = &cli.command {
        return validate::run(v);
    }
    cli::run(cli)
}
