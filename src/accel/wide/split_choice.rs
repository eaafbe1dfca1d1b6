//! Whether a scene's tree gets spatial splits (`bvh::spatial`), decided
//! when it is built, per scene and deterministically (`Splits::Auto`, the
//! default): from counted work, never from timings, so the same scene and
//! ray count always give the same tree.
//!
//! Spatial splits cost a second build, 4-10x the first, and gain little
//! on most scenes, losing on some: the SAH estimate cannot tell which (it
//! fell most on CBbunny and grass, whose rays got slower). So the rule is:
//!
//! 1. **Could it pay?** The second build is tried only where the rays the
//!    caller expects to trace, at the sampled work per ray of the tree
//!    without splits, would save more than the build costs if the splits
//!    cut the work by `MIN_GAIN` (`BUILD_WORK_PER_PRIM` converts the build
//!    into traversal work). A render knows its rays (pixels × samples ×
//!    bounces); a caller that gives none (0) gets no second build. Where
//!    even `SAH_MARGIN` times the tree's SAH cost a ray could not repay it
//!    (most 1M+ scenes), this is decided without the sample.
//! 2. **Does it?** Both trees trace the same sample of the plain tree's own
//!    rays (`sample`: diffuse-like closest hits and shadow-like any hits),
//!    counting nodes and triangle groups; the split tree is kept only where
//!    its work is below `1 - MIN_GAIN` of the plain tree's.
//!
//! The summary line and the benchmark's table say which happened and why
//! (`SplitOutcome::describe`).

use super::sample::Work;

/// Spatial splits are kept only where they cut the sampled work by this
/// fraction. Sampled work with a budget of 0.3 against none (4096 rays):
/// beetle −4.5 %, grass:500k −3.7 %, maxplanck −2.7 %, cow −2.4 %,
/// subdivided bunny −0.4 %, CBbunny 0.0 %, arch:500k −0.5 %,
/// stadium:500k +5.8 %. Speed did not follow the counts far enough: grass's
/// random rays ran 10 % slower with splits (its tree grows by the
/// duplicated blades and misses the caches more), and beetle, the largest
/// count, rendered 1-3 % slower with them (480x360, 256 spp, `-m 5`, three
/// alternating runs: 5.22-5.43 s against 5.16-5.25 s) though its single
/// random rays had gained 4 %. So the margin is twice beetle's count: no
/// scene measured clears it, and a scene that does has a gain no
/// larger tree is likely to eat.
pub(super) const MIN_GAIN: f64 = 0.10;

/// The split build's extra cost in units of traversal work (a node visit
/// or a triangle group test) per primitive: up to about 10 µs of one
/// thread per primitive (grass:500k 7.5, the subdivided bunny 500k 10.8,
/// CBbunny 0.8), against about 20 ns per unit of work (single rays on a
/// 2-vCPU AMD EPYC: 15-20 ns on the small scanned meshes, 50 on the 500k
/// scenes, whose trees miss the caches). Both sides are of one machine, so
/// their ratio carries to others.
pub(super) const BUILD_WORK_PER_PRIM: f64 = 500.0;

/// What the build did about spatial splits, for the summary line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SplitOutcome {
    /// The options fixed a budget (`Splits::Budget`).
    Asked { budget: f64 },
    /// Not tried: the expected rays could not repay the second build.
    NotTried { expected_rays: u64, needed_rays: u64 },
    /// Tried and left out: the work ratio (split ÷ plain) was too high.
    Rejected { ratio: f64 },
    /// Tried and kept.
    Kept { ratio: f64 },
}

impl SplitOutcome {
    /// Whether the tree has spatial splits.
    pub fn split(&self) -> bool {
        match *self {
            SplitOutcome::Asked { budget } => budget > 0.0,
            SplitOutcome::Kept { .. } => true,
            _ => false,
        }
    }

    /// The words for the summary line: "spatial splits kept (sampled work
    /// −12.0 %)", "no spatial splits (tried: sampled work −2.4 %; kept only
    /// below −10 %)".
    pub fn describe(&self) -> String {
        let pct = |r: f64| format!("{:+.1} %", (r - 1.0) * 100.0).replace('-', "−");
        match *self {
            SplitOutcome::Asked { budget } if budget > 0.0 => format!("spatial splits (budget {budget} asked)"),
            SplitOutcome::Asked { .. } => "no spatial splits (asked)".to_string(),
            SplitOutcome::NotTried { expected_rays: 0, .. } => "no spatial splits (not tried: no ray count given)".to_string(),
            SplitOutcome::NotTried { expected_rays, needed_rays } => {
                format!("no spatial splits (not tried: {} rays expected, {} would repay the build)", count(expected_rays), count(needed_rays))
            }
            SplitOutcome::Rejected { ratio } => format!("no spatial splits (tried: sampled work {}; kept only below −{:.0} %)", pct(ratio), MIN_GAIN * 100.0),
            SplitOutcome::Kept { ratio } => format!("spatial splits (sampled work {})", pct(ratio)),
        }
    }
}

