"""Indirect light gathered at fewer texels, and interpolated between them where it is smooth:
irradiance caching (Ward et al. 1988) on the lightmap's grid.

A radiance walk costs about ten visibility masks, and bounce light mostly changes slowly
across a surface. So texels gather on a coarse lattice first (every 2^LEVELS-th row and
column), then level by level on lattices of half the spacing. A texel new to a level lies
midway between two texels of the coarser lattice (along a row or a column) or in the middle
of four, and takes their mean when

- all of them are there (inside the islands, not inside solid geometry);
- it lies where they are: its position departs from their mean by at most a quarter of
  their spread, and its normal is within 20 degrees of each of theirs (the other side of
  a UV seam, or another island, is not between them);
- they lie closer together than `NEAR` times the harmonic mean distance to what each sees
  (`Scene.gather_views`' distance, the R of irradiance caching): near a wall or an object
  standing on the surface, bounce light changes at the scale of that distance;
- the light bends little there: at each of them, the second differences along the coarser
  lattice's row and column (a mean of two texels misses their midpoint by an eighth of the
  second difference over twice that spacing) add up to at most 8 x `contrast` of the
  neighbours' band 0, in every SH coefficient. Band 0 counts as at least `DARK` of the
  brightest one the first lattice gathered, and at least the texel's direct light (`floor`):
  an error shows against all the light a texel gets. A texel without lattice neighbours
  on both sides of a row or column takes the second difference of the next one in.

The others gather. Receivers that are not valid (inside solid geometry) gather nothing: the
bake fills their texels from their neighbours. A feature that no lattice texel sees (a
shadow narrower than the spacing, between two lattice texels) can be missed, as irradiance
caching can miss one between its records.
"""

import numpy as np

#: Largest estimated error of a mean, relative to band 0 (see the module's docstring).
CONTRAST = 0.02

#: Band-0 values below this share of the brightest count as it.
DARK = 0.01

#: The first lattice's spacing is 2^LEVELS texels; each level halves it.
LEVELS = 2

#: Lattice neighbours farther apart than this share of the distance to what they see
#: (irradiance caching's harmonic mean distance R) do not interpolate: near a wall, light
#: bends at the wall's scale. Next to a box standing above a plane, 1.0 left texels 2.7 %
#: off a gather at every texel, 0.5 1.2 % (tests/addon/test_lightmaps_atlas.py's scene).
NEAR = 0.5

_COS_NORMAL = np.cos(np.radians(20.0))

# Neighbours (in half spacings) on the coarser lattice of a texel new to a level, by its
# (row, column) parity in half spacings: midway along a column, along a row, or in the
# middle of four (the two-neighbour cases repeat theirs).
_NEIGHBOURS = {(1, 0): ((-1, 0), (1, 0), (-1, 0), (1, 0)),
               (0, 1): ((0, -1), (0, 1), (0, -1), (0, 1)),
               (1, 1): ((-1, -1), (-1, 1), (1, -1), (1, 1))}


