//! Writing images: CS184's PNG tone step, its sample-rate image, and linear
//! OpenEXR. Every file is written to a temporary name and renamed into place,
//! so a failed or interrupted write never leaves a partial output file.

use crate::error::{Error, Result};
use glam::Vec3;
use std::path::{Path, PathBuf};

/// A linear RGB image, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Rgb {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<Vec3>,
}

impl Rgb {
    pub fn new(width: u32, height: u32) -> Self {
        Rgb { width, height, pixels: vec![Vec3::ZERO; (width * height) as usize] }
    }

    pub fn get(&self, x: u32, y: u32) -> Vec3 {
        self.pixels[(y * self.width + x) as usize]
    }
}

/// CS184's `toColor`: exposure sqrt(2), gamma 1/2.2, clamp, truncate to 8 bits.
pub fn tone_byte(v: f32) -> u8 {
    let c = (v * std::f32::consts::SQRT_2).powf(1.0 / 2.2);
    if c > 0.0 {
        (c.min(1.0) * 255.0) as u8
    } else {
        0
    }
}

/// CS184's sample-rate colour map: blue (0) -> green (0.5) -> red (1).
pub fn rate_color(rate: f32) -> [u8; 3] {
    let (blue, green, red) = (Vec3::Z, Vec3::Y, Vec3::X);
    let c = if rate <= 0.5 {
        let t = (0.5 - rate) / 0.5;
        blue * t + green * (1.0 - t)
    } else {
        let t = (1.0 - rate) / 0.5;
        green * t + red * (1.0 - t)
    };
    [c.x, c.y, c.z].map(|v| (v.clamp(0.0, 1.0) * 255.0) as u8)
}

fn temp_path(path: &Path) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    path.with_file_name(format!(".{name}.partial-{}", std::process::id()))
}

/// Write with `write` to a temporary file beside `path`, then rename it.
pub fn atomically(path: &Path, write: impl FnOnce(&Path) -> std::result::Result<(), String>) -> Result<()> {
    let tmp = temp_path(path);
    match write(&tmp) {
        Ok(()) => std::fs::rename(&tmp, path).map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            Error::new(format!("{}: cannot write: {e}", path.display()))
        }),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(Error::new(format!("{}: cannot write: {e}", path.display())))
        }
    }
}

/// A text file, written atomically.
pub fn write_text(path: &Path, text: &str) -> Result<()> {
    atomically(path, |tmp| std::fs::write(tmp, text).map_err(|e| e.to_string()))
}

fn write_rgba_png(path: &Path, w: u32, h: u32, data: Vec<u8>) -> Result<()> {
    atomically(path, |tmp| {
        image::save_buffer_with_format(tmp, &data, w, h, image::ColorType::Rgba8, image::ImageFormat::Png).map_err(|e| e.to_string())
    })
}

/// The main PNG, through CS184's tone step.
pub fn write_png(path: &Path, img: &Rgb) -> Result<()> {
    let mut data = Vec::with_capacity(img.pixels.len() * 4);
    for p in &img.pixels {
        data.extend_from_slice(&[tone_byte(p.x), tone_byte(p.y), tone_byte(p.z), 255]);
    }
    write_rgba_png(path, img.width, img.height, data)
}

/// The 8-bit formats `-f` writes, named by the file's extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DisplayFormat {
    Png,
    /// Baseline JPEG at quality 95 (lossy; no alpha).
    Jpeg,
}

/// JPEG quality for `-f NAME.jpg`: high enough that the tone step's
/// banding, not the compression, is what one sees.
const JPEG_QUALITY: u8 = 95;

impl DisplayFormat {
    /// The format `path`'s extension names (case-insensitive), or one line
    /// saying which extensions are accepted.
    pub fn of(path: &Path) -> Result<DisplayFormat> {
        let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
        match ext.as_deref() {
            Some("png") => Ok(DisplayFormat::Png),
            Some("jpg" | "jpeg") => Ok(DisplayFormat::Jpeg),
            Some(other) => Err(Error::new(format!("{}: cannot write images of type '.{other}': name a .png, .jpg or .jpeg file (linear radiance: --exr FILE.exr)", path.display()))),
            None => Err(Error::new(format!("{}: no file extension: name a .png, .jpg or .jpeg file", path.display()))),
        }
    }
}

