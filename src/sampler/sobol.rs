//! Owen-scrambled, shuffled Sobol points (Burley 2020, "Practical Hash-based
//! Owen Scrambling"), one independent 2D (or 1D) sequence per dimension id.
//!
//! Model: for pixel seed `s` and dimension id `d`, the draw of sample index
//! `i` is
//!   j = owen(i, h(s, d, 0))                 — the index, nested-scrambled
//!   (x, y) = Sobol dimensions 0 and 1 at j   — x = bit-reverse(j)
//!   u = owen(x, h(s, d, 1)), v = owen(y, h(s, d, 2))
//! `owen` is base-2 nested uniform scrambling done with a hash whose output
//! bit k depends only on input bits 0..k, applied to the bit-reversed value
//! (the hash is the one with Vegdahl's 2021 constants, as Cycles 3.4's
//! `reversed_bit_owen` and pbrt-v4's `FastOwenScrambler` use).
//!
//! Why this shape: scrambling the index maps every aligned block of 2^m
//! indices onto an aligned block of the Sobol sequence, which is a
//! (0,m,2)-net, and Owen scrambling keeps nets nets; so every aligned block
//! of 2^m consecutive samples of one pixel's draw is stratified in every
//! elementary interval of area 2^-m. Seeding each dimension id on its own
//! ("padding") decorrelates dimensions without a dimension limit, so the
//! integrator can give every draw a fixed id (camera, lens, then per bounce:
//! light, BSDF, Russian roulette) and a skipped draw never shifts another.
//! CS184 has no such sampler: it draws independent uniform numbers.

/// Sobol dimension 1's direction words: V[0] = 2^31, V[k] = V[k-1] ^ (V[k-1] >> 1)
/// (the Pascal matrix mod 2).
const DIRECTIONS: [u32; 32] = {
    let mut v = [0u32; 32];
    v[0] = 1 << 31;
    let mut k = 1;
    while k < 32 {
        v[k] = v[k - 1] ^ (v[k - 1] >> 1);
        k += 1;
    }
    v
};

/// Sobol dimensions 0 and 1 of index `i`, as 32-bit fractions.
#[inline]
pub fn sobol2(i: u32) -> (u32, u32) {
    let mut y = 0;
    let mut bits = i;
    let mut k = 0;
    while bits != 0 {
        if bits & 1 != 0 {
            y ^= DIRECTIONS[k];
        }
        bits >>= 1;
        k += 1;
    }
    (i.reverse_bits(), y)
}

/// Base-2 nested uniform (Owen) scrambling of `v`: bit b (from the top) is
/// flipped by a pseudo-random function of `seed` and the bits above it.
#[inline]
pub fn owen(v: u32, seed: u32) -> u32 {
    let mut x = v.reverse_bits();
    x ^= x.wrapping_mul(0x3d20_adea);
    x = x.wrapping_add(seed);
    x = x.wrapping_mul((seed >> 16) | 1);
    x ^= x.wrapping_mul(0x0552_6c56);
    x ^= x.wrapping_mul(0x53a2_2864);
    x.reverse_bits()
}

