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
  more than `contrast` of its own value.

Values below 1 % of the brightest texel of the map (AO: of the open sky, 1) count as 1 % of
it, so departures in the dark are measured against `contrast` x 1 % of the brightest, not
against their own tiny values. A linear gradient of any slope refines nothing. A refined
texel gets exactly the samples it would get without refinement.
"""

import numpy as np

#: Second difference, relative to the texel's own light, above which it takes all samples.
#: Measured against a sample everywhere and against Cycles in docs/lightmaps.md.
CONTRAST = 0.02

#: Values below this share of a channel's brightest texel are compared as if they were it.
DARK = 0.01

_AXES = ((0, 1), (1, 0), (1, 1), (1, -1))


def texels_to_refine(values, usable, contrast=CONTRAST, full=None):
    """Texels (T, R, R) bool that need all their samples, from the light at their centre
    samples: `values` (T, R, R, C) (any value where there is no usable centre), `usable`
    (T, R, R): a centre sample inside a UV triangle and not inside solid geometry. `full`
    (C,): per channel the value that counts as full, of which `DARK` is the least a departure
    is measured against (None: the brightest texel's). Texels outside every island come out
    refined too; the caller has no samples for them."""
    values = np.where(usable[..., None], values, 0.0)
    brightest = np.abs(values).reshape(-1, values.shape[-1]).max(axis=0)
    floor = DARK * (brightest if full is None else np.where(np.isnan(full), brightest, full))
    scale = np.maximum(np.abs(values), np.maximum(floor, 1e-30))
    padded_values = np.pad(values, ((0, 0), (1, 1), (1, 1), (0, 0)))
    padded_usable = np.pad(usable, ((0, 0), (1, 1), (1, 1)))
    rows, cols = values.shape[1:3]

    def shifted(array, dy, dx):
        return array[:, 1 + dy:1 + dy + rows, 1 + dx:1 + dx + cols]

    refine = ~usable
    for dy, dx in _AXES:
        both = shifted(padded_usable, -dy, -dx) & shifted(padded_usable, dy, dx)
        mean = (shifted(padded_values, -dy, -dx) + shifted(padded_values, dy, dx)) / 2
        refine |= ~both | (np.abs(values - mean) > contrast * scale).any(axis=-1)
    return refine
