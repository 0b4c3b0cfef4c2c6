"""The 3 x 3 tent filter over a texel's neighbours on the same surface.

Used where each texel's value is right on average but carries an error of its own: the
environment light of texels lit at their centre (their masks' four turned lattices,
`tilts.py`) and the bounce light they gather (each gather sees the bounce field through one
lattice: the corner of bench/lightmap_cycles.py with 2 bounces, 64 x 64, 0.40 -> 0.38 % off
Cycles; the room unchanged). A tent weighs each parity class of a 2 x 2 pattern a quarter.
"""

import numpy as np

#: Neighbours farther than this many texels (their world size at the texel) or whose normals
#: part by more than 20 degrees are another island or across a fold: not averaged.
_NEAR = 1.5
_COS_NORMAL = np.cos(np.radians(20.0))

# The tent's 3 x 3 weights by offset: each parity class of a 2 x 2 pattern weighs a quarter.
_TENT = [(dr, dc, (2 - abs(dr)) * (2 - abs(dc))) for dr in (-1, 0, 1) for dc in (-1, 0, 1)]


def smoothed(values, grid, points, normals, spacing, use, chunk=1 << 15):
    """Per sample (one per texel, `grid` a `sparse_gather.Grid` of them, grouped by target),
    the 3 x 3 tent-weighted mean of `values` (P, C) over its texel and the neighbours on the
    same surface: the grid's (its group), in `use`, within `_NEAR` texels (`spacing` (P,): a
    texel's world size) and 20 degrees. Samples not in `use` keep their values. `chunk` samples at a
    time (each gathers its 9 neighbours' values)."""
    out = values.copy()
    mine = np.flatnonzero(use)
    offsets = np.array([(dr, dc) for dr, dc, _ in _TENT])
    tent = np.array([w for *_, w in _TENT], np.float32)
    reach = (_NEAR * np.hypot(offsets[:, 0], offsets[:, 1])) ** 2
    padded = np.concatenate([values, np.zeros((1,) + values.shape[1:], values.dtype)])  # row -1: no neighbour
    for start in range(0, len(mine), chunk):
        i = mine[start:start + chunk]
        j = np.stack([grid.neighbour(i, dr, dc) for dr, dc in offsets], axis=1)   # (n, 9), -1: none
        k = np.maximum(j, 0)
        ok = (j >= 0) & use[k]
        ok &= np.einsum("nkd,nd->nk", normals[k], normals[i]) >= _COS_NORMAL
        gap = points[k] - points[i, None]
        ok &= np.einsum("nkd,nkd->nk", gap, gap) <= reach * spacing[i, None] ** 2
        weights = np.where(ok, tent, np.float32(0))
        near = np.einsum("nk,nkc->nc", weights, padded[np.where(ok, j, -1)].reshape(len(i), 9, -1))
        out[i] = (near / weights.sum(axis=1, keepdims=True)).reshape((len(i),) + values.shape[1:])
    return out
