"""Texels of a UV layout: triangles rasterized in UV space with supersampling.

Texel (row r, column c) of an R x R map covers u in [c, c+1] / R and v in [1 - (r+1)/R,
1 - r/R]: its centre is u = (c + 0.5) / R, v = 1 - (r + 0.5) / R, rows top to bottom as in an
EXR. In texel space x = u R, y = (1 - v) R, texel (r, c) is the unit square at (c, r).

Each texel holds `samples` points (a regular s x s grid when samples = s^2, else the R2
low-discrepancy sequence); a sample belongs to the first triangle that contains it. A texel
that a triangle touches without any sample inside it (an island's rim, a sliver) gets one
sample at the point of that triangle nearest to its centre, so it uses the part of the
triangle it covers. `coverage` is 1 where a texel centre lies in a triangle, before padding.
"""

from dataclasses import dataclass

import numpy as np

from . import tilts

_CANDIDATES_PER_CHUNK = 1 << 17  # about 0.05 s each: a cancel waits no longer
_EPS = 1e-9


@dataclass
class Texels:
    texel: np.ndarray      # (S,) int64: flat texel index r * R + c of each sample
    triangle: np.ndarray   # (S,) int64
    bary: np.ndarray       # (S, 3) float64 barycentric weights of the triangle's corners
    coverage: np.ndarray   # (R, R) bool: a texel centre inside a triangle
    island: np.ndarray     # (R, R) bool: texels with at least one sample
    index: np.ndarray      # (S,) int64: which of the texel's sample positions (0 for rim samples)
    overlapping: int       # samples strictly inside more than one triangle (overlapping UVs)
    light: np.ndarray      # (S,) int64: the pattern each sample sees suns and lamps by (`light_patterns`)
    tilt: np.ndarray       # (S,) int64: the direction its visibility mask tilts to (`tilts.classes`)


def offsets(samples):
    """Sample positions (n, 2) inside the unit texel."""
    side = int(round(np.sqrt(samples)))
    if side * side == samples:
        g = (np.arange(side) + 0.5) / side
        x, y = np.meshgrid(g, g)
        return np.stack([x.ravel(), y.ravel()], axis=1)
    g = 1.32471795724474602596  # plastic number: the R2 sequence (Roberts 2018)
    k = np.arange(1, samples + 1)[:, None]
    return (0.5 + k * np.array([1 / g, 1 / (g * g)])) % 1.0


def light_patterns(key, index, samples):
    """(S,) int64: per sample, the pattern (0 .. samples - 1) it samples area light through:
    its position `index` in the texel, permuted by a pseudo-random permutation per texel
    (`key` (S,): a number naming each sample's texel). Where a sample sits in its texel must
    say nothing about where it looks on a sun's disk or a lamp: tied together (the same offset
    for both), a sample on a texel's lit side also looked at the lamp's far side, and penumbrae
    came out wider (a sun's edge in the room of bench/lightmap_cycles.py: 0.27 against Cycles'
    0.19 on its dark side). One permutation for all texels cannot part them along every axis
    with 4 samples; one per texel does on average (room, 128 x 128: 1.24 % off Cycles against
    1.45 %). A texel's samples still take every pattern once."""
    key, index = np.asarray(key, np.int64), np.asarray(index, np.int64)
    if samples <= 1 or not len(key):
        return index
    if samples > 8:  # one permutation per texel, not per sample
        key, of_sample = np.unique(key, return_inverse=True)
    else:
        of_sample = np.arange(len(key))
    hashes = _mixed(key.astype(np.uint64)[:, None] * np.uint64(samples) + np.arange(samples, dtype=np.uint64))
    return np.argsort(hashes, axis=1)[of_sample.reshape(-1), index]


def _mixed(x):
    """SplitMix64's finaliser (Steele et al. 2014): well-spread 64-bit hashes of uint64 keys
    (wrapping multiplication, as intended)."""
    x = x + np.uint64(0x9E3779B97F4A7C15)
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def _texel_places(texel, triangle, tri, resolution):
    """Per sample, its texel named the same wherever an atlas slot moves the layout by whole
    texels: the texel's lowest triangle and its column and row relative to that triangle's
    UV box, (S,) each (so a target bakes the same in an atlas as alone)."""
    first = np.full(resolution * resolution, np.iinfo(np.int64).max)
    np.minimum.at(first, texel, triangle)
    owner = first[texel]
    anchor = np.floor(tri.min(axis=1)).astype(np.int64)[owner]
    return owner, texel % resolution - anchor[:, 0], texel // resolution - anchor[:, 1]


