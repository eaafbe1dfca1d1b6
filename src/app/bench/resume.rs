//! `pathtracer bench --resume DIR`: each finished part of a run (one scene's
//! tables, one scene's path-traced renders) kept in DIR as it finishes, and
//! taken from there by a later run of the same binary on the same machine
//! with the same options, so that a run cut short (a shared machine's time
//! limit, a pre-empted job) starts again at the part it stopped in instead
//! of from the beginning: the full benchmark takes hours on two cores.
//!
//! A kept part is used only where its key equals the run's: the XXH3-128 of
//! the executable's bytes (any rebuild measures again), the CPU and thread
//! count, every option that changes what is timed, the `PATHTRACER_*`
//! environment (Embree configuration, build options), and the XXH3-128 of
//! the part's scene files (an edited scene measures again). Otherwise, or where
//! the file is damaged, the part is measured again and the reason printed.
//! Measurements are stored exactly (`f64` in Rust's shortest round-trip
//! form), so tables printed from kept parts are the tables the first run
//! would have printed.

use crate::error::{Error, Result};
use serde_json::Value;
use std::path::{Path, PathBuf};
use xxhash_rust::xxh3::xxh3_128;

/// The folder of kept parts, and this run's key.
pub(super) struct Checkpoints {
    dir: PathBuf,
    key: String,
}

/// What a file holds: its format, then the key and part it was measured
/// under.
const FORMAT: &str = "pathtracer-bench-part 1";

impl Checkpoints {
    /// The store in `dir` (created if missing) for runs described by
    /// `options` (everything but the executable and environment, which are
    /// read here).
    pub(super) fn open(dir: &Path, options: &str) -> Result<Checkpoints> {
        std::fs::create_dir_all(dir).map_err(|e| Error::new(format!("{}: cannot create the --resume folder: {e}", dir.display())))?;
        let exe = std::env::current_exe().map_err(|e| Error::new(format!("bench --resume: cannot find this program's file: {e}")))?;
        let bytes = std::fs::read(&exe).map_err(|e| Error::new(format!("{}: cannot read this program's file: {e}", exe.display())))?;
        let mut env: Vec<String> = std::env::vars().filter(|(k, _)| k.starts_with("PATHTRACER_")).map(|(k, v)| format!("{k}={v}")).collect();
        env.sort();
        let key = format!("executable xxh3-128 {:032x}; {options}; environment [{}]", xxh3_128(&bytes), env.join(" "));
        Ok(Checkpoints { dir: dir.to_path_buf(), key })
    }

    /// The file of `part`: its name made safe for a file name, and a hash of
    /// the whole name so that two names never share a file.
    fn path(&self, part: &str) -> PathBuf {
        let safe: String = part.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '.' { c } else { '_' }).collect();
        // The name's end (ASCII now, so any byte is a boundary).
        let tail = &safe[safe.len().saturating_sub(60)..];
        self.dir.join(format!("{tail}-{:08x}.json", xxh3_128(part.as_bytes()) as u32))
    }

    /// The key of a part read from the scene `files`: the run's, and each
    /// file's bytes (read here, once per part: `load` and `save` take it).
    pub(super) fn part_key(&self, files: &[PathBuf]) -> String {
        let hashes: Vec<String> = files
            .iter()
            .map(|f| match std::fs::read(f) {
                Ok(bytes) => format!("{} xxh3-128 {:032x}", f.display(), xxh3_128(&bytes)),
                Err(e) => format!("{} unreadable ({e})", f.display()),
            })
            .collect();
        format!("{}; scene files [{}]", self.key, hashes.join(", "))
    }

    /// The kept measurements of `part`, where a file holds them under `key`
    /// (`part_key`); `None` (saying why on stderr when a file was there)
    /// where they must be measured.
    pub(super) fn load(&self, part: &str, key: &str) -> Option<Value> {
        let path = self.path(part);
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return None,
            Err(e) => {
                eprintln!("bench: {}: cannot read ({e}); measuring {part} again", path.display());
                return None;
            }
        };
        let doc: Value = match serde_json::from_str(&text) {
            Ok(v) => v,
            Err(e) => {
                eprintln!("bench: {}: damaged ({e}); measuring {part} again", path.display());
                return None;
            }
        };
        if doc["format"] != FORMAT || doc["part"] != part {
            eprintln!("bench: {}: not a kept part of {part}; measuring it again", path.display());
            return None;
        }
        if doc["key"] != key {
            eprintln!("bench: {}: measured by another build, machine or options, or from other scene files; measuring {part} again", path.display());
            return None;
        }
        Some(doc["measured"].clone())
    }

    /// Keep `measured` as `part`'s under `key` (`part_key`; written whole
    /// or not at all).
    pub(super) fn save(&self, part: &str, key: &str, measured: Value) -> Result<()> {
        let doc = serde_json::json!({ "format": FORMAT, "part": part, "key": key, "measured": measured });
        let text = serde_json::to_string_pretty(&doc).map_err(|e| Error::new(format!("bench: {part}: {e}")))?;
        crate::image_io::write_text(&self.path(part), &text)
    }

    pub(super) fn dir(&self) -> &Path {
        &self.dir
    }
}

/// `x` as text that parses back to the same bits (Rust prints the shortest
/// such decimal).
pub(super) fn exact(x: f64) -> Value {
    Value::String(format!("{x:?}"))
}

/// The number `exact` wrote.
pub(super) fn parse_exact(v: &Value) -> Option<f64> {
    v.as_str()?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("pathtracer-resume-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn numbers_come_back_bit_for_bit() {
        for x in [0.1, 1.0 / 3.0, 0.1 + 0.2, f64::MIN_POSITIVE, 123456.789e-300, 55.7586, f64::INFINITY] {
            assert_eq!(parse_exact(&exact(x)).unwrap().to_bits(), x.to_bits(), "{x}");
        }
    }

    #[test]
    fn a_part_is_kept_only_under_its_own_key() {
        let d = scratch("key");
        let a = Checkpoints::open(&d, "rays 16").unwrap();
        let key = a.part_key(&[]);
        assert!(a.load("sphere:1M", &key).is_none());
        a.save("sphere:1M", &key, serde_json::json!({ "x": exact(2.5) })).unwrap();
        assert_eq!(parse_exact(&a.load("sphere:1M", &key).unwrap()["x"]), Some(2.5));
        // Another part, other options: nothing to take.
        assert!(a.load("sphere:5M", &key).is_none());
        let b = Checkpoints::open(&d, "rays 32").unwrap();
        assert!(b.load("sphere:1M", &b.part_key(&[])).is_none());
        // A scene file edited after its part was kept: measured again.
        let scene = d.join("scene.obj");
        std::fs::write(&scene, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        a.save("scene.obj", &a.part_key(&[scene.clone()]), serde_json::json!({ "x": exact(1.5) })).unwrap();
        assert!(a.load("scene.obj", &a.part_key(&[scene.clone()])).is_some());
        std::fs::write(&scene, "v 0 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        assert!(a.load("scene.obj", &a.part_key(&[scene.clone()])).is_none());
        // A damaged file is measured again, not trusted.
        std::fs::write(a.path("sphere:1M"), "{\"format\": \"pathtracer-bench-part 1\", \"par").unwrap();
        assert!(a.load("sphere:1M", &key).is_none());
        // Names that differ only in characters a file name cannot hold.
        assert_ne!(a.path("a/b"), a.path("a:b"));
        let _ = std::fs::remove_dir_all(&d);
    }
}
