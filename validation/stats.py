"""Statistical verdicts for an image against a reference (docs/validation/README.md, Verdicts).

* Per pixel-channel Welch z: z = (x - r) / sqrt(var_x + var_r), both variances of the mean.
  Family-wise alpha 0.01, Šidák-corrected over all pixel-channels; the image passes when at
  least 99.75 % of pixel-channels pass (Mitsuba's rule).
* Global mean test, by batch means: both images are averages of independent renders (ours 8,
  the reference's 16); the difference of the image means is divided by the standard error
  estimated from the spread of those renders' image means, and compared with Student's t
  at alpha = 0.01 and the smaller side's degrees of freedom. It catches a uniform bias of a
  fraction of a percent. Per-pixel variances are not used for it: path-tracing samples are
  right-skewed (fireflies next to a point light), so a pixel's sample variance is usually too
  small exactly when its mean is too low; the sum of per-pixel z over sqrt(N), reported as
  `summed_pixel_z`, drifts negative on a correct renderer. The spread of whole-render means
  sees the fireflies that happened.
* Where both variances are 0 (black background, directly seen emitters) the values must match
  to 1e-5 relative.
* Region means (a 4 x 3 grid) with 95 % confidence intervals, relMSE (eps 0.01) and SMAPE,
  for the report.
"""
import math
from statistics import NormalDist

import numpy as np

ALPHA = 0.01
PASS_FRACTION = 0.9975


# Two-sided Student t critical values at alpha = 0.01 by degrees of freedom.
T_CRIT_001 = {3: 5.841, 4: 4.604, 5: 4.032, 6: 3.707, 7: 3.499, 8: 3.355, 9: 3.250, 10: 3.169, 11: 3.106, 12: 3.055, 13: 3.012, 14: 2.977, 15: 2.947}


def _beta_fraction(a, b, x):
    """Continued fraction of the regularised incomplete beta function (modified Lentz)."""
    tiny, eps = 1e-300, 1e-15
    c, d = 1.0, 1.0 - (a + b) * x / (a + 1.0)
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 400):
        for aa in (m * (b - m) * x / ((a - 1.0 + 2 * m) * (a + 2 * m)), -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 1.0 + 2 * m))):
            d = 1.0 + aa * d
            d = 1.0 / (d if abs(d) > tiny else tiny)
            c = 1.0 + aa / c
            c = c if abs(c) > tiny else tiny
            h *= d * c
        if abs(d * c - 1.0) < eps:
            break
    return h


def beta_regularised(a, b, x):
    """I_x(a, b)."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    front = math.exp(math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x))
    if x < (a + 1.0) / (a + b + 2.0):
        return front * _beta_fraction(a, b, x) / a
    return 1.0 - front * _beta_fraction(b, a, 1.0 - x) / b


def t_two_sided_p(t, dof):
    """P(|T| >= |t|) for Student's t with `dof` degrees of freedom."""
    return beta_regularised(dof / 2.0, 0.5, dof / (dof + t * t))


def welch_ok(diff, var_x, dof_x, var_r, dof_r, n_tests):
    """Per-element Welch test at family-wise ALPHA (Šidák over `n_tests`): True where the
    difference is consistent with 0. Each variance of the mean comes with its degrees of
    freedom (a reference's 8 renders give 7), combined by Welch-Satterthwaite, and the
    difference is judged against Student's t with them, not the normal distribution: with few
    renders the normal's tails pass too little (simulated, 471 tests, 8 reference renders whose
    variance is 20x ours: 37 % of runs failed the 99.75 % rule with the normal, none with t). Elements with |z| within the normal's
    critical value pass under any t, so only the others are computed exactly."""
    diff, var_x, var_r = (np.asarray(a, dtype=np.float64) for a in (diff, var_x, var_r))
    var = var_x + var_r
    z = np.abs(diff) / np.sqrt(np.maximum(var, 1e-300))
    ok = z <= z_critical(n_tests)
    alpha_pix = 1.0 - (1.0 - ALPHA) ** (1.0 / max(n_tests, 1))
    for i in zip(*np.nonzero(~ok)):
        vx, vr = float(var_x[i]), float(var_r[i])
        den = (vx * vx / dof_x if dof_x else 0.0) + (vr * vr / dof_r if dof_r else 0.0)
        if var[i] <= 0 or den <= 0:
            continue
        ok[i] = t_two_sided_p(float(z[i]), (vx + vr) ** 2 / den) >= alpha_pix
    return ok


def z_critical(n):
    """Two-sided critical |z| for n tests at family-wise alpha ALPHA (Šidák)."""
    alpha_pix = 1.0 - (1.0 - ALPHA) ** (1.0 / max(n, 1))
    return NormalDist().inv_cdf(1.0 - alpha_pix / 2.0)


