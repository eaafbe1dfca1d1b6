//! A render's output files: the names checked before any work, then the
//! tone-mapped image in the format its name says, the sample-rate image
//! where adaptive sampling ran, and the OpenEXRs asked for. The render and
//! `merge` both write through here, so a merged split render writes exactly
//! what the one-machine render writes.

use crate::error::Result;
use crate::image_io;
use crate::render;
use std::path::{Path, PathBuf};

/// The output files' names, checked before any work: the image's extension
/// names its format (.png, .jpg, .jpeg), the EXRs end in .exr.
pub fn check_output_names(image: Option<&Path>, exr: Option<&Path>, variance_exr: Option<&Path>) -> Result<()> {
    if let Some(p) = image {
        image_io::DisplayFormat::of(p)?;
    }
    for (p, flag) in [(exr, "--exr"), (variance_exr, "--variance-exr")] {
        if let Some(p) = p.filter(|p| !p.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr"))) {
            crate::bail!("{flag} {}: an OpenEXR file's name ends in .exr", p.display());
        }
    }
    Ok(())
}

/// A render's image files: the tone-mapped image in the format its name
/// says, with `rate` (adaptive sampling ran) its `_rate.png` beside it, and
/// the EXRs asked for; returns the paths written. `merge` writes through
/// this too, so a merged split render writes what the render would have.
pub fn write_images(
    out: &render::RenderOutput,
    image: &Path,
    rate: bool,
    exr: Option<&Path>,
    variance_exr: Option<&Path>,
    spp: u32,
) -> Result<Vec<String>> {
    image_io::write_display(image, &out.image)?;
    let mut written = vec![image.display().to_string()];
    if rate {
        let rate = rate_path(image);
        image_io::write_rate_png(&rate, out.image.width, out.image.height, &out.samples, spp)?;
        written.push(rate.display().to_string());
    }
    for (path, img) in [(exr, &out.image), (variance_exr, &out.variance)] {
        if let Some(p) = path {
            image_io::write_exr(p, img)?;
            written.push(p.display().to_string());
        }
    }
    Ok(written)
}

/// CS184's `<FILE minus its last 4 chars>_rate.png`, done on the extension.
pub fn rate_path(output: &Path) -> PathBuf {
    let stem = output.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    output.with_file_name(format!("{stem}_rate.png"))
}
