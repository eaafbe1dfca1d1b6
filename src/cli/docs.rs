//! The command line's own documentation, all from the clap definitions in
//! `args`: the long `--version`, shell completions, man pages, and the
//! Markdown reference that `docs/reference/cli.md` holds (a test checks
//! that the file is this output).

use super::args::Cli;
use crate::error::{Error, Result};
use clap::CommandFactory;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// `--version`: the version, the backends this build has and what they
/// run on (the Embree library's version, the native SIMD level).
pub fn long_version() -> String {
    use crate::accel::embree::{self, Major};
    let embree: Vec<String> = Major::ALL.iter().map(|&m| format!("embree{}: {}", m.number(), embree::version_string(m))).collect();
    let newest = embree::newest().map_or("none".to_string(), |m| format!("embree{}", m.number()));
    format!(
        "{}\nbackends: native ({}), brute\n{}\n(embree = {newest})\npeers built in: {}",
        env!("CARGO_PKG_VERSION"),
        crate::accel::wide::simd_level(crate::accel::NativeOptions::from_env().map(|o| o.isa).unwrap_or_default()),
        embree.join("\n"),
        if cfg!(feature = "peers") { "obvhs, tinybvh (bench only)" } else { "none (build with --features peers)" }
    )
}

/// The clap command to parse `args` with: when they ask for help or the
/// version, with what is found at run time (loading the Embree libraries to
/// ask their versions), else as defined, so that a render does not load
/// libraries it may not use.
pub fn command_for<T: AsRef<std::ffi::OsStr>>(args: &[T]) -> clap::Command {
    let asks = args.iter().skip(1).any(|a| matches!(a.as_ref().to_str(), Some("-h" | "--help" | "help" | "-V" | "--version")));
    if asks {
        command()
    } else {
        reference_command().version(env!("CARGO_PKG_VERSION"))
    }
}

/// The clap command, with the long version and which Embree `embree`
/// means in this build filled in at run time.
pub fn command() -> clap::Command {
    let newest = crate::accel::embree::newest()
        .map_or("no Embree loads here".to_string(), |m| format!("here: {}", crate::accel::embree::version_string(m)));
    reference_command().long_version(long_version()).mut_arg("backend", |a| {
        let help = a.get_help().map(|h| h.to_string()).unwrap_or_default();
        a.help(format!("{help} [embree = the newest Embree, {newest}]"))
    })
}

/// The clap command as defined, without anything found at run time (the
/// reference and the man pages are the same on every machine).
fn reference_command() -> clap::Command {
    Cli::command()
}

/// Write the completion script for `shell` to `out`.
pub fn completions(shell: clap_complete::Shell, out: &mut dyn std::io::Write) {
    clap_complete::generate(shell, &mut command(), "pathtracer", out);
}

/// Write `pathtracer.1` and `pathtracer-<sub>.1` for every visible
/// subcommand into `dir`; returns the files written.
pub fn man_pages(dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| Error::new(format!("{}: cannot create: {e}", dir.display())))?;
    let root = reference_command().after_help(super::args::EXAMPLES);
    let mut pages = vec![("pathtracer".to_string(), root.clone())];
    for sub in root.get_subcommands().filter(|s| !s.is_hide_set() && s.get_name() != "help") {
        let name = format!("pathtracer-{}", sub.get_name());
        pages.push((name.clone(), sub.clone().name(name)));
    }
    let mut written = Vec::new();
    for (name, cmd) in pages {
        let mut buf = Vec::new();
        clap_mangen::Man::new(cmd).render(&mut buf).map_err(|e| Error::new(format!("man page {name}: {e}")))?;
        let path = dir.join(format!("{name}.1"));
        crate::image_io::atomically(&path, |tmp| std::fs::write(tmp, &buf).map_err(|e| e.to_string()))?;
        written.push(path);
    }
    Ok(written)
}