def region_means(x, var_x, r, var_r, xs=None, rs=None, cols=4, rows=3):
    """Means of a cols x rows grid of image regions (channels averaged), ours and the
    reference's, each with a 95 % confidence half-width, and the z of their difference. The
    standard error comes from the spread of the independent renders' region means where the
    renders are given (`xs`, `rs`: POV-Ray's lightlet jitter is shared by all pixels of a
    render, so its pixel errors are correlated), else from the summed per-pixel variances of
    the mean (pixels sampled independently, as Mitsuba's are)."""
    h, w = x.shape[:2]
    out = []

    def se_of(img_var, renders, sl):
        if renders is not None and len(renders) > 1:
            m = np.array([float(a[sl].mean()) for a in renders])
            return float(m.std(ddof=1) / np.sqrt(m.size))
        v = img_var[sl]
        return float(np.sqrt(v.sum()) / v.size)

    for j in range(rows):
        for i in range(cols):
            y0, y1, x0, x1 = j * h // rows, (j + 1) * h // rows, i * w // cols, (i + 1) * w // cols
            sl = (slice(y0, y1), slice(x0, x1))
            m, mr = float(x[sl].mean()), float(r[sl].mean())
            se, ser = se_of(var_x, xs, sl), se_of(var_r, rs, sl)
            se_d = float(np.hypot(se, ser))
            out.append({"region": [x0, y0, x1, y1], "mean": m, "ci95": 1.96 * se, "reference_mean": mr, "reference_ci95": 1.96 * ser,
                        "z": (m - mr) / se_d if se_d > 0 else (0.0 if m == mr else float("inf"))})
    return out


def verdict(x, var_x, r, var_r, batch_means_x, batch_means_r, spp=None, max_sample=None, renders_x=None, renders_r=None):
    """`max_sample`, when the estimator's largest single-sample value is known (uniform
    hemisphere sampling at -m 1: 2·albedo·radiance), decides pixels where none of our `spp`
    samples was non-zero: their sample variance is 0, which is no evidence of precision. Such a
    pixel is consistent with a reference mean r when a hit probability p <= -ln(alpha_pix)/spp
    (P(no hit in spp samples) >= alpha_pix) times max_sample reaches r."""
    x, var_x, r, var_r = (np.asarray(a, dtype=np.float64) for a in (x, var_x, r, var_r))
    n = x.size
    z_pix = z_critical(n)
    alpha_pix = 1.0 - (1.0 - ALPHA) ** (1.0 / n)
    var = var_x + var_r
    noisy = var > 0
    z = np.zeros_like(x)
    z[noisy] = (x[noisy] - r[noisy]) / np.sqrt(var[noisy])
    exact_ok = np.abs(x - r) <= 1e-5 * np.maximum(np.abs(r), 1e-6)
    ok = np.where(noisy, np.abs(z) <= z_pix, exact_ok)
    unobserved = (x == 0) & (var_x == 0) & (r > 0)
    if max_sample is not None and spp:
        bound = max_sample * -np.log(alpha_pix) / spp
        ok = np.where(unobserved, r <= bound, ok)
    frac = float(ok.mean())
    z_sum = float(z[noisy].sum() / np.sqrt(max(noisy.sum(), 1)))
    bx, br = np.asarray(batch_means_x, dtype=np.float64), np.asarray(batch_means_r, dtype=np.float64)
    se_glob = float(np.sqrt(bx.var(ddof=1) / bx.size + br.var(ddof=1) / br.size))
    z_glob = float((bx.mean() - br.mean()) / se_glob) if se_glob > 0 else (0.0 if bx.mean() == br.mean() else float("inf"))
    z_glob_crit = T_CRIT_001[min(bx.size, br.size) - 1]
    rel_mse = float(np.mean((x - r) ** 2 / (r * r + 1e-2)))
    denom = np.abs(x) + np.abs(r)
    smape = float(np.mean(np.where(denom > 0, 2 * np.abs(x - r) / np.where(denom > 0, denom, 1), 0)))
    mean_x, mean_r = float(x.mean()), float(r.mean())
    se_mean = se_glob
    return {
        "pixel_channels": int(n),
        "pixel_channels_without_samples": int(unobserved.sum()),
        "alpha": ALPHA,
        "z_pixel_critical": z_pix,
        "pass_fraction": frac,
        "pixel_test_passed": frac >= PASS_FRACTION,
        "global_z": z_glob,
        "summed_pixel_z": z_sum,
        "global_z_critical": z_glob_crit,
        "global_test_passed": abs(z_glob) <= z_glob_crit,
        "mean": mean_x,
        "reference_mean": mean_r,
        "relative_mean_difference": (mean_x - mean_r) / mean_r if mean_r else None,
        "se_of_mean_difference": se_mean,
        "rel_mse": rel_mse,
        "smape": smape,
        "passed": bool(frac >= PASS_FRACTION and abs(z_glob) <= z_glob_crit),
        "regions": region_means(x, var_x, r, var_r, renders_x, renders_r),
        "z_image": z,
    }
