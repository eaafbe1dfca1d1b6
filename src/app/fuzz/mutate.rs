//! The mutations: what the fuzzer does to a seed input.
//!
//! Byte-level changes (bit flips, bytes set to boundary values, ranges
//! deleted, duplicated, inserted or spliced in from another seed, files cut
//! short, 32-bit fields set to boundary integers) reach the binary readers
//! (PLY, OpenEXR, partial records); text-aware ones (a number replaced by
//! NaN, an infinity, a huge or negative count; a line deleted, repeated or
//! swapped) reach the text readers' fields instead of their tokenisers.
//! One to four are stacked per case. Everything is drawn from a seeded
//! PCG32, so a case is reproducible from (seed, case number) alone.

use crate::rng::Rng;

/// Numbers that break readers: non-finite values, overflowing counts,
/// negatives where indices go, denormals, values at type limits.
const NUMBERS: &[&str] = &[
    "nan", "NaN", "inf", "-inf", "1e39", "-1e39", "1e308", "0", "-0", "-1", "1", "2", "3", "1e-45", "4294967295", "4294967296",
    "2147483647", "-2147483648", "18446744073709551616", "99999999999999999999999", "0.5", "-0.5", "1e12", "3.4e38", "", "0x10", "1,5",
];

/// Single bytes that mean something to a parser.
const BYTES: &[u8] = &[0, 0xff, 0x7f, 0x80, b'0', b'9', b'-', b'.', b'e', b' ', b'\n', b'\r', b'<', b'>', b'/', b'"', b'#', b'\t'];

/// 32-bit values for binary fields (counts, sizes, offsets).
const WORDS: &[u32] = &[0, 1, 2, 0x7fff_ffff, 0x8000_0000, 0xffff_ffff, 0xffff, 0x1_0000, 0x7f80_0000, 0xffc0_0000, 0x3f80_0000];

/// A uniform integer in `0..n` (`n > 0`).
fn below(rng: &mut Rng, n: usize) -> usize {
    ((rng.next_u32() as u64 * n as u64) >> 32) as usize
}

/// `input` with one to four mutations; `others` are the seeds to splice
/// from. For a text format (`text`), nine in ten mutations keep the text
/// valid UTF-8 (numbers, digits, lines, ranges), so that the cases reach
/// the fields instead of stopping at the decoder.
pub fn mutate(input: &[u8], others: &[&[u8]], text: bool, rng: &mut Rng) -> Vec<u8> {
    let mut v = input.to_vec();
    for _ in 0..1 + below(rng, 4) {
        let op = if text && below(rng, 10) != 0 { TEXT_OPS[below(rng, TEXT_OPS.len())] } else { below(rng, 13) };
        mutate_once(&mut v, others, op, rng);
    }
    v
}

/// The mutations (numbers of `mutate_once`) that keep ASCII text ASCII,
/// weighted toward numbers and lines.
const TEXT_OPS: &[usize] = &[3, 4, 5, 7, 8, 7, 8, 9, 9, 10, 12, 12];

fn mutate_once(v: &mut Vec<u8>, others: &[&[u8]], op: usize, rng: &mut Rng) {
    if v.is_empty() {
        v.push(BYTES[below(rng, BYTES.len())]);
        return;
    }
    let len = v.len();
    let at = below(rng, len);
    match op {
        0 | 1 => v[at] ^= 1 << below(rng, 8),
        2 => v[at] = BYTES[below(rng, BYTES.len())],
        3 => {
            let n = 1 + below(rng, 64.min(len - at));
            v.drain(at..at + n);
        }
        4 => {
            let n = 1 + below(rng, 256.min(len - at));
            let piece = v[at..at + n].to_vec();
            let to = below(rng, len + 1);
            v.splice(to..to, piece);
        }
        5 => v.truncate(at),
        6 => {
            let n = 1 + below(rng, 16);
            let bytes: Vec<u8> = (0..n).map(|_| rng.next_u32() as u8).collect();
            v.splice(at..at, bytes);
        }
        7 | 8 => {
            if !replace_number(v, rng) {
                v[at] ^= 1 << below(rng, 8);
            }
        }
        9 => line_edit(v, rng),
        10 => {
            if let Some(other) = others.get(below(rng, others.len().max(1))).filter(|o| !o.is_empty()) {
                let from = below(rng, other.len());
                let n = 1 + below(rng, 512.min(other.len() - from));
                let end = (at + below(rng, 512)).min(len);
                v.splice(at..end, other[from..from + n].iter().copied());
            }
        }
        11 => {
            if len >= 4 {
                let at = below(rng, len - 3);
                let w = WORDS[below(rng, WORDS.len())];
                let bytes = if below(rng, 2) == 0 { w.to_le_bytes() } else { w.to_be_bytes() };
                v[at..at + 4].copy_from_slice(&bytes);
            }
        }
        _ => {
            // A number's digits changed in place (a count one off, say).
            if let Some((s, e)) = pick_number(v, rng) {
                let d = s + below(rng, e - s);
                if v[d].is_ascii_digit() {
                    v[d] = b'0' + below(rng, 10) as u8;
                }
            }
        }
    }
}

