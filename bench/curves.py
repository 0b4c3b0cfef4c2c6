"""Embree's time-versus-error curve and the read-off of its time at a given error.

Beyond the ray counts that were run (`extend`), Embree's curve continues by a power law
error = a N^b, its time linear in N through the two densest measured points. Plain Monte
Carlo gives b = -1/2; stratified (jittered-grid) rays converge faster on the visibility
edges, up to b = -3/4 in two dimensions, and the measured curves do. So b is fitted to the
measured points and held within [-3/4, -1/2] (two or three noisy points can suggest anything),
and a to the two densest points. `time_at_error` interpolates the curve log-log, so a
hemishadow point's speed-up at equal error is time_at_error / its time.
"""

import math

import numpy as np

STEEPEST, SHALLOWEST = -0.75, -0.5


def fit_law(rays, errors):
    """(a, b, measured slope) of error = a N^b: the slope by least squares in log space over
    all points, b that slope held within [STEEPEST, SHALLOWEST], a through the two densest."""
    r, e = np.log(np.asarray(rays, float)), np.log(np.asarray(errors, float))
    order = np.argsort(r)
    slope = float(np.polyfit(r, e, 1)[0]) if len(r) >= 2 else SHALLOWEST
    b = min(SHALLOWEST, max(STEEPEST, slope))
    densest = order[-2:]
    a = float(np.exp(np.mean(e[densest] - b * r[densest])))
    return a, b, slope


def extend(measured, ray_counts):
    """measured: [(rays, ms, error)] (at least two). Returns the curve [(rays, ms, error,
    'measured' | 'fitted')] over the measured ray counts and the larger ones of `ray_counts`
    (a larger count by the fitted law, its time linear in rays through the two densest
    measured points), and the exponent b of the law."""
    measured = sorted(measured)
    a, b, _ = fit_law([m[0] for m in measured], [m[2] for m in measured])
    (r1, t1, _), (r2, t2, _) = measured[-2], measured[-1]
    per_ray = (t2 - t1) / (r2 - r1) if t2 > t1 else t2 / r2  # noise can invert the last two times
    curve = [(r, t, e, "measured") for r, t, e in measured]
    for r in sorted(set(ray_counts)):
        if r > r2:
            curve.append((r, t2 + per_ray * (r - r2), a * r**b, "fitted"))
    return curve, b


def reference_noise_factor(rays, reference_rays):
    """Per receiver, |T_embree - T_ref|^2 estimates err^2 (1 + rays / reference_rays) when the
    reference is the same unbiased estimator with more rays: the factor that takes it off."""
    return 1.0 / math.sqrt(1.0 + rays / reference_rays)


def time_at_error(error, curve, exponent=SHALLOWEST):
    """Time on `curve` [(rays, ms, error, ...)] at `error`, log-log interpolation between the
    neighbouring points -> (ms, how). Outside the curve, time ~ rays ~ error^(1 / exponent)
    from the nearest end: 'interpolated', 'law, beyond <rays> rays' or 'law, below <rays> rays'."""
    pts = sorted(curve)
    lt = [math.log(p[1]) for p in pts]
    le = [math.log(p[2]) for p in pts]
    x = math.log(error)
    first = next((k for k in range(len(pts)) if le[k] <= x), None)
    if first is None:  # more accurate than the densest point
        return math.exp(lt[-1] + (x - le[-1]) / exponent), f"law, beyond {pts[-1][0]} rays"
    if first == 0:  # less accurate than the cheapest point
        return math.exp(lt[0] + (x - le[0]) / exponent), f"law, below {pts[0][0]} rays"
    i = first - 1
    slope = (lt[i + 1] - lt[i]) / (le[i + 1] - le[i]) if le[i + 1] != le[i] else 0.0
    return math.exp(lt[i] + slope * (x - le[i])), "interpolated"
