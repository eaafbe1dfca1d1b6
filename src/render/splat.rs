//! The film of splats: light that a light-tracing connection (bidirectional
//! path tracing's t = 1 strategies, the light tracer) lands on whatever
//! pixel its ray meets, rather than the pixel whose sample made it.
//!
//! Exact, as the pixel sums are (`sums`): every splat is added to its pixel
//! in the same 192-bit fixed point, so the film does not depend on the
//! order splats arrive in — threads, tiles, or a render split by samples
//! over machines whose films are added. The normalisation is applied once,
//! to the whole render's film: every pixel sample traces one light subpath,
//! and the camera's importance is normalised over the whole frame, so each
//! light subpath estimates the whole frame and a pixel's splat estimate is
//! its splat sum × frame pixels / light subpaths, the light subpaths being
//! the samples of every pixel rendered (pbrt-v4 scales by 1/spp, the same
//! without `-p` cells). pbrt-v4 adds splats with floating-point atomics,
//! whose order (and so rounding) depends on scheduling.
//!
//! Box pixels: a splat goes to the one pixel containing it, as the camera
//! samples' box filter (pbrt-v3's splats do the same).
//!
//! The variance of a pixel's splat estimate is taken from the splats' own
//! squares, each splat counted as a sample of the light subpaths (zero for
//! those that splat elsewhere): slightly low where one light subpath splats
//! into one pixel twice (two strategies through the same lens point).

use super::sums::{add_channels, Fixed};
use glam::Vec3;

/// Light landing on frame pixel (x, y) (CS184's frame coordinates, y up).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Splat {
    pub x: u32,
    pub y: u32,
    pub l: Vec3,
}

/// One pixel's splats: exact sums of their values and squares per channel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SplatSums {
    pub sum: [Fixed; 3],
    pub sum_sq: [Fixed; 3],
}

impl SplatSums {
    /// Add one splat. Returns whether it had to be changed (a NaN channel
    /// counted as 0, a magnitude above `SAMPLE_LIMIT` as the limit), as
    /// `PixelSums::add` does.
    pub fn add(&mut self, l: Vec3) -> bool {
        add_channels(&mut self.sum, &mut self.sum_sq, l.to_array())
    }

    pub fn merge(&mut self, o: &SplatSums) {
        for c in 0..3 {
            self.sum[c] = self.sum[c].add(o.sum[c]);
            self.sum_sq[c] = self.sum_sq[c].add(o.sum_sq[c]);
        }
    }

    /// This pixel's splat estimate and its variance, per channel, for a
    /// render of `light_paths` light subpaths over a frame of `frame_pixels`.
    pub fn estimate(&self, light_paths: u64, frame_pixels: u64) -> ([f32; 3], [f32; 3]) {
        if light_paths == 0 {
            return ([0.0; 3], [0.0; 3]);
        }
        let n = light_paths as f64;
        let scale = frame_pixels as f64 / n;
        let mean = [0, 1, 2].map(|c| (self.sum[c].to_f64() * scale) as f32);
        let var = [0, 1, 2].map(|c| {
            let s = self.sum[c].to_f64();
            let q = self.sum_sq[c].to_f64();
            ((q - s * (s / n)).max(0.0) * scale * scale) as f32
        });
        (mean, var)
    }

    /// Bytes in a partial file: Σx and Σx², three limbs each, little-endian.
    pub const BYTES: usize = 6 * 24;

    pub fn write_le(&self, out: &mut Vec<u8>) {
        for f in self.sum.iter().chain(self.sum_sq.iter()) {
            for limb in f.0 {
                out.extend_from_slice(&limb.to_le_bytes());
            }
        }
    }

    pub fn read_le(b: &[u8]) -> SplatSums {
        let u64_at = |i: usize| u64::from_le_bytes(b[i..i + 8].try_into().unwrap());
        let fixed_at = |k: usize| Fixed([u64_at(24 * k), u64_at(8 + 24 * k), u64_at(16 + 24 * k)]);
        SplatSums { sum: [fixed_at(0), fixed_at(1), fixed_at(2)], sum_sq: [fixed_at(3), fixed_at(4), fixed_at(5)] }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splat_sums_do_not_depend_on_order_and_round_trip() {
        let values: Vec<Vec3> = (0..200).map(|i| Vec3::new(i as f32 * 0.37, 1e-6 * i as f32, (i as f32).powi(5))).collect();
        let mut fwd = SplatSums::default();
        values.iter().for_each(|v| {
            fwd.add(*v);
        });
        let (mut a, mut b) = (SplatSums::default(), SplatSums::default());
        for (i, v) in values.iter().enumerate().rev() {
            let _ = if i % 3 == 0 { a.add(*v) } else { b.add(*v) };
        }
        b.merge(&a);
        assert_eq!(fwd, b);
        let mut bytes = Vec::new();
        fwd.write_le(&mut bytes);
        assert_eq!(bytes.len(), SplatSums::BYTES);
        assert_eq!(SplatSums::read_le(&bytes), fwd);
        let mut bad = fwd;
        assert!(bad.add(Vec3::new(f32::NAN, 0.0, 0.0)));
    }

    #[test]
    fn estimate_scales_by_frame_pixels_over_light_paths() {
        let mut s = SplatSums::default();
        s.add(Vec3::splat(2.0));
        s.add(Vec3::splat(4.0));
        // 6 over 12 light paths, 4 pixels: 6·4/12 = 2.
        let (m, v) = s.estimate(12, 4);
        assert_eq!(m, [2.0; 3]);
        // (Σx² − (Σx)²/n)·scale² = (20 − 3)·(1/3)² = 17/9.
        assert!((v[0] - 17.0 / 9.0).abs() < 1e-6, "{v:?}");
    }
}
