//! Colour: the one measure of brightness everything shares.

use glam::Vec3;

/// CS184 illuminance (Rec. 709 luminance): what light sampling, the
/// adaptive stopping rule and the environment map's tables weigh colours by.
#[inline]
pub fn illuminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}
