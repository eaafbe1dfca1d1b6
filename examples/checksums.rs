//! What a partial's checksum costs: XXH3-128 (the one partials use) and
//! SHA-256 over the pixel records of a 1920×1080 partial (307 MB), best of
//! 7 passes, and the same through `pathtracer verify` on real partials is
//! in `scripts/measure-partials.sh`.
//!
//! ```sh
//! cargo run --release --example checksums
//! ```

use sha2::Digest;
use std::time::Instant;

fn best(mut f: impl FnMut() -> u64) -> f64 {
    let mut best = f64::MAX;
    let mut sink = 0u64;
    for _ in 0..7 {
        let t = Instant::now();
        sink ^= f();
        best = best.min(t.elapsed().as_secs_f64());
    }
    std::hint::black_box(sink);
    best
}

fn main() {
    let bytes = 1920 * 1080 * pathtracer::render::sums::PixelSums::BYTES;
    // Record-like bytes: pseudo-random, as sums are.
    let data: Vec<u8> = (0..bytes as u64).map(|i| (pathtracer::rng::mix64(i) >> 56) as u8).collect();
    let mb = bytes as f64 / 1e6;
    let cpu = std::fs::read_to_string("/proc/cpuinfo").ok().and_then(|t| t.lines().find(|l| l.starts_with("model name")).map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())).unwrap_or_default();
    println!("{mb:.1} MB of records (1920x1080 x {} B), one thread, {cpu}\n", pathtracer::render::sums::PixelSums::BYTES);
    println!("| checksum | ms | GB/s |\n|---|---:|---:|");
    let rows: [(&str, Box<dyn FnMut() -> u64>); 2] = [
        ("XXH3-128 (partials)", Box::new(|| xxhash_rust::xxh3::xxh3_128(&data) as u64)),
        ("SHA-256", Box::new(|| sha2::Sha256::digest(&data)[0] as u64)),
    ];
    for (name, f) in rows {
        let t = best(f);
        println!("| {name} | {:.1} | {:.2} |", t * 1e3, mb / t / 1e3);
    }
}
