"""Adaptive supersampling, as VRAD refines luxels: every texel is first lit at one sample, its
centre, and gets all its samples only where one is not enough.

A texel's mean over its area equals its centre value wherever the light varies linearly
across it; what the centre misses is curvature (soft falloff near a wall) and edges (sun
shadows, contact with an object standing on the surface). Both show as a second difference
between the texel and its neighbours, along rows, columns and both diagonals. An edge that
crosses a texel between its centre and a neighbour without a usable centre shows in no
difference, so a texel is refined when

- its centre sample is not usable: outside every UV triangle (an island's rim, where the
  texel keeps the part of the triangle it covers) or inside solid geometry (invalid);
- any of its 8 neighbours has no usable centre: the edge of an island or of the map, or an
  object's footprint on the surface;
- its light (every lobe's RGB and AO) departs from the mean of two opposite neighbours by
  more than `contrast` of its own value, and by more than `least` (the bake gives AO a least
  departure of `AO_CELLS` mask cells: smaller ones are the mask's resolution; in a closed
  room, where AO is a few cells of window, they refined 96 % of the floor's texels, against
  40 % with it, for the same error against Cycles).

Values below 1 % of the brightest texel of the map (AO: of the open sky, 1) count as 1 % of
it, so departures in the dark are measured against `contrast` x 1 % of the brightest, not
against their own tiny values. A linear gradient of any slope refines nothing. A refined
texel gets exactly the samples it would get without refinement.
"""

import numpy as np

#: Second difference, relative to the texel's own light, above which it takes all samples.
#: Measured against a sample everywhere and against Cycles in docs/lightmaps.md.
CONTRAST = 0.02

#: AO departures within this many of the visibility mask's cells (each at most 1/800 of the
#: open sky, `cells.largest_cell_ao`) never refine.
AO_CELLS = 4

#: Values below this share of a channel's brightest texel are compared as if they were it.
DARK = 0.01

_AXES = ((0, 1), (1, 0), (1, 1), (1, -1))


def texels_to_refine(values, usable, contrast=CONTRAST, full=None, least=None):
    """Texels (T, R, R) bool that need all their samples, from the light at their centre
    samples: `values` (T, R, R, C) (any value where there is no usable centre), `usable`
    (T, R, R): a centre sample inside a UV triangle and not inside solid geometry. `full`
    (C,): per channel the value that counts as full, of which `DARK` is the least a departure
    is measured against (None: the brightest texel's). `least` (C,): per channel the largest
    departure that never refines (None: 0). Texels outside every island come out refined
    too; the caller has no samples for them."""
    values = np.where(usable[..., None], values, 0.0)
    brightest = np.abs(values).reshape(-1, values.shape[-1]).max(axis=0)
    floor = DARK * (brightest if full is None else np.where(np.isnan(full), brightest, full))
    scale = np.maximum(np.abs(values), np.maximum(floor, 1e-30))
    threshold = contrast * scale if least is None else np.maximum(contrast * scale, least)
    padded_values = np.pad(values, ((0, 0), (1, 1), (1, 1), (0, 0)))
    padded_usable = np.pad(usable, ((0, 0), (1, 1), (1, 1)))
    rows, cols = values.shape[1:3]

    def shifted(array, dy, dx):
        return array[:, 1 + dy:1 + dy + rows, 1 + dx:1 + dx + cols]

    refine = ~usable
    for dy, dx in _AXES:
        both = shifted(padded_usable, -dy, -dx) & shifted(padded_usable, dy, dx)
        mean = (shifted(padded_values, -dy, -dx) + shifted(padded_values, dy, dx)) / 2
        refine |= ~both | (np.abs(values - mean) > threshold).any(axis=-1)
    return refine


def disagreeing(cell, valid, values, cells):
    """(cells,) bool: texels whose valid samples' `values` (P, C) (`cell` (P,): each sample's
    texel) are not all the same."""
    cell, values = cell[valid], values[valid]
    lo = np.full((cells, values.shape[1]), np.inf)
    hi = np.full((cells, values.shape[1]), -np.inf)
    np.minimum.at(lo, cell, values)
    np.maximum.at(hi, cell, values)
    return (hi > lo).any(axis=1)


def differs_from_a_neighbour(cell, valid, values, shape):
    """(layers * R * R,) bool: texels (of the grid `shape`) whose valid samples' mean `values`
    (P, C) differ from those of a side neighbour that has valid samples too."""
    cells = int(np.prod(shape))
    cell, values = cell[valid], values[valid]
    count = np.bincount(cell, minlength=cells)
    mean = np.stack([np.bincount(cell, values[:, c], cells) for c in range(values.shape[1])], axis=-1)
    mean = (mean / np.maximum(count, 1)[:, None]).reshape(shape + (-1,))
    known = (count > 0).reshape(shape)
    out = np.zeros(shape, bool)
    for axis in (1, 2):
        lower = tuple(slice(None, -1) if a == axis else slice(None) for a in range(3))
        upper = tuple(slice(1, None) if a == axis else slice(None) for a in range(3))
        differ = known[lower] & known[upper] & (mean[lower] != mean[upper]).any(axis=-1)
        out[lower] |= differ
        out[upper] |= differ
    return out.reshape(-1)
