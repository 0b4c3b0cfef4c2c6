"""One map shared by several targets (an atlas): each target's islands sit in its own slot of
the same R x R map (the lightmap UVs place them; nothing here moves texels).

Every target is filled and padded on its own, inside its slot's bounding box, exactly as if
it were baked alone, and the pieces are then laid over each other: an island texel keeps its
own target's value, and a padding texel takes the target whose island is nearest (the first
padding pass to reach it; ties go to the earlier target). So padding never bleeds into
another object's islands, and an island reads the same texels as its own bake would.
"""

import numpy as np

from . import dilate


def _box(island, margin):
    """Rows and columns (slices) of the island's bounding box grown by `margin` (+1)."""
    rows, cols = np.nonzero(island)
    r = island.shape[0]
    if not len(rows):
        return None
    grow = int(margin) + 1
    return (slice(max(rows.min() - grow, 0), min(rows.max() + grow + 1, r)),
            slice(max(cols.min() - grow, 0), min(cols.max() + grow + 1, r)))


def _pad(image, known, island, margin, check=None):
    """Fills the island from its valid texels and pads `margin` passes; returns the pass at
    which each texel got its value (0: island, k: k-th padding pass, inf: never)."""
    dilate.fill(image, known, island, check)
    reached = np.where(known, 0.0, np.inf)
    for k in range(1, int(margin) + 1):
        if check is not None:
            check()
        if not dilate.grow(image, known):
            break
        reached[known & np.isinf(reached)] = k
    return reached


def compose(pieces, resolution, channels, margin, check=None):
    """pieces: per target (image (R, R, C) of texel means, known (R, R) texels with a valid
    sample, island (R, R) texels with a sample). Returns the atlas (R, R, C), its known texels
    and the owner of each texel (target index, -1 for none). `check`: called between passes."""
    r = int(resolution)
    atlas = np.zeros((r, r, channels), np.float32)
    best = np.full((r, r), np.inf)
    owner = np.full((r, r), -1, np.int64)
    for k, (image, known, island) in enumerate(pieces):
        box = _box(island | known, margin)
        if box is None:
            continue
        part, part_known = image[box].copy(), known[box].copy()
        reached = _pad(part, part_known, island[box], margin, check)
        closer = reached < best[box]
        atlas[box][closer] = part[closer]
        owner[box][closer] = k
        best[box] = np.minimum(best[box], reached)
    return atlas, owner >= 0, owner