/// One argument's line in the reference: its flags, values, meaning,
/// default and possible values.
fn arg_row(a: &clap::Arg) -> Option<String> {
    if a.is_hide_set() {
        return None;
    }
    let mut flag = match (a.get_short(), a.get_long()) {
        (Some(s), Some(l)) => format!("-{s}, --{l}"),
        (Some(s), None) => format!("-{s}"),
        (None, Some(l)) => format!("--{l}"),
        (None, None) => return None, // positionals are listed in the usage line
    };
    let takes_value = a.get_num_args().is_some_and(|n| n.takes_values()) && !matches!(a.get_action(), clap::ArgAction::SetTrue | clap::ArgAction::Help | clap::ArgAction::Version);
    if takes_value {
        let names: Vec<String> = a.get_value_names().map(|v| v.iter().map(|n| n.to_string()).collect()).unwrap_or_else(|| vec![a.get_id().to_string().to_uppercase()]);
        flag += &format!(" {}", names.join(" "));
    }
    let help = a.get_long_help().or(a.get_help()).map(|h| h.to_string()).unwrap_or_default().replace('\n', " ").replace('|', "\\|");
    let mut meaning = help;
    let values: Vec<String> = a
        .get_possible_values()
        .iter()
        .filter(|v| !v.is_hide_set())
        .map(|v| match v.get_help() {
            Some(h) => format!("`{}`: {}", v.get_name(), h.to_string().replace('|', "\\|")),
            None => format!("`{}`", v.get_name()),
        })
        .collect();
    if !values.is_empty() && takes_value {
        meaning += &format!(" — {}", values.join("; "));
    }
    let defaults: Vec<String> = a.get_default_values().iter().map(|d| d.to_string_lossy().into_owned()).collect();
    let default = if defaults.is_empty() || !takes_value { String::new() } else { format!("`{}`", defaults.join(" ")) };
    Some(format!("| `{}` | {meaning} | {default} |\n", flag.replace('|', "\\|")))
}

/// A command's section: usage, description, positional arguments, then
/// its options grouped under their help headings.
fn command_section(out: &mut String, cmd: &mut clap::Command, title: &str) {
    let usage = cmd.render_usage().to_string().replace("Usage: ", "");
    let _ = writeln!(out, "{title}\n\n```\n{usage}\n```\n");
    if let Some(about) = cmd.get_long_about().or(cmd.get_about()) {
        let _ = writeln!(out, "{about}\n");
    }
    let positionals: Vec<&clap::Arg> = cmd.get_positionals().filter(|a| !a.is_hide_set()).collect();
    if !positionals.is_empty() {
        let _ = writeln!(out, "| argument | meaning |\n|---|---|");
        for a in positionals {
            let name = a.get_value_names().and_then(|v| v.first().map(|n| n.to_string())).unwrap_or_else(|| a.get_id().to_string().to_uppercase());
            let help = a.get_long_help().or(a.get_help()).map(|h| h.to_string()).unwrap_or_default().replace('\n', " ");
            let _ = writeln!(out, "| `{name}` | {help} |");
        }
        out.push('\n');
    }
    // Headings in the order their first argument appears.
    let mut headings: Vec<Option<String>> = Vec::new();
    for a in cmd.get_arguments().filter(|a| !a.is_positional()) {
        let h = a.get_help_heading().map(str::to_string);
        if !headings.contains(&h) {
            headings.push(h);
        }
    }
    for h in headings {
        let rows: String = cmd.get_arguments().filter(|a| !a.is_positional() && a.get_help_heading().map(str::to_string) == h).filter_map(arg_row).collect();
        if rows.is_empty() {
            continue;
        }
        let _ = writeln!(out, "**{}**\n\n| option | meaning | default |\n|---|---|---|\n{rows}", h.as_deref().unwrap_or("Options"));
    }
}

/// The whole command line as Markdown (`docs/reference/cli.md`).
pub fn reference_markdown() -> String {
    let mut cmd = reference_command();
    cmd.build();
    let mut out = String::from(
        "# Command-line reference\n\n<!-- Generated by `pathtracer cli-reference` from the clap definitions in src/cli/args.rs; \
         tests/docs.rs fails when this file is stale. Regenerate: cargo run --release -- cli-reference > docs/reference/cli.md -->\n\n\
         The same text is in `pathtracer --help`, `pathtracer SUBCOMMAND --help` and the man pages (`pathtracer man --out DIR`).\n\n",
    );
    let names: Vec<String> = cmd.get_subcommands().filter(|s| !s.is_hide_set() && s.get_name() != "help").map(|s| s.get_name().to_string()).collect();
    let _ = writeln!(out, "Subcommands: {}.\n", names.iter().map(|n| format!("[`{n}`](#pathtracer-{n})")).collect::<Vec<_>>().join(", "));
    command_section(&mut out, &mut cmd, "## pathtracer (render)");
    let _ = writeln!(out, "{}\n", super::args::EXAMPLES.replace("Examples:\n", "**Examples**\n\n```\n") + "\n```");
    for name in names {
        let sub = cmd.find_subcommand_mut(&name).expect("listed subcommand");
        let mut sub = sub.clone().bin_name(format!("pathtracer {name}"));
        command_section(&mut out, &mut sub, &format!("## pathtracer {name}"));
    }
    out.trim_end().to_string() + "\n"
}
