"""Error measures and error-against-time curves: a reference from independent renders,
relMSE, mean FLIP, and the relMSE ratio at equal render time."""
import numpy as np

from images import to_png


def from_renders(imgs, meta):
    """A reference from its independent renders: their mean, the per-pixel variance of that
    mean, each render's image mean (for the global test), the renders and their total time."""
    stack = np.stack(imgs)
    return {"mean": stack.mean(axis=0), "var": stack.var(axis=0, ddof=1) / len(imgs), "image_means": [float(i.mean()) for i in imgs],
            "renders": imgs, "seconds": sum(p["seconds"] for p in meta["renders"])}


def rel_mse(x, r):
    return float(np.mean((x - r) ** 2 / (r * r + 1e-2)))


def interp_loglog(points, y):
    """x at which the piecewise log-log line through (y_i, x_i), sorted by y, reaches y; None
    outside the range (segments with a value <= 0 are skipped)."""
    pts = sorted(points)
    for (y0, x0), (y1, x1) in zip(pts, pts[1:]):
        if y0 <= y <= y1 and y1 > y0 > 0 and x0 > 0 and x1 > 0:
            a = (np.log(y) - np.log(y0)) / (np.log(y1) - np.log(y0))
            return float(np.exp(np.log(x0) + a * (np.log(x1) - np.log(x0))))
    return None


def flip_error(x, r):
    """Mean FLIP (NVIDIA's flip-evaluator, LDR mode) between the CS184 tone-mapped images; None
    when the package is missing."""
    try:
        import flip_evaluator as flip
    except ImportError:
        return None
    a = to_png(x).astype(np.float32)
    b = to_png(r).astype(np.float32)
    _, mean, _ = flip.evaluate(b, a, "LDR")
    return float(mean)


def fixed_cost_fit(points):
    """Least-squares line seconds = fixed + per_spp·spp through (spp, seconds) points.
    `fixed` is what a render costs whatever its length (threads, buffers, Blender's scene
    sync, kernel set-up); `per_spp` the cost of one more sample per pixel."""
    n = np.array([p[0] for p in points], dtype=np.float64)
    t = np.array([p[1] for p in points], dtype=np.float64)
    if len(set(n.tolist())) < 2:
        return 0.0, float(np.max(t / n))
    b, a = np.polyfit(n, t, 1)
    if not b > 0:
        # Timing noise larger than the rendering: the longest rung alone.
        return 0.0, float(t[np.argmax(n)] / n[np.argmax(n)])
    return float(a), float(b)


def ladder_curve(runs, ref_mean):
    """The error-against-time curve of one renderer from its ladder runs [(spp, seconds,
    image)], several independent renders (seeds) per spp.

    Error: the expected relMSE of one render at that spp, sum over pixels of the variance
    across the independent renders / (reference² + 0.01). It is the variance part of the
    relMSE only — an unbiased renderer's whole relMSE, and free of the reference's own noise
    and of any systematic difference between the renderers (the verdicts test those).

    Time: the median of the rung's timings, then fixed costs taken out the same way for
    every renderer: a line fixed + per_spp·spp through the medians, and the curve's time
    is per_spp·spp (the rung's median is kept as `median_seconds`)."""
    if not runs:
        return {"curve": [], "fit": None}
    by = {}
    for n, sec, img in runs:
        by.setdefault(n, []).append((sec, img))
    med = {n: float(np.median([s for s, _ in v])) for n, v in by.items()}
    fixed, per_spp = fixed_cost_fit(sorted(med.items()))
    denom = ref_mean * ref_mean + 1e-2
    curve = []
    for n in sorted(by):
        imgs = np.stack([img for _, img in by[n]])
        if len(imgs) < 2:
            continue
        rel_var = float(np.mean(imgs.var(axis=0, ddof=1) / denom))
        curve.append({"spp": n, "seconds": per_spp * n, "median_seconds": med[n], "timings": [s for s, _ in by[n]], "renders": len(imgs), "rel_mse": rel_var})
    return {"curve": curve, "fit": {"fixed_seconds": fixed, "seconds_per_spp": per_spp}}


def equal_time_ratio(ours, theirs):
    """relMSE(ours) / relMSE(theirs) at equal render time: both curves interpolated
    log-log at the geometric mean of the overlapping time range. None without overlap."""
    def at(curve, t):
        return interp_loglog([(p["seconds"], p["rel_mse"]) for p in curve], t)
    if not ours or not theirs:
        return None
    lo = max(min(p["seconds"] for p in ours), min(p["seconds"] for p in theirs))
    hi = min(max(p["seconds"] for p in ours), max(p["seconds"] for p in theirs))
    if not (hi > lo > 0):
        return None
    t = float(np.sqrt(lo * hi))
    a, b = at(ours, t), at(theirs, t)
    return {"seconds": t, "ratio": a / b} if a and b else None