/// How far a sampled ray's work may exceed the tree's SAH cost before step 1
/// is decided without the sample (`beyond_reach`). Sampled work per ray ÷
/// SAH cost on the 20 shipped scenes and the 7 generated bench scenes:
/// 0.83 (CBgems) to 1.51 (beetle); the margin is twice the largest.
pub(super) const SAH_MARGIN: f64 = 3.0;

/// Step 1: the rays it takes to repay the second build at `plain`'s
/// sampled work over `prims` primitives, if the splits saved `MIN_GAIN` of
/// it (one ray: half a closest hit and half an any hit, `Work::total` / 2).
pub(super) fn rays_to_repay(plain: &Work, prims: usize) -> u64 {
    rays_at(plain.total() / 2.0, prims)
}

/// The rays that repay the second build at `per_ray` units of work a ray.
fn rays_at(per_ray: f64, prims: usize) -> u64 {
    (BUILD_WORK_PER_PRIM * prims as f64 / (per_ray.max(1.0) * MIN_GAIN)).ceil() as u64
}

/// Step 1 before any sample, from the tree's SAH cost `sah` (expected work
/// of a ray through the root's box, which costs nothing to read): the rays
/// that would repay the second build, where `expected_rays` could not
/// repay it even at `SAH_MARGIN` times that work a ray; `None` where the
/// sample must decide. On the large scenes this skips the sample (4096 rays
/// of each kind, and a pass over every triangle to spread them: about
/// 20 ms of a 1M-triangle build on 2 threads).
pub(super) fn beyond_reach(sah: f64, prims: usize, expected_rays: u64) -> Option<u64> {
    let at_most = rays_at(sah * SAH_MARGIN, prims);
    (expected_rays < at_most).then(|| rays_at(sah, prims))
}

/// Step 2: the outcome for the two trees' sampled work.
pub(super) fn judge(plain: &Work, split: &Work) -> SplitOutcome {
    let ratio = if plain.total() > 0.0 { split.total() / plain.total() } else { 1.0 };
    if ratio < 1.0 - MIN_GAIN {
        SplitOutcome::Kept { ratio }
    } else {
        SplitOutcome::Rejected { ratio }
    }
}

/// 1234567 as "1.2M".
fn count(n: u64) -> String {
    match n {
        0..1_000 => n.to_string(),
        1_000..1_000_000 => format!("{:.1}k", n as f64 / 1e3),
        1_000_000..1_000_000_000 => format!("{:.1}M", n as f64 / 1e6),
        _ => format!("{:.1}G", n as f64 / 1e9),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rule_keeps_only_gains_past_the_margin_and_says_so() {
        let plain = Work { closest: 10.0, any: 10.0 };
        assert_eq!(judge(&plain, &Work { closest: 8.5, any: 8.5 }), SplitOutcome::Kept { ratio: 0.85 });
        assert!(matches!(judge(&plain, &Work { closest: 9.5, any: 9.5 }), SplitOutcome::Rejected { .. }));
        assert!(matches!(judge(&plain, &Work { closest: 11.0, any: 11.0 }), SplitOutcome::Rejected { .. }));
        // 500 units a primitive over a saving of 10 % of 10 units a ray.
        assert_eq!(rays_to_repay(&plain, 1000), 500_000);
        assert_eq!(SplitOutcome::Kept { ratio: 0.954 }.describe(), "spatial splits (sampled work −4.6 %)");
        assert_eq!(SplitOutcome::Rejected { ratio: 1.027 }.describe(), "no spatial splits (tried: sampled work +2.7 %; kept only below −10 %)");
        assert_eq!(SplitOutcome::NotTried { expected_rays: 2_500_000, needed_rays: 61_000_000 }.describe(), "no spatial splits (not tried: 2.5M rays expected, 61.0M would repay the build)");
        assert!(!SplitOutcome::Asked { budget: 0.0 }.split() && SplitOutcome::Asked { budget: 0.3 }.split());
    }

    #[test]
    fn the_sah_decides_alone_only_far_from_the_line() {
        // 1000 primitives at SAH cost 10: 500k rays repay at that work a ray,
        // 166,667 at three times it.
        assert_eq!(beyond_reach(10.0, 1000, 100_000), Some(500_000));
        assert_eq!(beyond_reach(10.0, 1000, 166_666), Some(500_000));
        assert_eq!(beyond_reach(10.0, 1000, 166_667), None);
        assert_eq!(beyond_reach(10.0, 1000, 10_000_000), None);
    }
}
