"""Lighting at any point from baked probes, without leaking through walls.

Grid probes: the 8 probes of the point's cell with trilinear weights; probe-list bakes: the
8 nearest probes, weights 1 / distance^2. Weights drop invalid probes and, when `blockers`
(the scene's world triangles) are given, every probe that the point cannot see: the segment
from the point (lifted by `bias` along its normal) to the probe crosses a triangle
(`segments.blocked`, exact). The remaining weights are renormalised. Where nothing is left,
the valid probes among the 8 are used as they are (the point is reported in `fallback`);
where none is valid either, the nearest valid probe. Plain trilinear (blockers=None) leaks
light through a wall thinner than a cell: tests/test_probes.py shows it.
"""

import numpy as np

from . import grid, segments
from .cube import sample

NEIGHBOURS = 8


def _neighbours(probes, points):
    if "grid_matrix" in probes and "grid_resolution" in probes:
        return grid.corners(probes["grid_matrix"], probes["grid_resolution"], points)
    pos = np.asarray(probes["positions"], np.float64)
    d = ((points[:, None] - pos[None]) ** 2).sum(-1)
    k = min(NEIGHBOURS, len(pos))
    ids = np.argsort(d, axis=1)[:, :k]
    w = 1.0 / np.maximum(np.take_along_axis(d, ids, 1), 1e-12)
    return ids, w


def evaluate(probes, points, normals=None, *, blockers=None, bias=None):
    """Interpolated `cube` (Q, 6, 3), `sh9` (Q, 9, 3), `value` (Q, 3) (n-squared sampling of
    the cube for `normals`, when given), `weights` (Q, 8) and `ids` (Q, 8) used, `fallback` (Q,).

    probes: a `bake` / `bake_grid` result or `files.read_npz`. blockers: world triangles
    (M, 3, 3) for the visibility rule; None: no visibility test (leaks). bias: how far points
    are lifted along their normals before the test (default: 5 % of the smallest probe spacing).
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or not np.isfinite(pts).all():
        raise ValueError(f"points must be finite (Q, 3), got shape {pts.shape}")
    valid = np.asarray(probes["valid"], bool)
    if not valid.any():
        raise ValueError("no valid probe to evaluate from")
    pos = np.asarray(probes["positions"], np.float64)
    ids, w = _neighbours(probes, pts)
    w = w * valid[ids]
    lifted = pts
    if normals is not None:
        n = np.asarray(normals, np.float64)
        if n.shape != pts.shape or not np.isfinite(n).all():
            raise ValueError(f"normals must be finite (Q, 3) like points, got shape {n.shape}")
        n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        lifted = pts + n * (_spacing(probes) * 0.05 if bias is None else float(bias))
    if blockers is not None:
        seen = ~segments.blocked(np.repeat(lifted, ids.shape[1], 0), pos[ids.reshape(-1)], blockers)
        w_seen = w * seen.reshape(ids.shape)
    else:
        w_seen = w
    fallback = w_seen.sum(1) <= 0
    w = np.where(fallback[:, None], w, w_seen)
    none = w.sum(1) <= 0
    if none.any():  # no valid probe around: the nearest valid one
        good = np.flatnonzero(valid)
        near = good[np.argmin(((pts[none][:, None] - pos[good][None]) ** 2).sum(-1), axis=1)]
        ids[none], w[none] = near[:, None], 1.0
    w = w / w.sum(1, keepdims=True)
    cube = np.einsum("qk,qkjc->qjc", w, np.asarray(probes["cube"], np.float64)[ids])
    sh9 = np.einsum("qk,qkjc->qjc", w, np.asarray(probes["sh9"], np.float64)[ids])
    out = {"cube": cube, "sh9": sh9, "weights": w, "ids": ids, "fallback": fallback}
    if normals is not None:
        out["value"] = sample(cube, normals)
    return out


def _spacing(probes):
    """The grid's smallest cell axis, or the median nearest-neighbour distance of (up to 256
    of) the listed probes."""
    if "grid_matrix" in probes:
        return float(np.linalg.norm(np.asarray(probes["grid_matrix"])[:3, :3], axis=0).min())
    pos = np.asarray(probes["positions"], np.float64)
    if len(pos) < 2:
        return 0.0
    some = pos[np.linspace(0, len(pos) - 1, min(len(pos), 256)).astype(np.int64)]
    d = np.sqrt(((some[:, None] - pos[None]) ** 2).sum(-1))
    d[d == 0] = np.inf
    return float(np.median(d.min(axis=1)))
