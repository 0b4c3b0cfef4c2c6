"""Visibility masks through four turned lattices, which `tent.py`'s filter averages.

A mask sees the environment through 1,024 fixed cell directions, a cell open or blocked by
its sample direction alone. Neighbouring texels see the same edges (a window's sill, a
table's top) cross the same cells, so their environment light is off by the same whole cells:
it steps in bands a few texels wide, and a small patch of sky (a window seen under a table)
came out a third too dark over a whole region of the room of bench/lightmap_cycles.py.
Moving the sample within its texel does not help: the cells stay where they are.

So each sample's mask is taken with its normal tilted by `TILT` towards one of four
directions (`tilted_normals`), which turns the lattice of cell directions, and is read as if
it were not turned (in the frame of the true normal): the scene is seen turned by 4 degrees
one way or another. The direction comes from the parity of the texel's row and column (a
2 x 2 pattern), turned on by the sample's light pattern, so that a texel's samples take each
in turn. Texels lit at their centre alone (refinement found their light smooth) take the
tent-filtered mean of their own and their neighbours' environment light (`tent.py`), where
each direction weighs a quarter. Either way, a turn's first-order change cancels against its
opposite's, and the cells' errors average over four lattices: a 4-degree blur of what the
masks see, the anti-aliasing a single lattice lacks. An open plane stays exact (an open
mask turned is still open).

Room of bench/lightmap_cycles.py, direct light, 64 x 64, against Cycles: 1.22 % without,
0.92 % with, the same time (at 128 x 128: 1.25 -> 0.92 %); tilts of 2 and 6 degrees did
worse than 4; the filter without the tilts gave 1.15 %, the tilts without the filter 1.21 %.
The filter also keeps refinement from mistaking the turns for light changing (1,441 texels
refined instead of 1,606 without tilts, 1,769 with tilts and no filter).
"""

import numpy as np

from . import cells

#: How far each sample's mask normal tilts from its geometric normal, in radians (about half
#: the elevation a mask cell spans near the horizon).
TILT = np.radians(4.0)


def classes(dx, dy, pattern):
    """(S,) int64: each sample's tilt direction (0 .. 3, `tilted_normals`) from its texel's
    column and row parity (`dx`, `dy`, relative to a place that moves with the texel in an
    atlas) and its light pattern (`texels.light_patterns`, 0 .. samples - 1). Directions
    2k and 2k + 1 are opposite: side neighbours in a row, and a texel's samples 0 and 1, turn
    opposite ways; samples 0 to 3 take all four."""
    return (2 * (np.asarray(dy) % 2) + np.asarray(dx) % 2) ^ (np.asarray(pattern) % 4)


def tilted_normals(ng, tilt):
    """Unit normals (P, 3) the masks of samples with geometric normals `ng` (P, 3) are taken
    with: tilted by `TILT` towards the engine frame's t, -t, b or -b for `tilt` 0, 1, 2, 3;
    untilted where `tilt` is negative (a sample no other averages with)."""
    ng = np.asarray(ng)
    tilt = np.asarray(tilt)
    t, b = cells.engine_frame(ng)
    side = np.where((tilt % 2 == 0)[:, None], 1.0, -1.0) * np.where((tilt // 2 % 2 == 0)[:, None], t, b)
    tilted = np.cos(TILT) * ng.astype(np.float64) + np.sin(TILT) * side
    tilted /= np.linalg.norm(tilted, axis=1, keepdims=True)
    return np.where((tilt >= 0)[:, None], tilted, ng).astype(ng.dtype)
