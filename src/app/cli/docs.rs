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
        super::version_line(),
        crate::accel::wide::simd_level(crate::app::build_options(0).map(|o| o.native.isa).unwrap_or_default()),
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
        reference_command().version(super::version_line())
    }
}

/// The clap command, with the long version and which Embree `embree`
/// means in this build filled in at run time.
pub fn command() -> clap::Command {
    let newest = crate::accel::embree::newest()
        .map_or("no Embree loads here".to_string(), |m| format!("here: {}", crate::accel::embree::version_string(m)));
    reference_command().version(super::version_line()).long_version(long_version()).mut_arg("backend", |a| {
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

/// What each exit status means (the man pages' EXIT STATUS, the
/// reference's "Exit status").
pub const EXIT_STATUS: [(u8, &str); 3] = [
    (0, "Success: the images, partials or tables were written (verify: every partial is intact)."),
    (1, "The work failed: a file is missing, damaged or unsupported, a render or write failed, (verify) a partial is damaged, or (validate) a check failed. One line on standard error names the file and the problem; nothing partial is left behind."),
    (2, "The command line is wrong: an unknown command or option, a missing or malformed value, a value out of range, or flags that do not go together; or (validate) a check could not be decided within the budget, or could not run. One line on standard error says what is accepted, or which checks to read."),
];

/// The environment variables the program reads when it runs (the build's
/// and the tests' are in docs/reference/environment.md).
pub const ENVIRONMENT: [(&str, &str); 7] = [
    ("PATHTRACER_NATIVE_ISA", "auto, sse, avx2 or avx512: the SIMD level of the native backend's kernels (default: auto, AVX2 where the CPU has it, single rays' walks compiled with AVX-512VL where it has that too)."),
    ("PATHTRACER_NATIVE_SPLITS", "auto (the default) or a number from 0 to 4: spatial splits in the native BVH build; auto tries them where the render's rays could repay the second build and keeps them where they cut the traversal work counted on a sample by 10 %; a number fixes the extra references per primitive allowed (0: none)."),
    ("PATHTRACER_NATIVE_BATCH", "single, interleaved, streams or auto: how the native backend traces incoherent closest-hit batches (default auto: decided per batch)."),
    ("PATHTRACER_NATIVE_SHADOW", "packets, streams or auto: how the native backend traces coherent shadow batches (default auto: streams on large trees whose rays miss the caches, packets elsewhere)."),
    ("PATHTRACER_EMBREE_CONFIG", "an Embree device configuration string, appended to every Embree device's (verbose=2 prints Embree's build statistics)."),
    ("PATHTRACER_SCENES", "a folder where bench looks for scenes given by name, before scenes/cs184 under the current folder."),
    ("CI", "set to anything: no progress bar (as when standard error is not a terminal)."),
];

/// Text as roff: backslashes and hyphens escaped, no line starting with a
/// control character.
fn roff(text: &str) -> String {
    let t = text.replace('\\', "\\e").replace('-', "\\-");
    t.lines().map(|l| if l.starts_with(['.', '\'']) { format!("\\&{l}") } else { l.to_string() }).collect::<Vec<_>>().join("\n")
}

/// One man page: clap's name, description, options and commands, with our
/// own title, synopsis (clap's leaves out the value names), examples, exit
/// status, environment and see-also sections.
fn man_page(cmd: clap::Command, page: &str, usage: &str, examples: &[(String, String)], see_also: &[String]) -> std::io::Result<Vec<u8>> {
    let version = env!("CARGO_PKG_VERSION");
    let has_commands = cmd.get_subcommands().any(|s| !s.is_hide_set());
    let man = clap_mangen::Man::new(cmd)
        .title(page.to_uppercase())
        .section("1")
        .source(format!("pathtracer {version}"))
        .manual("pathtracer manual");
    let mut w = Vec::new();
    man.render_title(&mut w)?;
    man.render_name_section(&mut w)?;
    let mut synopsis = String::from(".SH SYNOPSIS\n");
    for (i, line) in usage.lines().enumerate() {
        if i > 0 {
            synopsis += ".br\n";
        }
        let words: Vec<String> = line.split_whitespace().enumerate().map(|(j, word)| if j == 0 || !word.starts_with(['[', '<']) { format!("\\fB{}\\fR", roff(word)) } else { format!("\\fI{}\\fR", roff(word)) }).collect();
        synopsis += &words.join(" ");
        synopsis.push('\n');
    }
    w.extend_from_slice(synopsis.as_bytes());
    man.render_description_section(&mut w)?;
    man.render_options_section(&mut w)?;
    if has_commands {
        man.render_subcommands_section(&mut w)?;
    }
    let mut tail = String::new();
    if !examples.is_empty() {
        tail += ".SH EXAMPLES\n";
        for (command, what) in examples {
            let lines: Vec<String> = command.split('\n').map(|c| format!("\\fB{}\\fR", roff(c))).collect();
            tail += &format!(".TP\n{}\n{}\n", lines.join("\n.br\n"), roff(what));
        }
    }
    tail += ".SH EXIT STATUS\n";
    for (code, what) in EXIT_STATUS {
        tail += &format!(".TP\n\\fB{code}\\fR\n{}\n", roff(what));
    }
    tail += ".SH ENVIRONMENT\n";
    for (name, what) in ENVIRONMENT {
        tail += &format!(".TP\n\\fB{}\\fR\n{}\n", roff(name), roff(what));
    }
    tail += ".SH SEE ALSO\n";
    tail += &see_also.iter().map(|s| format!("\\fB{}\\fR(1)", roff(s))).collect::<Vec<_>>().join(", ");
    tail += "\n";
    tail += &format!(".SH VERSION\n{}\n", roff(&super::version_line()));
    w.extend_from_slice(tail.as_bytes());
    Ok(w)
}

/// The examples of `EXAMPLES` as (command lines, what they do) pairs: a
/// description belongs to the command lines above it.
pub fn examples() -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut commands: Vec<String> = Vec::new();
    for line in super::args::EXAMPLES.lines().skip(1) {
        if let Some(what) = line.strip_prefix("      ") {
            out.push((commands.join("\n"), what.trim().to_string()));
            commands.clear();
        } else {
            commands.push(line.trim().to_string());
        }
    }
    out
}

/// Write `pathtracer.1` and `pathtracer-<sub>.1` for every visible
/// subcommand into `dir`; returns the files written.
pub fn man_pages(dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| Error::new(format!("{}: cannot create: {e}", dir.display())))?;
    let mut root = reference_command().subcommand_help_heading("COMMANDS");
    root.build();
    let subs: Vec<clap::Command> = root.get_subcommands().filter(|s| !s.is_hide_set() && s.get_name() != "help").cloned().collect();
    let sub_pages: Vec<String> = subs.iter().map(|s| format!("pathtracer-{}", s.get_name())).collect();
    let root_usage = "pathtracer [OPTIONS] [SCENE]\npathtracer COMMAND [ARGS]".to_string();
    let mut pages = vec![("pathtracer".to_string(), root.clone().disable_help_subcommand(true), root_usage, examples(), sub_pages.clone())];
    for sub in subs {
        let short = sub.get_name().to_string();
        let name = format!("pathtracer-{short}");
        let mut sub = sub.bin_name(format!("pathtracer {short}"));
        let usage = sub.render_usage().to_string().replace("Usage: ", "");
        let mine: Vec<(String, String)> = examples().into_iter().filter(|(c, _)| c.contains(&format!("pathtracer {short} "))).collect();
        let see: Vec<String> = std::iter::once("pathtracer".to_string()).chain(sub_pages.iter().filter(|p| **p != name).cloned()).collect();
        pages.push((name.clone(), sub.name(name), usage, mine, see));
    }
    let mut written = Vec::new();
    for (name, cmd, usage, examples, see) in pages {
        let buf = man_page(cmd, &name, &usage, &examples, &see).map_err(|e| Error::new(format!("man page {name}: {e}")))?;
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
        "# Command-line reference\n\n<!-- Generated by `pathtracer cli-reference` from the clap definitions in src/app/cli/args.rs; \
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
    let _ = writeln!(out, "## Exit status\n\n| status | meaning |\n|---|---|");
    for (code, what) in EXIT_STATUS {
        let _ = writeln!(out, "| {code} | {what} |");
    }
    let _ = writeln!(out, "\n## Environment\n\nRead when the program runs (the build's and the tests' variables: [environment variables](environment.md)).\n\n| variable | effect |\n|---|---|");
    for (name, what) in ENVIRONMENT {
        let _ = writeln!(out, "| `{name}` | {what} |");
    }
    out.trim_end().to_string() + "\n"
}
