"""Filling texels from their neighbours: invalid receivers, and padding around islands.

One pass gives every unknown texel with a known 8-neighbour the mean of its known
neighbours, so `margin` passes pad exactly `margin` texels (Chebyshev distance) around each
island, and texels whose receivers were all invalid (inside geometry) take the values of the
nearest valid texels of their island instead of black or leaked light.
"""

import numpy as np

_OFFSETS = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx]


def grow(values, known, region=None):
    """One pass: unknown texels of `region` (all when None) next to known ones take their
    known neighbours' mean. Returns the number of texels filled; updates in place."""
    h, w = known.shape
    padded = np.pad(values * known[..., None], ((1, 1), (1, 1), (0, 0)))
    count_pad = np.pad(known.astype(np.float32), 1)
    total = np.zeros_like(values)
    count = np.zeros(known.shape, np.float32)
    for dy, dx in _OFFSETS:
        total += padded[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
        count += count_pad[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
    new = ~known & (count > 0)
    if region is not None:
        new &= region
    values[new] = total[new] / count[new, None]
    known |= new
    return int(new.sum())


def _checked(check):
    if check is not None:
        check()
    return True


def fill(values, known, region, check=None):
    """Fills every texel of `region` from the known ones: first through the region itself,
    then (an island with no valid texel at all) from whatever is nearest. In place. `check`:
    called before each pass (a cancel raises there)."""
    while _checked(check) and (region & ~known).any() and grow(values, known, region):
        pass
    if (region & ~known).any() and known.any():
        scratch, reach = values.copy(), known.copy()
        while _checked(check) and (region & ~reach).any() and grow(scratch, reach):
            pass
        rest = region & ~known
        values[rest], known[rest] = scratch[rest], True


def dilate(values, known, margin, check=None):
    """Pads `margin` texels around the known ones. In place."""
    for _ in range(int(margin)):
        _checked(check)
        if not grow(values, known):
            break
