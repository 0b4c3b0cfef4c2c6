"""Embree's time-versus-error curve and the read-off of its time at a given error.

A Monte-Carlo estimate's error falls as 1/sqrt(rays): beyond the ray counts that were run
(`extend`), Embree's curve continues by the law error = a / sqrt(rays), a fitted to the two
densest measured points, and its time grows linearly in rays through those two points. `time_at_error` interpolates the
curve log-log, so a hemishadow point's speed-up at equal error is time_at_error / its time.
"""

import math

import numpy as np


def fit_law(rays, errors):
    """a of error = a / sqrt(rays), least squares in log space; and the measured log-log slope."""
    r, e = np.log(np.asarray(rays, float)), np.log(np.asarray(errors, float))
    a = float(np.exp(np.mean(e + 0.5 * r)))
    slope = float(np.polyfit(r, e, 1)[0]) if len(r) >= 2 else float("nan")
    return a, slope


def extend(measured, ray_counts):
    """measured: [(rays, ms, error)] (at least two). Returns the curve [(rays, ms, error,
    'measured' | 'fitted')] over the measured ray counts and the larger ones of `ray_counts`:
    a measured point as it was, a larger ray count by the law (error a / sqrt(rays), a fitted
    to the two densest measured points; time linear in rays through them)."""
    measured = sorted(measured)
    a, _ = fit_law([m[0] for m in measured[-2:]], [m[2] for m in measured[-2:]])  # the densest two
    (r1, t1, _), (r2, t2, _) = measured[-2], measured[-1]
    per_ray = (t2 - t1) / (r2 - r1) if t2 > t1 else t2 / r2  # noise can invert the last two times
    curve = [(r, t, e, "measured") for r, t, e in measured]
    for r in sorted(set(ray_counts)):
        if r > r2:
            curve.append((r, t2 + per_ray * (r - r2), a / math.sqrt(r), "fitted"))
    return curve


def reference_noise_factor(rays, reference_rays):
    """Per receiver, |T_embree - T_ref|^2 estimates err^2 (1 + rays / reference_rays) when the
    reference is the same unbiased estimator with more rays: the factor that takes it off."""
    return 1.0 / math.sqrt(1.0 + rays / reference_rays)


def time_at_error(error, curve):
    """Time on `curve` [(rays, ms, error, ...)] at `error`, log-log interpolation between the
    neighbouring points -> (ms, how). Outside the curve, time ~ error^-2 (the Monte-Carlo law)
    from the nearest end: 'interpolated', 'law, beyond <rays> rays' or 'law, below <rays> rays'."""
    pts = sorted(curve)
    lt = [math.log(p[1]) for p in pts]
    le = [math.log(p[2]) for p in pts]
    x = math.log(error)
    first = next((k for k in range(len(pts)) if le[k] <= x), None)
    if first is None:  # more accurate than the densest point
        return math.exp(lt[-1] - 2.0 * (x - le[-1])), f"law, beyond {pts[-1][0]} rays"
    if first == 0:  # less accurate than the cheapest point
        return math.exp(lt[0] - 2.0 * (x - le[0])), f"law, below {pts[0][0]} rays"
    i = first - 1
    slope = (lt[i + 1] - lt[i]) / (le[i + 1] - le[i]) if le[i + 1] != le[i] else 0.0
    return math.exp(lt[i] + slope * (x - le[i])), "interpolated"