def _texel_keys(owner, dx, dy):
    """(S,) int64: one number per texel place (`_texel_places`)."""
    return (owner * 4096 + dy) * 4096 + dx


def texel_space(uv, resolution):
    """UV (..., 2) -> texel-space (x, y) = (u R, (1 - v) R)."""
    uv = np.asarray(uv, dtype=np.float64)
    return np.stack([uv[..., 0] * resolution, (1.0 - uv[..., 1]) * resolution], axis=-1)


def barycentric(tri, p):
    """Barycentric weights (K, 3) of points p (K, 2) in triangles tri (K, 3, 2)."""
    return np.stack(_Corners(tri).weights(p[:, 0], p[:, 1]), axis=1)


class _Corners:
    """Triangles (K, 3, 2) as columns, for barycentric weights at many points per triangle."""

    def __init__(self, tri):
        (self.ax, self.ay), (self.bx, self.by), (self.cx, self.cy) = (tri[:, k].T for k in range(3))
        self.area = (self.bx - self.ax) * (self.cy - self.ay) - (self.by - self.ay) * (self.cx - self.ax)

    def weights(self, px, py):
        """(wa, wb, wc) at points (px, py), each (K,) or (K, n): n points per triangle."""
        column = (slice(None),) + (None,) * (np.ndim(px) - 1)
        ax, ay, bx, by, cx, cy, area = (v[column] for v in (self.ax, self.ay, self.bx, self.by, self.cx, self.cy,
                                                               self.area))
        bx, by, cx, cy = bx - px, by - py, cx - px, cy - py
        wa = (bx * cy - by * cx) / area
        wb = (cx * (ay - py) - cy * (ax - px)) / area
        return wa, wb, 1.0 - wa - wb


def _all_above(weights, limit, inclusive=False):
    """Where every one of the weights (columns) is above `limit` (or equal, when inclusive)."""
    above = np.greater_equal if inclusive else np.greater
    return above(weights[0], limit) & above(weights[1], limit) & above(weights[2], limit)


def _cross(a, b):
    return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]