class Grid:
    """Receivers on the texel grid: which are valid, their rows and columns, and the valid
    receiver of each cell.
    origin (N, 2): the row and column each receiver's lattices count from (its target's first
    ones, so that they fall on the same texels in an atlas as alone; default 0, 0); group
    (N,): receivers of another group (target) are no one's neighbours (default: one group)."""

    def __init__(self, cell, valid, shape, origin=None, group=None):
        self.rows, self.cols = shape[1:]
        self.cell, self.valid = cell, valid
        self.row, self.col = cell // self.cols % self.rows, cell % self.cols
        self.origin = np.zeros((len(cell), 2), np.int64) if origin is None else np.asarray(origin, np.int64)
        self.group = np.zeros(len(cell), np.int64) if group is None else np.asarray(group, np.int64)
        self.at = np.full(int(np.prod(shape)), -1, np.int64)
        self.at[cell[valid]] = np.flatnonzero(valid)

    def on(self, spacing):
        """Receivers on the lattice of every `spacing`-th row and column (from their origin)."""
        return ((self.row - self.origin[:, 0]) % spacing == 0) & ((self.col - self.origin[:, 1]) % spacing == 0)

    def parity(self, i, half):
        """(len(i), 2): receivers i's row and column parity in steps of `half` (from their origin)."""
        return np.stack([(self.row[i] - self.origin[i, 0]) // half % 2, (self.col[i] - self.origin[i, 1]) // half % 2],
                        axis=1)

    def neighbour(self, i, dr, dc):
        """The receivers (len(i),) dr rows and dc columns away from receivers i; -1 off the
        map, where that cell has no valid receiver, or one of another group."""
        r, c = self.row[i] + dr, self.col[i] + dc
        inside = (r >= 0) & (r < self.rows) & (c >= 0) & (c < self.cols)
        j = np.where(inside, self.at[np.where(inside, self.cell[i] + dr * self.cols + dc, 0)], -1)
        return np.where((j >= 0) & (self.group[np.maximum(j, 0)] == self.group[i]), j, -1)


def gather(gather_at, coefficients, points, normals, grid, steps=None, weight=1, contrast=CONTRAST, floor=None):
    """SH (N, coefficients, 3) of N receivers, one per texel (`grid`, a `Grid` of them),
    `gather_at(indices)` gathering for some of them; invalid ones get zeros. steps: a
    `bake.Steps` chunking the gathers, stepped by `weight` per receiver. floor (N, 3): the
    least band 0 each receiver's error is measured against (the bake gives its direct light,
    in band-0 units: an error is seen against the total)."""
    valid = grid.valid
    out = np.zeros((len(grid.cell), coefficients, 3), np.float32)
    distance = np.full(len(grid.cell), np.inf, np.float32)
    if steps is not None:
        steps.step(int((~valid).sum()) * weight)
    spacing = 2 ** LEVELS
    first = np.flatnonzero(valid & grid.on(spacing))
    _gather_some(gather_at, first, out, distance, steps, weight)
    while spacing > 1:
        half = spacing // 2
        new = np.flatnonzero(valid & grid.on(half) & ~grid.on(spacing))
        least = None if floor is None else floor[new]
        smooth = _interpolated(out, distance, grid, new, spacing, points, normals, contrast, out[first], least)
        if steps is not None:
            steps.step(int(smooth.sum()) * weight)
        _gather_some(gather_at, new[~smooth], out, distance, steps, weight)
        spacing = half
    return out


def _interpolated(out, distance, grid, new, spacing, points, normals, contrast, first_values, floor):
    """Sets the receivers `new` (on the lattice of spacing/2, not of spacing) that lie
    smoothly between their neighbours on the lattice of `spacing` to their mean; which did."""
    half = spacing // 2
    neighbours = np.full((len(new), 4), -1, np.int64)
    parity = grid.parity(new, half)
    for key, offsets in _NEIGHBOURS.items():
        mine = np.flatnonzero((parity[:, 0] == key[0]) & (parity[:, 1] == key[1]))
        for k, (dr, dc) in enumerate(offsets):
            neighbours[mine, k] = grid.neighbour(new[mine], dr * half, dc * half)
    smooth = _between(neighbours, points[new], normals[new], points, normals, distance)
    nb = neighbours[smooth]
    bend = _bend(out, grid, nb.reshape(-1), spacing).reshape(nb.shape + (3,))
    smooth[smooth] = _smooth(out[nb], bend, first_values, contrast, None if floor is None else floor[smooth])
    out[new[smooth]] = out[neighbours[smooth]].mean(axis=1)
    distance[new[smooth]] = distance[neighbours[smooth]].min(axis=1)
    return smooth


def _gather_some(gather_at, indices, out, distance, steps, weight):
    for s in [slice(0, len(indices))] if steps is None else steps.chunks(len(indices), weight=weight, least=1024):
        out[indices[s]], distance[indices[s]] = gather_at(indices[s])


def _bend(out, grid, i, spacing):
    """(len(i), 3): at receivers i on the lattice of `spacing`, the largest over SH
    coefficients of the second differences along the lattice's row and column, added: each
    centred on i, or on its neighbour where i has one on one side only (a map's or an
    island's edge); inf where there is none."""
    total = np.zeros((len(i), 3), np.float32)
    for dr, dc in ((spacing, 0), (0, spacing)):
        lo, hi = grid.neighbour(i, -dr, -dc), grid.neighbour(i, dr, dc)
        lo2 = np.where(lo >= 0, grid.neighbour(np.maximum(lo, 0), -dr, -dc), -1)
        hi2 = np.where(hi >= 0, grid.neighbour(np.maximum(hi, 0), dr, dc), -1)
        # three receivers in a row: (lo, i, hi), else (i, hi, hi2), else (lo2, lo, i)
        centred = (lo >= 0) & (hi >= 0)
        ahead = ~centred & (hi2 >= 0)
        behind = ~centred & ~ahead & (lo2 >= 0)
        a, b, c = (np.select([centred, ahead, behind], choices, -1)
                   for choices in ((lo, i, lo2), (i, hi, lo), (hi, hi2, i)))
        known = (a >= 0) & (b >= 0) & (c >= 0)
        second = out[np.maximum(a, 0)] - 2 * out[np.maximum(b, 0)] + out[np.maximum(c, 0)]
        total += np.where(known[:, None], np.abs(second).max(axis=1), np.inf)
    return total


def _between(neighbours, points, normals, all_points, all_normals, distance):
    """Receivers whose every lattice neighbour exists and lies around them, facing their way,
    closer together than `NEAR` of the distance to what each sees."""
    ok = (neighbours >= 0).all(axis=1)
    nb = np.where(neighbours >= 0, neighbours, 0)
    p, n = all_points[nb], all_normals[nb]
    spread = np.linalg.norm(p - p[:, :1], axis=2).max(axis=1)
    off = np.linalg.norm(points - p.mean(axis=1), axis=1)
    facing = (np.einsum("nkj,nj->nk", n, normals) >= _COS_NORMAL).all(axis=1)
    near = spread <= NEAR * distance[nb].min(axis=1)
    return ok & facing & near & (off <= 0.25 * spread)


def _smooth(values, bend, first_values, contrast, floor):
    """For lattice neighbours' SH (n, 4, K, 3) and bends (n, 4, 3): whether a mean of them
    misses by at most `contrast` of their mean's band 0 (at least `DARK` of the brightest
    band 0 of `first_values` (L, K, 3), the first lattice's, and at least `floor` (n, 3))."""
    mean = values.mean(axis=1)
    brightest = np.abs(first_values[:, 0]).max(axis=0) if len(first_values) else np.zeros(3)
    scale = np.maximum(np.abs(mean[:, 0]), np.maximum(DARK * brightest, 1e-30))   # (n, 3)
    if floor is not None:
        scale = np.maximum(scale, floor)
    return (bend.max(axis=1) / 8 <= contrast * scale).all(axis=1)