/// Three 32-bit scramble seeds (index, x, y) of (pixel seed, dimension id),
/// from one 64-bit hash.
#[inline]
fn seeds_of(pixel_seed: u64, dim: u64) -> [u32; 3] {
    let h = crate::rng::mix64(pixel_seed ^ dim.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    [h as u32, (h >> 32) as u32, (h.wrapping_mul(0xD6E8_FEB8_6659_FD93) >> 32) as u32]
}

/// A 32-bit fraction as a float in [0, 1): its top 24 bits, so 1 is never returned.
#[inline]
pub fn to_unit(bits: u32) -> f32 {
    (bits >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// The sample index, nested-scrambled within its `bits` low bits (all
/// indices of a render are below 2^bits): the shuffled index stays below
/// 2^bits, so `sobol2` loops over `bits` bits, not 32 (Cycles 3.5 caps the
/// index the same way), and aligned blocks still map to aligned blocks.
#[inline]
fn shuffled(index: u32, bits: u32, seed: u32) -> u32 {
    if bits == 0 {
        return 0;
    }
    owen(index << (32 - bits), seed) >> (32 - bits)
}

/// Draw `index` (< 2^`bits`) of the 2D sequence of dimension `dim` of a pixel.
#[inline]
pub fn sample_2d(pixel_seed: u64, dim: u64, index: u32, bits: u32) -> (f32, f32) {
    let s = seeds_of(pixel_seed, dim);
    let (x, y) = sobol2(shuffled(index, bits, s[0]));
    (to_unit(owen(x, s[1])), to_unit(owen(y, s[2])))
}

/// Draw `index` of the 1D sequence of dimension `dim` of a pixel (Sobol
/// dimension 0: a scrambled van der Corput sequence).
#[inline]
pub fn sample_1d(pixel_seed: u64, dim: u64, index: u32, bits: u32) -> f32 {
    let s = seeds_of(pixel_seed, dim);
    to_unit(owen(shuffled(index, bits, s[0]).reverse_bits(), s[1]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether `pts` (2^m of them) is a (0,m,2)-net: every elementary
    /// interval [a/2^k, (a+1)/2^k) x [b/2^(m-k), (b+1)/2^(m-k)) holds exactly one.
    fn is_net(pts: &[(f32, f32)], m: u32) -> bool {
        (0..=m).all(|k| {
            let mut seen = vec![false; 1 << m];
            pts.iter().all(|&(x, y)| {
                let (cx, cy) = ((x * (1u32 << k) as f32) as usize, (y * (1u32 << (m - k)) as f32) as usize);
                let cell = (cx << (m - k)) | cy;
                !std::mem::replace(&mut seen[cell], true)
            })
        })
    }

    #[test]
    fn sobol_is_the_known_sequence() {
        // Dimension 1 in index (not Gray-code) order: 0, 1/2, 3/4, 1/4, 5/8, 1/8, 3/8, 7/8.
        let y: Vec<f64> = (0..8).map(|i| sobol2(i).1 as f64 / 4294967296.0).collect();
        assert_eq!(y, [0.0, 0.5, 0.75, 0.25, 0.625, 0.125, 0.375, 0.875]);
        let x: Vec<f64> = (0..4).map(|i| sobol2(i).0 as f64 / 4294967296.0).collect();
        assert_eq!(x, [0.0, 0.5, 0.25, 0.75]);
    }

    #[test]
    fn owen_scrambling_is_nested() {
        // Values sharing their top b bits keep sharing them (possibly
        // flipped together): the scramble is a nested permutation.
        for seed in [1u32, 0xdead_beef, 77] {
            for v in [0u32, 0x1234_5678, 0xffff_0000] {
                for b in 1..31 {
                    let w = v ^ (1 << (31 - b)); // differs first at bit b from the top
                    let (sv, sw) = (owen(v, seed), owen(w, seed));
                    let top = !0u32 << (32 - b);
                    assert_eq!(sv & top, sw & top, "seed {seed} v {v:#x} bit {b}");
                    assert_ne!(sv, sw);
                }
            }
        }
    }

    #[test]
    fn every_aligned_block_is_a_net() {
        for pixel in 0..64u64 {
            let seed = crate::rng::mix64(pixel);
            for dim in [0u64, 1, 17, 1000, 1 << 48] {
                let pts: Vec<(f32, f32)> = (0..1024).map(|i| sample_2d(seed, dim, i, 10)).collect();
                for m in 1..=8u32 {
                    for block in pts.chunks(1 << m).take(4) {
                        assert!(is_net(block, m), "pixel {pixel} dim {dim} m {m}");
                    }
                }
                // 1D: every aligned block of 2^m is stratified in 2^m intervals.
                let xs: Vec<f32> = (0..256).map(|i| sample_1d(seed, dim, i, 8 + (pixel % 3) as u32)).collect();
                for m in 1..=8u32 {
                    for block in xs.chunks(1 << m) {
                        let mut seen = vec![false; 1 << m];
                        for &x in block {
                            assert!(!std::mem::replace(&mut seen[(x * (1u32 << m) as f32) as usize], true), "1D pixel {pixel} dim {dim} m {m}");
                        }
                    }
                }
            }
        }
    }
}
