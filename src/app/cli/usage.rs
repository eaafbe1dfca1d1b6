//! Command-line mistakes answered in one line each: clap's parse errors
//! rewritten to say what was wrong and what is accepted (without clap's
//! hints), and a mistyped command suggested before clap would read it as a
//! scene.

use crate::error::Result;
use std::path::Path;

/// A first argument that is neither a command nor a scene: a word with no
/// extension that names no file, such as a mistyped `merg`. Left to clap,
/// it would be read as the scene and the next argument as a command.
pub(super) fn not_a_command(command: &clap::Command, first: &std::ffi::OsStr) -> Result<()> {
    let Some(word) = first.to_str() else { return Ok(()) };
    let path = Path::new(word);
    let looks_like_scene = word.starts_with('-') || path.exists() || path.extension().is_some() || word.contains(['/', ':']);
    let names: Vec<&str> = command.get_subcommands().filter(|s| !s.is_hide_set()).map(|s| s.get_name()).filter(|n| *n != "help").collect();
    if looks_like_scene || command.find_subcommand(word).is_some() || word == "help" {
        return Ok(());
    }
    let near = names.iter().copied().filter(|n| n.starts_with(word) || edit_distance(n, word) <= 2).min_by_key(|n| edit_distance(n, word));
    match near {
        Some(n) => crate::bail!("'{word}' is not a command; did you mean '{n}'? (commands: {})", names.join(", ")),
        None => crate::bail!("'{word}' is neither a command ({}) nor a scene file ({})", names.join(", "), crate::scene::FORMATS),
    }
}

/// Levenshtein distance, for suggesting a command.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

/// clap's parse error as one line saying what was wrong and what is
/// accepted, without clap's own hints (its "try --help" and its tip to
/// write `-- -1`, which this command line would read as a scene).
pub(super) fn usage_error(e: &clap::Error) -> String {
    use clap::error::{ContextKind, ContextValue, ErrorKind};
    let get = |k: ContextKind| match e.get(k) {
        Some(ContextValue::String(s)) => Some(s.clone()),
        Some(ContextValue::Strings(v)) => Some(v.join(", ")),
        _ => None,
    };
    // "-s <N>" -> "-s": the flag as the user typed it.
    let arg = get(ContextKind::InvalidArg).map(|a| a.split([' ', '=']).next().unwrap_or_default().to_string()).unwrap_or_default();
    let value = get(ContextKind::InvalidValue).unwrap_or_default();
    let suggestion = get(ContextKind::SuggestedArg)
        .or_else(|| get(ContextKind::SuggestedSubcommand))
        .or_else(|| get(ContextKind::SuggestedValue))
        .map(|s| format!("; did you mean '{s}'?"))
        .unwrap_or_default();
    match e.kind() {
        ErrorKind::InvalidValue if value.is_empty() => format!("{arg}: a value is required"),
        ErrorKind::InvalidValue => match get(ContextKind::ValidValue) {
            Some(valid) => format!("{arg} {value}: not one of {valid}{suggestion}"),
            None => format!("{arg} {value}: not a valid value"),
        },
        ErrorKind::ValueValidation => {
            use std::error::Error as _;
            let source = e.source();
            let why = if let Some(p) = source.and_then(|s| s.downcast_ref::<std::num::ParseIntError>()) {
                use std::num::IntErrorKind::*;
                match p.kind() {
                    InvalidDigit if value.starts_with('-') => "expected a number of 0 or more".to_string(),
                    InvalidDigit => "expected a whole number".to_string(),
                    PosOverflow | NegOverflow => "the number is too large".to_string(),
                    Empty => "a value is required".to_string(),
                    _ => p.to_string(),
                }
            } else if source.is_some_and(|s| s.is::<std::num::ParseFloatError>()) {
                "expected a number".to_string()
            } else {
                source.map(|s| s.to_string()).unwrap_or_else(|| "not a valid value".into())
            };
            format!("{arg} {value}: {why}")
        }
        ErrorKind::UnknownArgument => format!("unknown option '{arg}'{suggestion}"),
        ErrorKind::InvalidSubcommand => format!("'{arg}' is not a command{suggestion}"),
        ErrorKind::WrongNumberOfValues | ErrorKind::TooFewValues | ErrorKind::TooManyValues => match e.get(ContextKind::ExpectedNumValues) {
            Some(ContextValue::Number(n)) => format!("{arg}: expected {n} values"),
            _ => format!("{arg}: wrong number of values"),
        },
        _ => {
            // clap's message up to its usage block (with the argument names
            // it lists on the lines after the first), without its hints.
            let text = e.render().to_string();
            let message = text.split("\n\nUsage").next().unwrap_or("invalid arguments");
            let message = message.split("\n\n  tip:").next().unwrap_or_default();
            let joined = message.split_whitespace().collect::<Vec<_>>().join(" ");
            joined.trim_start_matches("error: ").to_string()
        }
    }
}
