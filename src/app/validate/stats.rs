//! The tests `validate` decides by: Welch's t-test of two estimators' means
//! from independent replicates, a family of them held to one error rate by
//! Šidák's correction, and Student's quantiles for the confidence interval
//! of a difference (the equivalence test of `transport`).

use statrs::distribution::{ContinuousCDF, StudentsT};

/// The mean and the unbiased variance of `x`.
pub fn mean_var(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    let v = if x.len() > 1 { x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / (n - 1.0) } else { 0.0 };
    (m, v)
}

/// The replicate farthest from the mean of `x` and its share of the sum of
/// squared deviations: near 1 where one replicate holds a rare, very
/// bright sample (a heavy-tailed estimator), which widens the interval far
/// more than more samples of the usual kind would. With normal replicates
/// a share above 0.6 of 8 or more is rarer than one in 10^4.
pub fn lone_share(x: &[f64]) -> (usize, f64) {
    let (m, _) = mean_var(x);
    let dev: Vec<f64> = x.iter().map(|v| (v - m) * (v - m)).collect();
    let total: f64 = dev.iter().sum();
    let (k, top) = dev.iter().enumerate().fold((0, 0.0), |b, (i, &d)| if d > b.1 { (i, d) } else { b });
    (k, if total > 0.0 { top / total } else { 0.0 })
}

/// Welch's test of `a` against `b` (each a set of independent replicate
/// means).
#[derive(Clone, Copy, Debug)]
pub struct Welch {
    pub mean_a: f64,
    pub mean_b: f64,
    /// Standard error of the difference of the means.
    pub se: f64,
    /// Welch–Satterthwaite degrees of freedom.
    pub df: f64,
    pub t: f64,
    /// Two-sided p-value.
    pub p: f64,
}

pub fn welch(a: &[f64], b: &[f64]) -> Welch {
    let ((ma, va), (mb, vb)) = (mean_var(a), mean_var(b));
    let (sa, sb) = (va / a.len() as f64, vb / b.len() as f64);
    let se = (sa + sb).sqrt();
    let df = if sa + sb > 0.0 { (sa + sb) * (sa + sb) / (sa * sa / (a.len() as f64 - 1.0) + sb * sb / (b.len() as f64 - 1.0)) } else { (a.len() + b.len() - 2) as f64 };
    let (t, p) = if se > 0.0 {
        let t = (ma - mb) / se;
        (t, 2.0 * (1.0 - student(df).cdf(t.abs())))
    } else if ma == mb {
        (0.0, 1.0)
    } else {
        (f64::INFINITY, 0.0)
    };
    Welch { mean_a: ma, mean_b: mb, se, df, t, p }
}

fn student(df: f64) -> StudentsT {
    StudentsT::new(0.0, 1.0, df.max(1.0)).expect("positive degrees of freedom")
}

/// The per-test level that holds a family of `m` tests to `alpha` (Šidák).
pub fn sidak(alpha: f64, m: usize) -> f64 {
    1.0 - (1.0 - alpha).powf(1.0 / m.max(1) as f64)
}

/// The `q` quantile of Student's t with `df` degrees of freedom.
pub fn t_quantile(df: f64, q: f64) -> f64 {
    student(df).inverse_cdf(q)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn welch_finds_a_shift_and_passes_equal_means() {
        let a: Vec<f64> = (0..8).map(|i| 1.0 + 0.01 * (i as f64 - 3.5)).collect();
        let b: Vec<f64> = a.iter().map(|x| x + 0.2).collect();
        let w = welch(&a, &b);
        assert!(w.p < 1e-8 && (w.df - 14.0).abs() < 1e-9, "{w:?}");
        // A textbook value: t = 2.1448 with 14 degrees of freedom is p = 0.05.
        assert!((2.0 * (1.0 - student(14.0).cdf(2.1448)) - 0.05).abs() < 1e-4);
        let c: Vec<f64> = a.iter().rev().copied().collect();
        assert!(welch(&a, &c).p > 0.99);
        assert!((t_quantile(14.0, 0.975) - 2.1448).abs() < 1e-3);
        assert!((sidak(0.01, 1) - 0.01).abs() < 1e-12 && sidak(0.01, 10) < 0.0011);
    }

    #[test]
    fn lone_share_finds_one_bright_replicate() {
        // Spread evenly: no replicate dominates.
        let even: Vec<f64> = (0..15).map(|i| 1.0 + 0.01 * (i as f64 - 7.0)).collect();
        assert!(lone_share(&even).1 < 0.2, "{:?}", lone_share(&even));
        let mut bright = even.clone();
        bright[9] += 0.5;
        assert_eq!(lone_share(&bright).0, 9);
        assert!(lone_share(&bright).1 > 0.8, "{:?}", lone_share(&bright));
        assert_eq!(lone_share(&[2.0; 8]).1, 0.0);
    }
}
