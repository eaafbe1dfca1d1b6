//! Exact per-pixel sums: sample count, Σx and Σx² per channel, in fixed point.
//!
//! Why not f64: floating-point addition is not associative, so a pixel whose
//! samples are summed in two parts and then added (a split render, `merge`)
//! would differ in its last bits from the same samples summed in one run.
//! Here every sample is converted, by a fixed function of its value alone,
//! to a 192-bit two's-complement integer with 96 fraction bits, and integer
//! addition is associative: any grouping of the same samples — one machine,
//! N sample ranges, tiles, any order — gives the same bits, and so the same
//! image, byte for byte.
//!
//! Range: a sample channel is an f32; its square is exact in f64 (48-bit
//! mantissa). Every f32 of magnitude ≥ 2^-72 (Σx) or ≥ 2^-24 (Σx²) lands
//! on the grid exactly; smaller ones are truncated at 2^-96 ≈ 1.3e-29,
//! far below anything an image shows. Sample values are limited to
//! |x| ≤ [`SAMPLE_LIMIT`] = 2^36 (radiance 6.9e10, which no physical
//! sample reaches), so that Σx² over the at most 2^20 samples a pixel
//! keeps (`-s` ≤ 1048576) stays below 2^92 < 2^95, the integer range. A sample outside it, or NaN, is counted in
//! [`PixelSums::add`]'s return value and reported by the caller, never
//! clamped silently.

/// Largest sample magnitude accumulated as is (see the module comment).
pub const SAMPLE_LIMIT: f32 = 68_719_476_736.0; // 2^36

/// A 192-bit two's-complement fixed-point number with 96 fraction bits,
/// little-endian limbs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Fixed(pub [u64; 3]);

impl Fixed {
    pub const ZERO: Fixed = Fixed([0; 3]);
    const FRACTION_BITS: i32 = 96;

    /// `v` on the 2^-96 grid, truncated toward zero. `|v|` must be below
    /// 2^95 (callers pass at most 2^72).
    #[inline]
    pub fn from_f64(v: f64) -> Fixed {
        debug_assert!(v.is_finite() && v.abs() < 2f64.powi(95), "{v}");
        let bits = v.to_bits();
        let exp_bits = ((bits >> 52) & 0x7ff) as i32;
        if exp_bits == 0 {
            // Zero or subnormal (< 2^-1022): below the grid.
            return Fixed::ZERO;
        }
        // |v| = m * 2^(pos - 96): m's lowest bit lands on grid bit `pos`.
        let m = (bits & ((1u64 << 52) - 1)) | 1 << 52;
        let pos = exp_bits - 1075 + Self::FRACTION_BITS;
        let (lo, hi): (u128, u64) = if pos <= 0 {
            ((if pos > -64 { m >> -pos } else { 0 }) as u128, 0)
        } else if pos < 128 {
            // m has 53 bits: it spills into the top limb once pos > 75.
            ((m as u128) << pos, if pos > 75 { m >> (128 - pos) } else { 0 })
        } else {
            (0, m << (pos - 128))
        };
        let f = Fixed([lo as u64, (lo >> 64) as u64, hi]);
        if v < 0.0 {
            f.neg()
        } else {
            f
        }
    }

    fn neg(self) -> Fixed {
        let inv = Fixed([!self.0[0], !self.0[1], !self.0[2]]);
        inv.add(Fixed([1, 0, 0]))
    }

    #[inline]
    pub fn add(self, o: Fixed) -> Fixed {
        let a = self.0[0] as u128 | (self.0[1] as u128) << 64;
        let b = o.0[0] as u128 | (o.0[1] as u128) << 64;
        let (lo, carry) = a.overflowing_add(b);
        let hi = self.0[2].wrapping_add(o.0[2]).wrapping_add(carry as u64);
        Fixed([lo as u64, (lo >> 64) as u64, hi])
    }

    fn is_negative(self) -> bool {
        self.0[2] >> 63 == 1
    }

