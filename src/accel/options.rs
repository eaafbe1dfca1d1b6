//! The choices a backend's build fixes, passed in through
//! [`accel::build_with`](super::build_with) instead of being read from the
//! environment inside the kernels. The application reads the
//! `PATHTRACER_NATIVE_*` switches once and passes them
//! ([`BuildOptions::from_lookup`]); the library's users and the tests pass
//! what they want.

use crate::error::{Error, Result};

/// Which instruction set native traversal runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum NativeIsa {
    /// AVX2 where the CPU has it, else SSE2; single rays' walks compiled
    /// with AVX-512VL as well where the CPU has it (the default).
    #[default]
    Auto,
    /// SSE2 even where AVX2 runs (A/B comparisons; same answers).
    Sse2,
    /// AVX2 without AVX-512VL even where the CPU has it (A/B comparisons;
    /// same answers).
    Avx2,
    /// AVX2 with the AVX-512 packet kernels, where the CPU has AVX-512F
    /// (not the default, by measurement: level on a Zen 5, 30 % slower
    /// camera rays on a Xeon; see `wide`).
    Avx512Packets,
}

/// How native traces coherent shadow batches.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ShadowWay {
    /// Streams on trees whose rays miss the caches, packets elsewhere,
    /// decided when the tree is built (the default; see `wide::stream`).
    #[default]
    Auto,
    /// Always packets.
    Packets,
    /// Always streams.
    Streams,
}

/// How native traces incoherent closest-hit batches (`intersect_batch`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum BatchWay {
    /// Per batch, from the batch itself: streams where its rays start close
    /// together, else interleaved single rays on trees whose rays miss the
    /// caches, else single rays (the default; see `wide::stream_choice`).
    #[default]
    Auto,
    /// One ray at a time.
    Single,
    /// Interleaved single rays (`wide::interleave`).
    Interleaved,
    /// Streams (`wide::hit_stream`).
    Streams,
}

/// Whether the native build uses spatial splits (`bvh::spatial`).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub enum Splits {
    /// Decided per scene (the default): tried only where the rays the
    /// caller expects to trace (`NativeOptions::expected_rays`) could repay
    /// the second build, kept only where they cut the tree's counted work
    /// on its own sample of rays (see `wide::split_choice`).
    #[default]
    Auto,
    /// Spatial splits may add this many references per primitive (0: none;
    /// at most 4), whatever they gain.
    Budget(f64),
}

/// The native backend's build choices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NativeOptions {
    pub isa: NativeIsa,
    pub splits: Splits,
    /// Rays the caller expects to trace through the tree (0: unknown), from
    /// which `Splits::Auto` judges whether a second build could pay.
    pub expected_rays: u64,
    pub shadow: ShadowWay,
    pub batch: BatchWay,
}

impl Default for NativeOptions {
    fn default() -> Self {
        NativeOptions { isa: NativeIsa::Auto, splits: Splits::Auto, expected_rays: 0, shadow: ShadowWay::Auto, batch: BatchWay::Auto }
    }
}

