//! Image error metrics (relMSE, relative bias; docs/validation/speed-vs-error.md).

use crate::image_io::Rgb;

/// Relative MSE, the usual renderer metric: mean over pixels and channels of
/// (x - r)^2 / (r^2 + eps), eps = 0.01 so black reference pixels stay finite.
pub fn rel_mse(img: &Rgb, reference: &Rgb) -> f64 {
    assert_eq!((img.width, img.height), (reference.width, reference.height), "image sizes differ");
    let mut sum = 0.0f64;
    for (x, r) in img.pixels.iter().zip(&reference.pixels) {
        for c in 0..3 {
            let (x, r) = (x[c] as f64, r[c] as f64);
            sum += (x - r) * (x - r) / (r * r + 1e-2);
        }
    }
    sum / (3 * img.pixels.len()) as f64
}

/// Signed relative bias of the image mean: sum(x - r) / sum(r).
pub fn rel_bias(img: &Rgb, reference: &Rgb) -> f64 {
    let sx: f64 = img.pixels.iter().map(|p| (p.x + p.y + p.z) as f64).sum();
    let sr: f64 = reference.pixels.iter().map(|p| (p.x + p.y + p.z) as f64).sum();
    (sx - sr) / sr
}