/// The byte ranges of the numbers in `v` (digits with sign, point and
/// exponent), or of some of them when there are many.
fn pick_number(v: &[u8], rng: &mut Rng) -> Option<(usize, usize)> {
    // Look around a random place first: files are long, numbers everywhere.
    let start = below(rng, v.len());
    let is_num = |b: u8| b.is_ascii_digit() || matches!(b, b'-' | b'+' | b'.' | b'e' | b'E');
    let found = (start..v.len()).chain(0..start).find(|&i| v[i].is_ascii_digit())?;
    let mut s = found;
    while s > 0 && is_num(v[s - 1]) {
        s -= 1;
    }
    let mut e = found;
    while e < v.len() && is_num(v[e]) {
        e += 1;
    }
    Some((s, e))
}

fn replace_number(v: &mut Vec<u8>, rng: &mut Rng) -> bool {
    match pick_number(v, rng) {
        Some((s, e)) => {
            let n = NUMBERS[below(rng, NUMBERS.len())];
            v.splice(s..e, n.bytes());
            true
        }
        None => false,
    }
}

/// Delete, repeat or swap lines.
fn line_edit(v: &mut Vec<u8>, rng: &mut Rng) {
    let mut starts: Vec<usize> = vec![0];
    starts.extend(v.iter().enumerate().filter(|(_, &b)| b == b'\n').map(|(i, _)| i + 1).filter(|&i| i < v.len()));
    let line = |k: usize, v: &Vec<u8>| (starts[k], starts.get(k + 1).copied().unwrap_or(v.len()));
    let (s, e) = line(below(rng, starts.len()), v);
    match below(rng, 3) {
        0 => {
            v.drain(s..e);
        }
        1 => {
            let piece = v[s..e].to_vec();
            v.splice(s..s, piece);
        }
        _ => {
            let (s2, e2) = line(below(rng, starts.len()), v);
            if e <= s2 {
                let (a, b) = (v[s..e].to_vec(), v[s2..e2].to_vec());
                v.splice(s2..e2, a);
                v.splice(s..e, b);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mutations_are_reproducible_and_change_the_input() {
        let seed = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n0 0 0\n1 0.5 -2e3\n".as_slice();
        let run = |case: u64| mutate(seed, &[seed], case % 2 == 0, &mut Rng::new(7, case));
        let changed = (0..500).filter(|&c| run(c) != seed).count();
        assert!(changed > 450, "only {changed} of 500 mutants differ from the seed");
        for c in 0..50 {
            assert_eq!(run(c), run(c), "case {c}");
        }
        // Every kind of mutation occurs: lengths go up and down, numbers become words.
        let mutants: Vec<Vec<u8>> = (0..2000).map(run).collect();
        assert!(mutants.iter().any(|m| m.len() > seed.len()) && mutants.iter().any(|m| m.len() < seed.len()));
        assert!(mutants.iter().any(|m| m.windows(3).any(|w| w == b"nan")));
        assert!(mutants.iter().any(|m| m.is_empty() || m.len() < 10));
        // Text mutations keep text text, nine times in ten or more.
        let text_ok = (0..2000).filter(|&c| std::str::from_utf8(&mutate(seed, &[seed], true, &mut Rng::new(3, c))).is_ok()).count();
        assert!(text_ok > 1800, "{text_ok} of 2000 text mutants are UTF-8");
    }
}
