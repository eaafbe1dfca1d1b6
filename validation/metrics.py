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
