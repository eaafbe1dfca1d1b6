//! The verdict as files: `summary.json` (every check), `junit.xml` (what CI
//! systems display: one test case per check) and `report.html`.

use super::{Check, Status};
use crate::error::Result;
use std::fmt::Write as _;
use std::path::Path;

/// Text escaped for XML and HTML.
fn esc(s: &str) -> String {
    s.chars()
        .filter(|c| !c.is_control() || *c == '\n' || *c == '\t')
        .map(|c| match c {
            '&' => "&amp;".to_string(),
            '<' => "&lt;".to_string(),
            '>' => "&gt;".to_string(),
            '"' => "&quot;".to_string(),
            '\'' => "&apos;".to_string(),
            c => c.to_string(),
        })
        .collect()
}

pub fn junit(scene: &str, checks: &[Check], seconds: f64) -> String {
    let count = |s: Status| checks.iter().filter(|c| c.status == s).count();
    let mut x = String::from("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    let _ = writeln!(
        x,
        "<testsuites name=\"pathtracer validate\" tests=\"{}\" failures=\"{}\" errors=\"{}\" skipped=\"{}\" time=\"{seconds:.3}\">",
        checks.len(),
        count(Status::Fail),
        count(Status::Unresolved),
        count(Status::Skipped)
    );
    let _ = writeln!(
        x,
        "  <testsuite name=\"{}\" tests=\"{}\" failures=\"{}\" errors=\"{}\" skipped=\"{}\" time=\"{seconds:.3}\">",
        esc(scene),
        checks.len(),
        count(Status::Fail),
        count(Status::Unresolved),
        count(Status::Skipped)
    );
    for c in checks {
        let _ = write!(x, "    <testcase classname=\"{}\" name=\"{}\" time=\"{:.3}\"", esc(scene), esc(&c.name), c.seconds);
        let body = match c.status {
            Status::Pass => None,
            Status::Fail => Some(format!("<failure message=\"{}\">{}</failure>", esc(&c.summary), esc(&c.details.join("\n")))),
            Status::Unresolved => Some(format!("<error message=\"{}\">{}</error>", esc(&c.summary), esc(&c.details.join("\n")))),
            Status::Skipped => Some(format!("<skipped message=\"{}\"/>", esc(&c.summary))),
        };
        match body {
            None => {
                let _ = writeln!(x, "><system-out>{}</system-out></testcase>", esc(&c.summary));
            }
            Some(b) => {
                let _ = writeln!(x, ">{b}</testcase>");
            }
        }
    }
    x.push_str("  </testsuite>\n</testsuites>\n");
    x
}

pub fn json(scene: &str, checks: &[Check], seconds: f64) -> serde_json::Value {
    serde_json::json!({
        "scene": scene,
        "seconds": seconds,
        "passed": checks.iter().all(|c| matches!(c.status, Status::Pass | Status::Skipped)),
        "checks": checks.iter().map(|c| serde_json::json!({
            "name": c.name, "status": c.status.word(), "summary": c.summary, "details": c.details, "seconds": c.seconds,
        })).collect::<Vec<_>>(),
    })
}

pub fn html(scene: &str, checks: &[Check], seconds: f64) -> String {
    let mut h = format!("<!doctype html><meta charset=\"utf-8\"><title>pathtracer validate: {0}</title><h1>pathtracer validate: {0}</h1><p>{1} checks in {seconds:.1} s.</p><table border=\"1\" cellpadding=\"4\"><tr><th>check</th><th>verdict</th><th>what it found</th></tr>", esc(scene), checks.len());
    for c in checks {
        let colour = match c.status {
            Status::Pass => "#cfc",
            Status::Fail => "#fcc",
            Status::Unresolved => "#fec",
            Status::Skipped => "#eee",
        };
        let _ = write!(
            h,
            "<tr><td>{}</td><td style=\"background:{colour}\">{}</td><td>{}<details><summary>evidence</summary><pre>{}</pre></details></td></tr>",
            esc(&c.name),
            c.status.word(),
            esc(&c.summary),
            esc(&c.details.join("\n"))
        );
    }
    h.push_str("</table>\n");
    h
}

/// Write the three files into `dir`.
pub fn write(dir: &Path, scene: &str, checks: &[Check], seconds: f64) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| crate::Error::new(format!("{}: cannot create: {e}", dir.display())))?;
    crate::image_io::write_text(&dir.join("summary.json"), &serde_json::to_string_pretty(&json(scene, checks, seconds)).unwrap_or_default())?;
    crate::image_io::write_text(&dir.join("junit.xml"), &junit(scene, checks, seconds))?;
    crate::image_io::write_text(&dir.join("report.html"), &html(scene, checks, seconds))
}
