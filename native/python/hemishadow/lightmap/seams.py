"""Seams: the two sides of a UV seam of one surface read the same values.

A seam edge joins two triangles that share its vertices but not its UVs. Points along it
(half a texel apart) have one texel-space position on each side; the bilinear lookups there
(what a renderer reads) are made equal by least squares on the texels of both footprints,
changing nothing else (Jacobi iterations of the normal equations; a lone pair of texels meets at
its mean in one step).
"""

import numpy as np

from .texels import texel_space


def seam_points(triangles, uv, resolution, spacing=0.5):
    """Texel-space positions (K, 2) on side A and (K, 2) on side B of every seam edge."""
    tris = np.asarray(triangles, dtype=np.int64)
    edges = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    ends = np.concatenate([uv[:, [0, 1]], uv[:, [1, 2]], uv[:, [2, 0]]])  # (3M, 2, 2)
    swap = edges[:, 0] > edges[:, 1]
    edges[swap] = edges[swap][:, ::-1]
    ends[swap] = ends[swap][:, ::-1]
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, ends = edges[order], ends[order]
    same = (edges[1:] == edges[:-1]).all(axis=1)
    single = same & np.r_[True, ~same[:-1]] & np.r_[~same[1:], True]  # exactly two triangles
    a, b = ends[:-1][single], ends[1:][single]
    seam = np.abs(a - b).max(axis=(1, 2)) > 1e-7
    a, b = texel_space(a[seam], resolution), texel_space(b[seam], resolution)
    length = np.maximum(np.linalg.norm(a[:, 1] - a[:, 0], axis=1), np.linalg.norm(b[:, 1] - b[:, 0], axis=1))
    count = np.maximum(np.ceil(length / spacing).astype(np.int64), 1)
    edge = np.repeat(np.arange(len(a)), count)
    t = ((np.arange(len(edge)) - np.repeat(np.cumsum(count) - count, count)) + 0.5) / count[edge]
    at = a[edge, 0] + t[:, None] * (a[edge, 1] - a[edge, 0])
    bt = b[edge, 0] + t[:, None] * (b[edge, 1] - b[edge, 0])
    return at, bt


def footprint(points, resolution):
    """Bilinear lookup at texel-space points (K, 2): flat texel indices (K, 4) and weights."""
    f = points - 0.5
    c0 = np.floor(f).astype(np.int64)
    w = f - c0
    idx, wts = [], []
    for dy in (0, 1):
        for dx in (0, 1):
            col = np.clip(c0[:, 0] + dx, 0, resolution - 1)
            row = np.clip(c0[:, 1] + dy, 0, resolution - 1)
            idx.append(row * resolution + col)
            wts.append((w[:, 0] if dx else 1 - w[:, 0]) * (w[:, 1] if dy else 1 - w[:, 1]))
    return np.stack(idx, axis=1), np.stack(wts, axis=1)


def lookup(values, points):
    """Bilinear values (K, C) of an (R, R, C) map at texel-space points."""
    idx, w = footprint(points, values.shape[0])
    flat = values.reshape(-1, values.shape[2])
    return (flat[idx] * w[..., None]).sum(axis=1)


def stitch(values, known, a, b, iterations=200, tolerance=1e-6, check=None):
    """Makes the bilinear lookups at `a` and `b` agree with the least change to the known
    texels (x = x0 - A^T (A A^T)^-1 A x0, A the lookup differences; conjugate gradients on
    A A^T). Unknown texels stay as they are. In place. `check`:
    called each iteration (a cancel raises there)."""
    if not len(a):
        return
    r = values.shape[0]
    flat = values.reshape(-1, values.shape[2])
    ia, wa = footprint(a, r)
    ib, wb = footprint(b, r)
    free = known.reshape(-1)
    idx = np.concatenate([ia, ib], axis=1)                              # (K, 8)
    wts = np.concatenate([wa * free[ia], -wb * free[ib]], axis=1)      # only known texels move

    def spread(lam):  # A^T lam: (T, C)
        return np.stack([np.bincount(idx.ravel(), (wts[..., None] * lam[:, None, c:c + 1]).ravel(), r * r)
                         for c in range(lam.shape[1])], axis=1)

    def apply(z):  # A z: (K, C)
        return (z[idx] * wts[..., None]).sum(axis=1)

    rhs = lookup(values, a) - lookup(values, b)
    scale = max(np.abs(flat).max(), 1e-30)
    lam = np.zeros_like(rhs)
    res = rhs.copy()
    direction = res.copy()
    rho = (res * res).sum(axis=0)
    for _ in range(iterations):
        if check is not None:
            check()
        if np.sqrt(rho.max()) <= tolerance * scale:
            break
        q = apply(spread(direction)) + 1e-9 * direction
        alpha = rho / np.maximum((direction * q).sum(axis=0), 1e-300)
        lam += alpha * direction
        res -= alpha * q
        new_rho = (res * res).sum(axis=0)
        direction = res + (new_rho / np.maximum(rho, 1e-300)) * direction
        rho = new_rho
    flat -= spread(lam)
