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
    (i.reverse_bits(), sobol_y_reversed(i).reverse_bits())
}

/// Sobol dimension 1 of index `i`, bit-reversed: the XOR of the reversed
/// direction words of `i`'s set bits, a byte of `i` at a time from tables
/// (a loop over the bits mispredicts its branch on every other bit).
#[inline]
fn sobol_y_reversed(i: u32) -> u32 {
    reversed_from(&Y_REVERSED, i)
}

/// `Y_REVERSED[b][v]`: the XOR of `DIRECTIONS[8b + t].reverse_bits()` over
/// the set bits t of byte v.
static Y_REVERSED: [[u32; 256]; 4] = reversed_tables(&DIRECTIONS);

/// Direction words of Sobol dimensions 2 and 3 (Joe and Kuo's primitive
/// polynomials x² + x + 1, m = {1, 3}, and x³ + x + 1, m = {1, 3, 1}):
/// V[k] = m_k·2^(31−k) for the first s words, then Bratley and Fox's
/// recurrence.
const DIRECTIONS_2: [u32; 32] = directions(2, 0b1, [1, 3, 0]);
const DIRECTIONS_3: [u32; 32] = directions(3, 0b01, [1, 3, 1]);

const fn directions(s: usize, a: u32, m: [u32; 3]) -> [u32; 32] {
    let mut v = [0u32; 32];
    let mut k = 0;
    while k < 32 {
        if k < s {
            v[k] = m[k] << (31 - k);
        } else {
            let mut x = v[k - s] ^ (v[k - s] >> s);
            let mut i = 1;
            while i < s {
                // a's bit for V[k−i], most significant first.
                if (a >> (s - 1 - i)) & 1 != 0 {
                    x ^= v[k - i];
                }
                i += 1;
            }
            v[k] = x;
        }
        k += 1;
    }
    v
}

/// `Y_REVERSED`'s tables for dimensions 2 and 3.
static REVERSED_2: [[u32; 256]; 4] = reversed_tables(&DIRECTIONS_2);
static REVERSED_3: [[u32; 256]; 4] = reversed_tables(&DIRECTIONS_3);

/// Per byte b of an index and value v of that byte: the XOR of the
/// reversed direction words `dirs[8b + t]` over the set bits t of v.
const fn reversed_tables(dirs: &[u32; 32]) -> [[u32; 256]; 4] {
    let mut t = [[0u32; 256]; 4];
    let mut b = 0;
    while b < 4 {
        let mut v = 0;
        while v < 256 {
            let mut x = 0u32;
            let mut k = 0;
            while k < 8 {
                if v & (1 << k) != 0 {
                    x ^= dirs[8 * b + k].reverse_bits();
                }
                k += 1;
            }
            t[b][v] = x;
            v += 1;
        }
        b += 1;
    }
    t
}

/// A dimension of index `i`, bit-reversed, from its tables.
#[inline]
fn reversed_from(t: &[[u32; 256]; 4], i: u32) -> u32 {
    let lo = t[0][(i & 0xff) as usize];
    if i < 256 {
        return lo; // every render below 257 spp
    }
    lo ^ t[1][((i >> 8) & 0xff) as usize] ^ t[2][((i >> 16) & 0xff) as usize] ^ t[3][(i >> 24) as usize]
}

/// The scrambling hash on bit-reversed values: output bit k depends only
/// on input bits 0..=k (low to high), so reversing before and after makes
/// it a nested scramble from the top bit down (`owen`).
#[inline]
fn scramble_reversed(mut x: u32, seed: u32) -> u32 {
    x ^= x.wrapping_mul(0x3d20_adea);
    x = x.wrapping_add(seed);
    x = x.wrapping_mul((seed >> 16) | 1);
    x ^= x.wrapping_mul(0x0552_6c56);
    x ^= x.wrapping_mul(0x53a2_2864);
    x
}

