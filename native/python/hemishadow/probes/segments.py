"""Exact segment-triangle occlusion in numpy (Moller-Trumbore), for the leak rule of
`evaluate`. `Scene` answers "is this direction blocked at any distance" only (its masks
have no depth), which cannot tell a wall between a point and a probe from the far wall of
the room behind the probe; this test can. Triangles are culled to each chunk's bounds."""

import numpy as np

_CHUNK = 256
_EPS = 1e-6


def blocked(starts, ends, triangles):
    """bool (S,): does the open segment starts -> ends (S, 3) cross a triangle (M, 3, 3)?
    Both ends are excluded by a relative margin of 1e-4 of the segment's length."""
    starts, ends = np.asarray(starts, np.float64), np.asarray(ends, np.float64)
    tris = np.asarray(triangles, np.float64)
    out = np.zeros(len(starts), bool)
    if not len(tris):
        return out
    tmin, tmax = tris.min(axis=1), tris.max(axis=1)
    for s in range(0, len(starts), _CHUNK):
        a, b = starts[s:s + _CHUNK], ends[s:s + _CHUNK]
        lo = np.minimum(a, b).min(axis=0)
        hi = np.maximum(a, b).max(axis=0)
        near = np.flatnonzero(((tmax >= lo) & (tmin <= hi)).all(axis=1))
        if len(near):
            out[s:s + _CHUNK] = _crosses(a, b - a, tris[near])
    return out


def _crosses(origin, direction, tris):
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    p = np.cross(direction[:, None], e2[None])                   # (S, M, 3)
    det = (e1[None] * p).sum(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        tvec = origin[:, None] - v0[None]
        u = (tvec * p).sum(-1) * inv
        q = np.cross(tvec, e1[None])
        v = (direction[:, None] * q).sum(-1) * inv
        t = (e2[None] * q).sum(-1) * inv
    hit = (np.abs(det) > 1e-30) & (u >= -_EPS) & (v >= -_EPS) & (u + v <= 1 + _EPS) & (t > 1e-4) & (t < 1 - 1e-4)
    return hit.any(axis=1)