def closest_barycentric(tri, p):
    """Barycentric weights of the point of each triangle nearest to p (K, 2)."""
    w = barycentric(tri, p)
    best = w.copy()
    best_d = np.where((w >= 0).all(axis=1), 0.0, np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        e = tri[:, j] - tri[:, i]
        t = np.clip(((p - tri[:, i]) * e).sum(1) / np.maximum((e * e).sum(1), 1e-300), 0.0, 1.0)
        d = (((tri[:, i] + t[:, None] * e) - p) ** 2).sum(1)
        better = d < best_d
        cand = np.zeros_like(w)
        cand[:, i], cand[:, j] = 1.0 - t, t
        best[better], best_d[better] = cand[better], d[better]
    return best


def _overlaps_square(tri, corner):
    """Whether each triangle (K, 3, 2) overlaps the unit square at corner (K, 2) with positive
    area (separating axes: the square's are covered by the candidates' bounding boxes). Column
    by column: numpy reduces a short last axis far slower than it combines columns."""
    hit = np.ones(len(tri), bool)
    x, y = tri[:, :, 0], tri[:, :, 1]
    for i, j in ((0, 1), (1, 2), (2, 0)):
        nx, ny = y[:, i] - y[:, j], x[:, j] - x[:, i]  # the edge's normal
        t = [x[:, k] * nx + y[:, k] * ny for k in range(3)]
        # the square's extent along the normal: its corner's, plus the positive parts of nx, ny
        s_lo = corner[:, 0] * nx + corner[:, 1] * ny + np.minimum(nx, 0.0) + np.minimum(ny, 0.0)
        s_hi = s_lo + np.abs(nx) + np.abs(ny)
        t_lo, t_hi = np.minimum(np.minimum(t[0], t[1]), t[2]), np.maximum(np.maximum(t[0], t[1]), t[2])
        hit &= (np.minimum(t_hi, s_hi) - np.maximum(t_lo, s_lo)) > _EPS * (np.abs(nx) + np.abs(ny))
    return hit


def rasterize(uv, resolution, samples, check=None, only=None):
    """Samples of every texel that the triangles' UVs (M, 3, 2) reach; see `Texels`. `check`:
    called between chunks (a cancel raises there). only: (R * R,) bool, the texels to sample
    (None: all); `coverage` and `island` then hold those texels only."""
    r = int(resolution)
    tri = texel_space(uv, r)
    area = np.abs(_cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]))
    lo = np.clip(np.floor(tri.min(axis=1)), 0, r).astype(np.int64)
    hi = np.clip(np.ceil(tri.max(axis=1)), 0, r).astype(np.int64)
    size = np.where(area[:, None] > 1e-12, np.maximum(hi - lo, 0), 0)
    count = size[:, 0] * size[:, 1]
    offs = offsets(samples)
    keys, tris, bary, touched_t, touched_tri = [], [], [], [], []
    strict_keys = []
    coverage = np.zeros(r * r, bool)
    ends = np.cumsum(count)
    start = 0
    while start < len(tri):
        if check is not None:
            check()
        stop = int(np.searchsorted(ends, (ends[start - 1] if start else 0) + _CANDIDATES_PER_CHUNK, side="right"))
        stop = max(stop, start + 1)
        t_idx = np.repeat(np.arange(start, stop), count[start:stop])
        first = np.repeat(np.cumsum(count[start:stop]) - count[start:stop], count[start:stop])
        k = np.arange(len(t_idx)) - first
        cx = lo[t_idx, 0] + k % np.maximum(size[t_idx, 0], 1)
        cy = lo[t_idx, 1] + k // np.maximum(size[t_idx, 0], 1)
        cell = cy * r + cx
        if only is not None:
            wanted = only[cell]
            t_idx, cell, cx, cy = t_idx[wanted], cell[wanted], cx[wanted], cy[wanted]
        corners = tri[t_idx]
        columns = _Corners(corners)
        x, y = cx.astype(np.float64), cy.astype(np.float64)
        coverage[cell[_all_above(columns.weights(x + 0.5, y + 0.5), -_EPS, inclusive=True)]] = True
        hit_any = np.zeros(len(t_idx), bool)
        block = max(1, _CANDIDATES_PER_CHUNK // max(len(t_idx), 1))  # offsets at a time: (candidates, block) arrays
        for first in range(0, len(offs), block):
            if check is not None:
                check()
            j = np.arange(first, min(first + block, len(offs)))
            w = columns.weights(x[:, None] + offs[j, 0], y[:, None] + offs[j, 1])
            inside = _all_above(w, -_EPS, inclusive=True)
            hit_any |= inside.any(axis=1)
            row, col = np.nonzero(inside)  # candidate-major: a sample in two triangles keeps the first's
            keys.append(cell[row] * len(offs) + j[col])
            strict = np.nonzero(_all_above(w, 1e-6))
            strict_keys.append(cell[strict[0]] * len(offs) + j[strict[1]])
            tris.append(t_idx[row])
            bary.append(np.stack([v[row, col] for v in w], axis=1))
        rest = ~hit_any
        rest[rest] = _overlaps_square(corners[rest], np.stack([cx[rest], cy[rest]], axis=1).astype(np.float64))
        touched_t.append(cell[rest])
        touched_tri.append(t_idx[rest])
        start = stop
    keys, tris, bary = np.concatenate(keys), np.concatenate(tris), np.concatenate(bary)
    strict = np.concatenate(strict_keys)
    overlapping = int((np.bincount(strict, minlength=r * r * len(offs)) > 1).sum())
    order = np.argsort(keys, kind="stable")  # a sample on a shared edge: the first triangle's
    first = order[np.r_[True, keys[order][1:] != keys[order][:-1]]] if len(keys) else order
    keys = keys[first]
    texel, tris, bary, index = keys // len(offs), tris[first], bary[first], keys % len(offs)
    # texels touched by a triangle but holding no sample: the triangle's point nearest the centre
    t_cells, t_tris = np.concatenate(touched_t), np.concatenate(touched_tri)
    has_sample = np.zeros(r * r, bool)
    has_sample[texel] = True
    keep = ~has_sample[t_cells]
    t_cells, where = np.unique(t_cells[keep], return_index=True)
    t_tris = t_tris[keep][where]
    centres = np.stack([t_cells % r + 0.5, t_cells // r + 0.5], axis=1).astype(np.float64)
    t_bary = closest_barycentric(tri[t_tris], centres)
    texel = np.concatenate([texel, t_cells])
    island = np.zeros(r * r, bool)
    island[texel] = True
    index = np.concatenate([index, np.zeros(len(t_cells), np.int64)])
    triangles = np.concatenate([tris, t_tris])
    owner, dx, dy = _texel_places(texel, triangles, tri, r)
    light = light_patterns(_texel_keys(owner, dx, dy), index, len(offs))
    return Texels(texel=texel, triangle=triangles, bary=np.concatenate([bary, t_bary]),
                  coverage=coverage.reshape(r, r), island=island.reshape(r, r), index=index,
                  overlapping=int(overlapping), light=light, tilt=tilts.classes(dx, dy, light))