    /// The value as an f64: a fixed function of the bits, so equal sums give
    /// equal results (within a few ulp of the exact value).
    pub fn to_f64(self) -> f64 {
        if self.is_negative() {
            return -self.neg().to_f64();
        }
        let [l0, l1, l2] = self.0;
        l2 as f64 * 2f64.powi(128 - Self::FRACTION_BITS) + l1 as f64 * 2f64.powi(64 - Self::FRACTION_BITS) + l0 as f64 * 2f64.powi(-Self::FRACTION_BITS)
    }
}

/// Add one value's channels to exact sums of values and squares. Returns
/// whether it had to be changed to be accumulated: a NaN channel counts as
/// 0 and a magnitude above `SAMPLE_LIMIT` as the limit (the caller reports
/// how many). Pixel samples and splats alike.
#[inline]
pub fn add_channels(sum: &mut [Fixed; 3], sum_sq: &mut [Fixed; 3], l: [f32; 3]) -> bool {
    let mut changed = false;
    for c in 0..3 {
        let mut x = l[c];
        if !(x.abs() <= SAMPLE_LIMIT) {
            changed = true;
            x = if x.is_nan() { 0.0 } else { SAMPLE_LIMIT.copysign(x) };
        }
        if x == 0.0 {
            continue; // adds nothing (black samples are common: escaped rays, shadow)
        }
        let x = x as f64;
        sum[c] = sum[c].add(Fixed::from_f64(x));
        sum_sq[c] = sum_sq[c].add(Fixed::from_f64(x * x));
    }
    changed
}

/// One pixel's samples: how many, and exact sums of radiance and its square.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PixelSums {
    pub n: u32,
    pub sum: [Fixed; 3],
    pub sum_sq: [Fixed; 3],
}

impl PixelSums {
    /// Add one sample. Returns whether the sample had to be changed to be
    /// accumulated: a NaN channel counts as 0 and a magnitude above
    /// `SAMPLE_LIMIT` as the limit (the caller reports how many).
    #[inline]
    pub fn add(&mut self, l: [f32; 3]) -> bool {
        self.n += 1;
        add_channels(&mut self.sum, &mut self.sum_sq, l)
    }

    /// The samples of both: exact, so the order of merging never matters.
    pub fn merge(&mut self, o: &PixelSums) {
        self.n += o.n;
        for c in 0..3 {
            self.sum[c] = self.sum[c].add(o.sum[c]);
            self.sum_sq[c] = self.sum_sq[c].add(o.sum_sq[c]);
        }
    }

    /// Mean per channel (0 without samples).
    pub fn mean(&self) -> [f32; 3] {
        if self.n == 0 {
            return [0.0; 3];
        }
        let n = self.n as f64;
        [0, 1, 2].map(|c| (self.sum[c].to_f64() / n) as f32)
    }

    /// Variance of the mean per channel (0 with fewer than two samples):
    /// (Σx² − Σx·mean) / (n(n−1)), clamped at 0 against rounding.
    pub fn var_of_mean(&self) -> [f32; 3] {
        if self.n < 2 {
            return [0.0; 3];
        }
        let n = self.n as f64;
        [0, 1, 2].map(|c| {
            let s = self.sum[c].to_f64();
            let q = self.sum_sq[c].to_f64();
            ((q - s * (s / n)).max(0.0) / (n * (n - 1.0))) as f32
        })
    }

    /// Bytes in a partial file: n, then Σx and Σx² (three limbs each), all
    /// little-endian.
    pub const BYTES: usize = 4 + 6 * 24;

