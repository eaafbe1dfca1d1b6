//! Deterministic random numbers: PCG32 streams for tests, benchmarks and
//! tabulation (renders draw through `sampler`), and `mix64`, the hash the
//! samplers are built on.

/// PCG32 (O'Neill, XSH-RR 64/32).
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
    inc: u64,
}

const MULT: u64 = 6364136223846793005;

/// SplitMix64 finaliser: a good 64-bit mix for deriving stream seeds.
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E3779B97F4A7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
    z ^ (z >> 31)
}

impl Rng {
    pub fn new(seed: u64, stream: u64) -> Self {
        let mut r = Rng { state: 0, inc: (mix64(stream ^ 0x5851F42D4C957F2D) << 1) | 1 };
        r.next_u32();
        r.state = r.state.wrapping_add(mix64(seed));
        r.next_u32();
        r
    }

    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(MULT).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Uniform in [0, 1): 24 random bits, so 1.0 is never returned.
    #[inline]
    pub fn uniform(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }

    #[inline]
    pub fn uniform2(&mut self) -> (f32, f32) {
        (self.uniform(), self.uniform())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_differ_and_repeat() {
        let a: Vec<u32> = (0..4).map({ let mut r = Rng::new(1, 23); move |_| r.next_u32() }).collect();
        let b: Vec<u32> = (0..4).map({ let mut r = Rng::new(1, 23); move |_| r.next_u32() }).collect();
        let c: Vec<u32> = (0..4).map({ let mut r = Rng::new(1, 32); move |_| r.next_u32() }).collect();
        assert_eq!(a, b);
        assert_ne!(a, c);
        let d: Vec<u32> = (0..4).map({ let mut r = Rng::new(2, 23); move |_| r.next_u32() }).collect();
        let e: Vec<u32> = (0..4).map({ let mut r = Rng::new(1, 24); move |_| r.next_u32() }).collect();
        assert_ne!(d, a);
        assert_ne!(e, a);
    }

    #[test]
    fn uniform_mean_is_half() {
        let mut r = Rng::new(7, 0);
        let n = 100_000;
        let mean: f64 = (0..n).map(|_| r.uniform() as f64).sum::<f64>() / n as f64;
        // sd of the mean is sqrt(1/12/n) = 0.00091; 5 sd.
        assert!((mean - 0.5).abs() < 0.0046, "{mean}");
    }
}