impl NativeOptions {
    /// From the values `lookup` gives `PATHTRACER_NATIVE_ISA` (`sse`,
    /// `avx512`), `PATHTRACER_NATIVE_SPLITS` (a number from 0 to 4),
    /// `PATHTRACER_NATIVE_SHADOW` (`packets`, `streams`, `auto`) and
    /// `PATHTRACER_NATIVE_BATCH` (`single`, `interleaved`, `streams`,
    /// `auto`); a value outside these is refused, naming the switch. The
    /// application passes the environment's (`app::environment`).
    pub fn from_lookup(lookup: impl Fn(&str) -> Option<String>) -> Result<NativeOptions> {
        let var = |k: &str| lookup(k).filter(|v| !v.is_empty());
        let mut o = NativeOptions::default();
        if let Some(v) = var("PATHTRACER_NATIVE_ISA") {
            o.isa = match v.as_str() {
                "sse" | "sse2" => NativeIsa::Sse2,
                "avx2" => NativeIsa::Avx2,
                "avx512" => NativeIsa::Avx512Packets,
                "auto" => NativeIsa::Auto,
                _ => return Err(Error::new(format!("PATHTRACER_NATIVE_ISA={v}: expected auto, sse, avx2 or avx512"))),
            };
        }
        if let Some(v) = var("PATHTRACER_NATIVE_SPLITS") {
            o.splits = match v.parse::<f64>() {
                _ if v == "auto" => Splits::Auto,
                Ok(b) if (0.0..=4.0).contains(&b) => Splits::Budget(b),
                _ => return Err(Error::new(format!("PATHTRACER_NATIVE_SPLITS={v}: expected auto or a number from 0 to 4"))),
            };
        }
        if let Some(v) = var("PATHTRACER_NATIVE_SHADOW") {
            o.shadow = match v.as_str() {
                "packets" => ShadowWay::Packets,
                "streams" => ShadowWay::Streams,
                "auto" => ShadowWay::Auto,
                _ => return Err(Error::new(format!("PATHTRACER_NATIVE_SHADOW={v}: expected packets, streams or auto"))),
            };
        }
        if let Some(v) = var("PATHTRACER_NATIVE_BATCH") {
            o.batch = match v.as_str() {
                "single" => BatchWay::Single,
                "interleaved" => BatchWay::Interleaved,
                "streams" => BatchWay::Streams,
                "auto" => BatchWay::Auto,
                _ => return Err(Error::new(format!("PATHTRACER_NATIVE_BATCH={v}: expected single, interleaved, streams or auto"))),
            };
        }
        Ok(o)
    }
}

/// Everything a build takes besides the backend and the shapes.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct BuildOptions {
    /// Threads of any pool the backend owns (Embree's TBB); 0: all cores.
    pub threads: usize,
    pub native: NativeOptions,
    /// Appended to every Embree device's configuration (for measurements:
    /// "verbose=2" prints its BVH statistics); empty by default.
    pub embree_config: String,
}

impl BuildOptions {
    /// The build options the environment asks for: the
    /// `PATHTRACER_NATIVE_*` switches and `PATHTRACER_EMBREE_CONFIG`, read
    /// once by the application and passed in.
    pub fn from_lookup(threads: usize, lookup: impl Fn(&str) -> Option<String>) -> Result<BuildOptions> {
        let native = NativeOptions::from_lookup(&lookup)?;
        Ok(BuildOptions { threads, native, embree_config: lookup("PATHTRACER_EMBREE_CONFIG").unwrap_or_default() })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(pairs: &[(&str, &str)]) -> Result<NativeOptions> {
        NativeOptions::from_lookup(|k| pairs.iter().find(|(kk, _)| *kk == k).map(|(_, v)| v.to_string()))
    }

    #[test]
    fn switches_parse_and_bad_values_are_refused_by_name() {
        assert_eq!(parse(&[]).unwrap(), NativeOptions::default());
        let o = parse(&[("PATHTRACER_NATIVE_ISA", "sse"), ("PATHTRACER_NATIVE_SPLITS", "0.3"), ("PATHTRACER_NATIVE_SHADOW", "streams")]).unwrap();
        assert_eq!((o.isa, o.splits, o.shadow), (NativeIsa::Sse2, Splits::Budget(0.3), ShadowWay::Streams));
        assert_eq!(parse(&[("PATHTRACER_NATIVE_SPLITS", "auto")]).unwrap().splits, Splits::Auto);
        assert_eq!(parse(&[("PATHTRACER_NATIVE_ISA", "avx512")]).unwrap().isa, NativeIsa::Avx512Packets);
        assert_eq!(parse(&[("PATHTRACER_NATIVE_ISA", "avx2")]).unwrap().isa, NativeIsa::Avx2);
        assert_eq!(parse(&[("PATHTRACER_NATIVE_ISA", "auto")]).unwrap().isa, NativeIsa::Auto);
        assert_eq!(parse(&[("PATHTRACER_NATIVE_BATCH", "streams")]).unwrap().batch, BatchWay::Streams);
        for (k, v) in [("PATHTRACER_NATIVE_BATCH", "sorted"), ("PATHTRACER_NATIVE_ISA", "neon"), ("PATHTRACER_NATIVE_SPLITS", "5"), ("PATHTRACER_NATIVE_SPLITS", "nan"), ("PATHTRACER_NATIVE_SHADOW", "both")] {
            let e = parse(&[(k, v)]).unwrap_err().0;
            assert!(e.starts_with(&format!("{k}={v}: expected")), "{e}");
        }
    }
}