/// The tone-mapped image in the format its extension names (PNG or JPEG).
pub fn write_display(path: &Path, img: &Rgb) -> Result<()> {
    match DisplayFormat::of(path)? {
        DisplayFormat::Png => write_png(path, img),
        DisplayFormat::Jpeg => {
            let mut data = Vec::with_capacity(img.pixels.len() * 3);
            for p in &img.pixels {
                data.extend_from_slice(&[tone_byte(p.x), tone_byte(p.y), tone_byte(p.z)]);
            }
            atomically(path, |tmp| {
                let file = std::fs::File::create(tmp).map_err(|e| e.to_string())?;
                let mut enc = image::codecs::jpeg::JpegEncoder::new_with_quality(std::io::BufWriter::new(file), JPEG_QUALITY);
                enc.encode(&data, img.width, img.height, image::ExtendedColorType::Rgb8).map_err(|e| e.to_string())
            })
        }
    }
}

/// `<name>_rate.png`: samples taken per pixel over the maximum, colour-mapped.
pub fn write_rate_png(path: &Path, w: u32, h: u32, samples: &[u32], max_samples: u32) -> Result<()> {
    let mut data = Vec::with_capacity(samples.len() * 4);
    for &n in samples {
        let [r, g, b] = rate_color(n as f32 / max_samples.max(1) as f32);
        data.extend_from_slice(&[r, g, b, 255]);
    }
    write_rgba_png(path, w, h, data)
}

/// Linear 32-bit float OpenEXR (RGB): RLE-compressed 64x64 tiles, written
/// in increasing order, so the same image always gives the same bytes (the
/// exr crate's default order is whichever tile its threads finish first,
/// which would make a merged split render differ from the one-machine file).
pub fn write_exr(path: &Path, img: &Rgb) -> Result<()> {
    use exr::prelude::*;
    atomically(path, |tmp| {
        let w = img.width as usize;
        let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
            let p = img.pixels[y * w + x];
            (p.x, p.y, p.z)
        });
        let encoding = Encoding { line_order: LineOrder::Increasing, ..Encoding::FAST_LOSSLESS };
        Image::from_encoded_channels((w, img.height as usize), encoding, channels).write().to_file(tmp).map_err(|e| e.to_string())
    })
}

/// The most pixels an OpenEXR image may have for `read_exr` (16384 x
/// 16384), and the most along a side: a header that claims more is refused
/// before anything is allocated for it (a damaged 500-byte file once
/// claimed 600 million pixels, and allocating them took seconds and gigabytes).
pub const MAX_EXR_PIXELS: u64 = 1 << 28;
pub const MAX_EXR_SIDE: u64 = 1 << 16;

/// Read an RGB(A) OpenEXR written by us or a reference renderer.
pub fn read_exr(path: &Path) -> Result<Rgb> {
    use exr::prelude::*;
    let fail = |e: String| crate::error::Error::new(format!("{}: cannot read OpenEXR: {e}", path.display()));
    // The headers first: sizes are checked before the pixels are read.
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| fail(e.to_string()))?;
    for h in &meta.headers {
        let (w, hgt) = (h.layer_size.width() as u64, h.layer_size.height() as u64);
        if w > MAX_EXR_SIDE || hgt > MAX_EXR_SIDE || w * hgt > MAX_EXR_PIXELS {
            return Err(fail(format!("a {w}x{hgt} layer is larger than this renderer reads (at most {MAX_EXR_PIXELS} pixels, {MAX_EXR_SIDE} a side)")));
        }
    }
    let image = read_first_rgba_layer_from_file(
        path,
        // The pixels are allocated when the first one is decoded.
        |res, _| Rgb { width: res.width() as u32, height: res.height() as u32, pixels: Vec::new() },
        |img: &mut Rgb, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            let w = img.width as usize;
            if img.pixels.is_empty() {
                img.pixels = vec![Vec3::ZERO; w * img.height as usize];
            }
            img.pixels[pos.y() * w + pos.x()] = Vec3::new(r, g, b);
        },
    )
    .map_err(|e| fail(e.to_string()))?;
    let mut img = image.layer_data.channel_data.pixels;
    if img.pixels.is_empty() {
        img.pixels = vec![Vec3::ZERO; img.width as usize * img.height as usize];
    }
    Ok(img)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tone_step_matches_cs184() {
        assert_eq!(tone_byte(0.0), 0);
        assert_eq!(tone_byte(-1.0), 0);
        assert_eq!(tone_byte(f32::NAN), 0);
        assert_eq!(tone_byte(10.0), 255);
        // (0.5*sqrt2)^(1/2.2) = 0.8540 -> 217.77 truncated.
        assert_eq!(tone_byte(0.5), 217);
    }

    #[test]
    fn rate_colours() {
        assert_eq!(rate_color(1.0), [255, 0, 0]);
        assert_eq!(rate_color(0.5), [0, 255, 0]);
        assert_eq!(rate_color(0.0), [0, 0, 255]);
    }
}
