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


def smoothed(values, grid, points, normals, spacing, target, use):
    """Per sample (one per texel, `grid` a `sparse_gather.Grid` of them), the 3 x 3
    tent-weighted mean of `values` (P, C) over its texel and the neighbours on the same
    surface: in `use`, of the same `target`, within `_NEAR` texels (`spacing` (P,): a texel's
    world size) and 20 degrees. Samples not in `use` keep their values."""
    total = np.zeros(values.shape, np.float64)
    weight = np.zeros(len(values), np.float64)
    mine = np.flatnonzero(use)
    for dr, dc, w in _TENT:
        other = grid.neighbour(mine, dr, dc)
        ok = other >= 0
        j, i = other[ok], mine[ok]
        ok[ok] = use[j] & (target[j] == target[i]) & ((normals[i] * normals[j]).sum(1) >= _COS_NORMAL) & (
            np.linalg.norm(points[j] - points[i], axis=1) <= _NEAR * np.hypot(dr, dc) * spacing[i])
        i, j = mine[ok], other[ok]  # each sample once per offset
        total[i] += w * values[j]
        weight[i] += w
    out = values.copy()
    out[mine] = (total[mine] / weight[mine, None]).astype(values.dtype)
    return out
