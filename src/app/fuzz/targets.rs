//! What a fuzz case runs: every reader, through the command line the user
//! runs, on one mutated input file.
//!
//! Scenes (COLLADA, OBJ, ASCII and binary PLY) are rendered at 8×6 pixels
//! (path tracing, `-m 2`), so a scene that loads also meets the checks,
//! the BVH build, the lights and the integrator; an OpenEXR map is the
//! built-in scene's `-e`, a camera file its `-c`; a partial is merged with
//! the intact other half of its two-part set. A case passes when it renders
//! (writing exactly the image and its rate image) or is refused with an
//! error that names the input file, leaving nothing behind. It fails when
//! it panics, hangs, leaves files behind, or is refused without naming the
//! file (a merge's set errors name parts or sample ranges instead).

use super::Outcome;
use std::path::{Path, PathBuf};

/// An input format the fuzzer covers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Kind {
    Dae,
    Obj,
    PlyAscii,
    PlyBinary,
    Exr,
    Camera,
    Partial,
}

impl Kind {
    pub const ALL: [Kind; 7] = [Kind::Dae, Kind::Obj, Kind::PlyAscii, Kind::PlyBinary, Kind::Exr, Kind::Camera, Kind::Partial];

    /// The name on the command line and of the corpus folder.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Dae => "dae",
            Kind::Obj => "obj",
            Kind::PlyAscii => "ply-ascii",
            Kind::PlyBinary => "ply-binary",
            Kind::Exr => "exr",
            Kind::Camera => "camera",
            Kind::Partial => "partial",
        }
    }

    pub fn from_name(name: &str) -> Option<Kind> {
        Kind::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Whether the format is text (mutated mostly as text).
    pub fn is_text(self) -> bool {
        matches!(self, Kind::Dae | Kind::Obj | Kind::PlyAscii | Kind::Camera)
    }

    /// The input file's extension (the scene loader picks its reader by it).
    pub fn extension(self) -> &'static str {
        match self {
            Kind::Dae => "dae",
            Kind::Obj => "obj",
            Kind::PlyAscii | Kind::PlyBinary => "ply",
            Kind::Exr => "exr",
            Kind::Camera => "cam",
            Kind::Partial => "ptp",
        }
    }
}

/// One kind's seeds, read from `<corpus>/<kind>/`. For partials the seeds
/// are the files `*-1.ptp`, each merged with its unmutated `*-0.ptp`.
pub struct Seeds {
    pub kind: Kind,
    pub files: Vec<(String, Vec<u8>)>,
    companions: Vec<PathBuf>,
}

impl Seeds {
    pub fn load(corpus: &Path, kind: Kind) -> crate::Result<Seeds> {
        let dir = corpus.join(kind.name());
        let entries = std::fs::read_dir(&dir).map_err(|e| crate::Error::new(format!("{}: cannot read the fuzz corpus: {e}", dir.display())))?;
        let mut names: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.is_file()).collect();
        names.sort();
        let mut files = Vec::new();
        let mut companions = Vec::new();
        for p in names {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            if kind == Kind::Partial {
                let Some(stem) = name.strip_suffix("-1.ptp") else { continue };
                let companion = dir.join(format!("{stem}-0.ptp"));
                if !companion.is_file() {
                    crate::bail!("{}: no {} beside it", p.display(), companion.display());
                }
                companions.push(companion);
            }
            let bytes = std::fs::read(&p).map_err(|e| crate::Error::new(format!("{}: {e}", p.display())))?;
            files.push((name, bytes));
        }
        if files.is_empty() {
            crate::bail!("{}: no seed inputs", dir.display());
        }
        Ok(Seeds { kind, files, companions })
    }
}

/// A worker's folder: the input file and an `out/` folder, emptied per case.
pub struct Workspace {
    pub dir: PathBuf,
}

impl Workspace {
    pub fn new(dir: PathBuf) -> std::io::Result<Workspace> {
        if dir.exists() {
            std::fs::remove_dir_all(&dir)?;
        }
        std::fs::create_dir_all(dir.join("out"))?;
        Ok(Workspace { dir })
    }

    fn entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir).map(|r| r.filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned())).collect()).unwrap_or_default();
        v.sort();
        v
    }

    /// Run `input` as seed `seed` of `seeds` (its index, for a partial's
    /// companion) and classify what happened.
    pub fn run(&self, seeds: &Seeds, seed: usize, input: &[u8]) -> Outcome {
        let kind = seeds.kind;
        let out = self.dir.join("out");
        for name in Self::entries(&out) {
            let _ = std::fs::remove_file(out.join(name));
        }
        for name in Self::entries(&self.dir).into_iter().filter(|n| n != "out") {
            let _ = std::fs::remove_file(self.dir.join(name));
        }
        let case_name = format!("case.{}", kind.extension());
        let file = self.dir.join(&case_name);
        if let Err(e) = std::fs::write(&file, input) {
            return Outcome::LeftOutput(format!("cannot write the case: {e}"));
        }
        let image = out.join("img.png");
        let f = file.to_string_lossy().into_owned();
        let img = image.to_string_lossy().into_owned();
        let small = ["-r", "8", "6", "-s", "1", "-t", "1"];
        let mut args: Vec<String> = vec!["pathtracer".into()];
        match kind {
            Kind::Dae | Kind::Obj | Kind::PlyAscii | Kind::PlyBinary => {
                args.push(f);
                args.extend(small.iter().map(|s| s.to_string()));
                args.extend(["-m".into(), "2".into()]);
            }
            Kind::Exr | Kind::Camera => {
                args.push(if kind == Kind::Exr { "-e" } else { "-c" }.into());
                args.push(f);
                args.extend(small.iter().map(|s| s.to_string()));
            }
            Kind::Partial => {
                args.push("merge".into());
                args.push(seeds.companions[seed].to_string_lossy().into_owned());
                args.push(f);
            }
        }
        args.extend(["-f".into(), img]);
        let live = super::alloc::mark();
        let result = std::panic::catch_unwind(|| crate::app::cli::parse(&args).and_then(|c| c.map_or(Ok(()), crate::app::run)));
        let held = super::alloc::peak() - live;
        let left: Vec<String> = Self::entries(&self.dir).into_iter().filter(|n| *n != case_name && n != "out").collect();
        let written = Self::entries(&out);
        match result {
            Err(payload) => Outcome::Panicked(super::panic_message(payload.as_ref())),
            _ if held > super::MEMORY_BOUND => Outcome::Memory(format!("the case held {} MiB at once", held >> 20)),
            _ if !left.is_empty() => Outcome::LeftOutput(format!("files beside the input: {}", left.join(", "))),
            // The rate image only where adaptive sampling ran (an adaptive partial's merge).
            Ok(Ok(())) if written == ["img.png"] || written == ["img.png", "img_rate.png"] => Outcome::Rendered,
            Ok(Ok(())) => Outcome::LeftOutput(format!("a successful run wrote {written:?}")),
            Ok(Err(_)) if !written.is_empty() => Outcome::LeftOutput(format!("a refused run left {written:?}")),
            Ok(Err(e)) => {
                let set_error = kind == Kind::Partial && (e.0.starts_with("incomplete set") || e.0.starts_with("overlapping parts"));
                if e.0.contains(&case_name) || set_error {
                    Outcome::Refused(e.0)
                } else {
                    Outcome::Unnamed(e.0)
                }
            }
        }
    }
}