    pub fn write_le(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.n.to_le_bytes());
        for f in self.sum.iter().chain(self.sum_sq.iter()) {
            for limb in f.0 {
                out.extend_from_slice(&limb.to_le_bytes());
            }
        }
    }

    pub fn read_le(b: &[u8]) -> PixelSums {
        let u64_at = |i: usize| u64::from_le_bytes(b[i..i + 8].try_into().unwrap());
        let fixed_at = |k: usize| Fixed([u64_at(4 + 24 * k), u64_at(12 + 24 * k), u64_at(20 + 24 * k)]);
        PixelSums {
            n: u32::from_le_bytes(b[0..4].try_into().unwrap()),
            sum: [fixed_at(0), fixed_at(1), fixed_at(2)],
            sum_sq: [fixed_at(3), fixed_at(4), fixed_at(5)],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    #[test]
    fn f32_values_land_exactly() {
        for v in [0.0f64, 1.0, 0.5, 3.0, -2.75, 1e-10, 123456.789f32 as f64, 2f64.powi(-72), 2f64.powi(72), -(2f64.powi(60) + 1.0)] {
            assert_eq!(Fixed::from_f64(v).to_f64(), v, "{v}");
        }
        // Below the grid: truncated toward zero.
        assert_eq!(Fixed::from_f64(2f64.powi(-100)), Fixed::ZERO);
        assert_eq!(Fixed::from_f64(3.0 * 2f64.powi(-97)).to_f64(), 2f64.powi(-96));
    }

    #[test]
    fn sums_do_not_depend_on_grouping() {
        // Values over many orders of magnitude, where f64 sums do depend on order.
        let mut rng = Rng::new(3, 4);
        let samples: Vec<[f32; 3]> = (0..1000)
            .map(|_| [0, 1, 2].map(|_| (rng.uniform() * 2.0).powi(40) * 1e-3 + rng.uniform() * 1e-7))
            .collect();
        let mut whole = PixelSums::default();
        for s in &samples {
            whole.add(*s);
        }
        for parts in [2, 3, 7, 64] {
            let mut merged = PixelSums::default();
            // Parts merged in reverse order, too.
            for p in (0..parts).rev() {
                let mut part = PixelSums::default();
                for s in &samples[p * samples.len() / parts..(p + 1) * samples.len() / parts] {
                    part.add(*s);
                }
                merged.merge(&part);
            }
            assert_eq!(merged, whole, "{parts} parts");
        }
        // ...and f64 would not have been enough for this test to mean something.
        let f64_fwd: f64 = samples.iter().map(|s| s[0] as f64).sum();
        let f64_rev: f64 = samples.iter().rev().map(|s| s[0] as f64).sum();
        assert_ne!(f64_fwd, f64_rev);
        let exact = whole.sum[0].to_f64();
        assert!((exact - f64_fwd).abs() <= 1e-12 * exact, "{exact} {f64_fwd}");
    }

    #[test]
    fn mean_and_variance() {
        let mut p = PixelSums::default();
        for x in [1.0f32, 2.0, 3.0, 4.0] {
            p.add([x, 0.25, -x]);
        }
        assert_eq!(p.mean(), [2.5, 0.25, -2.5]);
        // Sample variance 5/3, of the mean 5/12; a constant has none.
        let v = p.var_of_mean();
        assert!((v[0] - 5.0 / 12.0).abs() < 1e-6 && v[1] == 0.0 && (v[2] - 5.0 / 12.0).abs() < 1e-6, "{v:?}");
        let mut one = PixelSums::default();
        one.add([7.0; 3]);
        assert_eq!(one.var_of_mean(), [0.0; 3]);
    }

    #[test]
    fn out_of_range_samples_are_reported() {
        let mut p = PixelSums::default();
        assert!(!p.add([1.0, SAMPLE_LIMIT, 0.0]));
        assert!(p.add([f32::NAN, 0.0, 0.0]));
        assert!(p.add([f32::INFINITY, 0.0, 0.0]));
        assert_eq!(p.n, 3);
        assert_eq!(p.sum[0].to_f64(), 1.0 + SAMPLE_LIMIT as f64);
        // The worst case fits: 2^21 samples at the limit.
        let mut q = PixelSums { n: 0, sum: [Fixed::from_f64(2f64.powi(57)); 3], sum_sq: [Fixed::from_f64(2f64.powi(93)); 3] };
        q.add([SAMPLE_LIMIT; 3]);
        assert!(!q.sum_sq[0].is_negative());
    }

    #[test]
    fn bytes_round_trip() {
        let mut p = PixelSums::default();
        p.add([0.1, 2.0, 1e5]);
        p.add([-3.0, 0.0, 7.5]);
        let mut b = Vec::new();
        p.write_le(&mut b);
        assert_eq!(b.len(), PixelSums::BYTES);
        assert_eq!(PixelSums::read_le(&b), p);
    }
}