/// Base-2 nested uniform (Owen) scrambling of `v`: bit b (from the top) is
/// flipped by a pseudo-random function of `seed` and the bits above it.
#[inline]
pub fn owen(v: u32, seed: u32) -> u32 {
    scramble_reversed(v.reverse_bits(), seed).reverse_bits()
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

/// A sample index as the draws take it: its `bits` low bits reversed
/// (all indices of a render are below 2^bits). Computed once per sample.
#[inline]
pub fn reversed_index(index: u32, bits: u32) -> u32 {
    if bits == 0 {
        0
    } else {
        index.reverse_bits() >> (32 - bits)
    }
}

/// The sample index, nested-scrambled within its `bits` low bits, from
/// `reversed_index`: the shuffled index stays below 2^bits (Cycles 3.5 caps
/// the index the same way), and aligned blocks still map to aligned blocks.
/// Equal to `owen(index << (32 - bits), seed) >> (32 - bits)`.
#[inline]
fn shuffled(rev_index: u32, bits: u32, seed: u32) -> u32 {
    if bits == 0 {
        return 0;
    }
    scramble_reversed(rev_index, seed).reverse_bits() >> (32 - bits)
}

/// Draw `index` (< 2^`bits`, given as `reversed_index(index, bits)`) of the
/// 2D sequence of dimension `dim` of a pixel. Each coordinate is
/// `owen(sobol, seed)`; the sobol point's own reversal cancels the scramble's
/// first one, so a draw costs three bit reversals.
#[inline]
pub fn sample_2d(pixel_seed: u64, dim: u64, rev_index: u32, bits: u32) -> (f32, f32) {
    let s = seeds_of(pixel_seed, dim);
    let j = shuffled(rev_index, bits, s[0]);
    let x = scramble_reversed(j, s[1]).reverse_bits();
    let y = scramble_reversed(sobol_y_reversed(j), s[2]).reverse_bits();
    (to_unit(x), to_unit(y))
}

/// Draw `index` of the 4D sequence of dimension `dim`: Sobol dimensions
/// 0-3 at one shuffled index, each Owen-scrambled on its own seed. Its
/// first two coordinates are `sample_2d`'s draw for the same `dim`, so a
/// 2D draw can be extended to a 4D point without changing it.
#[inline]
pub fn sample_4d(pixel_seed: u64, dim: u64, rev_index: u32, bits: u32) -> [f32; 4] {
    let s = seeds_of(pixel_seed, dim);
    let j = shuffled(rev_index, bits, s[0]);
    let x = scramble_reversed(j, s[1]).reverse_bits();
    let y = scramble_reversed(sobol_y_reversed(j), s[2]).reverse_bits();
    // Two more seeds from a second hash of the same (pixel, dimension).
    let h = crate::rng::mix64(pixel_seed ^ dim.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0x4D44_5F34_445F_5345);
    let z = scramble_reversed(reversed_from(&REVERSED_2, j), h as u32).reverse_bits();
    let w = scramble_reversed(reversed_from(&REVERSED_3, j), (h >> 32) as u32).reverse_bits();
    [to_unit(x), to_unit(y), to_unit(z), to_unit(w)]
}

/// Draw `index` of the 1D sequence of dimension `dim` of a pixel (Sobol
/// dimension 0: a scrambled van der Corput sequence), as `sample_2d`'s x.
#[inline]
pub fn sample_1d(pixel_seed: u64, dim: u64, rev_index: u32, bits: u32) -> f32 {
    let s = seeds_of(pixel_seed, dim);
    to_unit(scramble_reversed(shuffled(rev_index, bits, s[0]), s[1]).reverse_bits())
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

    /// The draws as the model states them, without the reversal shortcuts.
    fn sample_2d_by_definition(pixel_seed: u64, dim: u64, index: u32, bits: u32) -> (f32, f32) {
        let s = seeds_of(pixel_seed, dim);
        let j = if bits == 0 { 0 } else { owen(index << (32 - bits), s[0]) >> (32 - bits) };
        let mut y = 0;
        for k in 0..32 {
            if j >> k & 1 != 0 {
                y ^= DIRECTIONS[k];
            }
        }
        (to_unit(owen(j.reverse_bits(), s[1])), to_unit(owen(y, s[2])))
    }

    #[test]
    fn shortcuts_give_the_defined_draws() {
        for (bits, n) in [(0u32, 1u32), (1, 2), (4, 16), (8, 256), (10, 1024), (20, 1 << 12), (32, 1 << 12)] {
            for dim in [0u64, 5, 1 << 40] {
                for i in 0..n {
                    let index = if bits == 32 { i.wrapping_mul(0x9E37_79B9) } else if bits == 20 { i * 255 } else { i };
                    let r = reversed_index(index, bits);
                    assert_eq!(sample_2d(77, dim, r, bits), sample_2d_by_definition(77, dim, index, bits), "bits {bits} index {index}");
                    assert_eq!(sample_1d(77, dim, r, bits), sample_2d_by_definition(77, dim, index, bits).0, "1D bits {bits} index {index}");
                }
            }
        }
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
                let pts: Vec<(f32, f32)> = (0..1024).map(|i| sample_2d(seed, dim, reversed_index(i, 10), 10)).collect();
                for m in 1..=8u32 {
                    for block in pts.chunks(1 << m).take(4) {
                        assert!(is_net(block, m), "pixel {pixel} dim {dim} m {m}");
                    }
                }
                // 1D: every aligned block of 2^m is stratified in 2^m intervals.
                let bits = 8 + (pixel % 3) as u32;
                let xs: Vec<f32> = (0..256).map(|i| sample_1d(seed, dim, reversed_index(i, bits), bits)).collect();
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

    /// Dimensions 2 and 3's direction words from Joe and Kuo's m-values by
    /// the integer recurrence m_k = 2a_1·m_(k−1) ⊕ … ⊕ 2^s·m_(k−s) ⊕ m_(k−s)
    /// (their formulation, not the shifted-word one the tables use).
    #[test]
    fn dimensions_2_and_3_are_joe_and_kuos() {
        for (s, a, init, words) in [(2usize, 1u64, vec![1u64, 3], &DIRECTIONS_2), (3, 1, vec![1, 3, 1], &DIRECTIONS_3)] {
            let mut m = init.clone();
            for k in s..32 {
                let mut x = (m[k - s] << s) ^ m[k - s];
                for i in 1..s {
                    if (a >> (s - 1 - i)) & 1 != 0 {
                        x ^= m[k - i] << i;
                    }
                }
                m.push(x);
            }
            for k in 0..32 {
                assert_eq!(words[k] as u64, m[k] << (31 - k), "s {s} word {k}");
            }
        }
        // Dimension 2 in index order.
        let z: Vec<f64> = (0..8u32).map(|i| (0..32).filter(|k| i >> k & 1 != 0).fold(0u32, |acc, k| acc ^ DIRECTIONS_2[k]) as f64 / 4294967296.0).collect();
        assert_eq!(z, [0.0, 0.5, 0.75, 0.25, 0.375, 0.875, 0.625, 0.125]);
    }

    /// Whether `pts` (2^m of them, `d` coordinates each) is a (t,m,d)-net:
    /// every elementary box of volume 2^(t−m) holds exactly 2^t points.
    fn is_net_nd(pts: &[[f32; 4]], dims: &[usize], m: u32, t: u32) -> bool {
        fn splits(total: u32, parts: usize) -> Vec<Vec<u32>> {
            if parts == 1 {
                return vec![vec![total]];
            }
            (0..=total).flat_map(|k| splits(total - k, parts - 1).into_iter().map(move |mut v| {
                v.insert(0, k);
                v
            })).collect()
        }
        splits(m - t, dims.len()).iter().all(|e| {
            let mut count = std::collections::HashMap::new();
            for p in pts {
                let cell: Vec<u32> = dims.iter().zip(e).map(|(&d, &k)| (p[d] * (1u64 << k) as f32) as u32).collect();
                *count.entry(cell).or_insert(0u32) += 1;
            }
            count.len() == 1 << (m - t) && count.values().all(|&c| c == 1 << t)
        })
    }

    /// The 4D draw: its first two coordinates are the 2D draw of the same
    /// dimension; every aligned block of 2^m is a (3,m,4)-net (Sobol's t
    /// for its first four dimensions), its last two coordinates a
    /// (1,m,2)-net (m = 3: (2,3,2)) and its first two a (0,m,2)-net.
    #[test]
    fn four_d_blocks_are_nets() {
        for pixel in 0..16u64 {
            let seed = crate::rng::mix64(pixel ^ 0xabc);
            for dim in [0u64, 33] {
                let pts: Vec<[f32; 4]> = (0..256).map(|i| sample_4d(seed, dim, reversed_index(i, 8), 8)).collect();
                for (i, p) in pts.iter().enumerate() {
                    assert_eq!((p[0], p[1]), sample_2d(seed, dim, reversed_index(i as u32, 8), 8));
                }
                for m in 3..=8u32 {
                    for block in pts.chunks(1 << m).take(2) {
                        assert!(is_net_nd(block, &[0, 1, 2, 3], m, 3), "pixel {pixel} dim {dim} m {m}: not a (3,m,4)-net");
                        let t = if m == 3 { 2 } else { 1 };
                        assert!(is_net_nd(block, &[2, 3], m, t), "pixel {pixel} dim {dim} m {m}: light pair not a ({t},m,2)-net");
                        assert!(is_net_nd(block, &[0, 1], m, 0), "pixel {pixel} dim {dim} m {m}: pixel pair not a (0,m,2)-net");
                    }
                }
            }
        }
    }
}
