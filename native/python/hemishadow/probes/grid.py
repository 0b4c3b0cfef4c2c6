"""Probe grids: where a Blender Light Probe Volume puts its samples, and grid index <-> world.

Blender (EEVEE, `lightprobe_volume_grid_sample_position`) places sample i of N along an axis
at local (i + 1) / (N + 1) * 2 - 1 of the volume object's [-1, 1] cube: one spacing inside
each face, never on it. `volume_matrix` folds that into one 4x4 "grid index -> world"
matrix, rotation and non-uniform scale of the object included.
"""

import numpy as np


def resolution3(resolution):
    """(3,) int64 of positive sample counts, or a ValueError."""
    res = np.asarray(resolution)
    if res.shape != (3,) or res.dtype.kind not in "iu":
        raise ValueError(f"grid resolution must be 3 integers (x, y, z), got {resolution!r}")
    if (res < 1).any():
        raise ValueError(f"grid resolution must be at least 1 on every axis, got {res.tolist()}")
    return res.astype(np.int64)


def matrix4(matrix, what="grid matrix"):
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4) or not np.isfinite(m).all():
        raise ValueError(f"{what} must be a finite 4x4 matrix, got shape {m.shape}")
    if abs(np.linalg.det(m[:3, :3])) < 1e-300:
        raise ValueError(f"{what} is singular")
    return m


def volume_matrix(object_matrix, resolution):
    """Grid index -> world (4, 4) of a Light Probe Volume with world matrix `object_matrix`."""
    res = resolution3(resolution)
    step = 2.0 / (res + 1)
    local = np.eye(4)
    local[:3, :3] = np.diag(step)
    local[:3, 3] = step - 1.0
    return matrix4(object_matrix, "volume matrix") @ local


def bounds_matrix(lo, hi, resolution):
    """Grid index -> world (4, 4) of a grid filling the box [lo, hi] (an Empty's bounds)
    the way a Light Probe Volume of that box fills it."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    if not (hi > lo).all():
        raise ValueError(f"bounds must have positive size, got {lo.tolist()} .. {hi.tolist()}")
    obj = np.eye(4)
    obj[:3, :3] = np.diag((hi - lo) / 2)
    obj[:3, 3] = (hi + lo) / 2
    return volume_matrix(obj, resolution)


def grid_points(matrix, resolution):
    """World positions (X*Y*Z, 3) of the grid's probes, C order of (x, y, z) indices."""
    m, res = matrix4(matrix), resolution3(resolution)
    index = np.stack(np.meshgrid(*[np.arange(n) for n in res], indexing="ij"), axis=-1).reshape(-1, 3)
    return index @ m[:3, :3].T + m[:3, 3]


def grid_coordinates(matrix, points):
    """Continuous grid indices (Q, 3) of world points."""
    m = np.linalg.inv(matrix4(matrix))
    return np.asarray(points, dtype=np.float64) @ m[:3, :3].T + m[:3, 3]


def flat_index(index, resolution):
    """C-order probe number of integer indices (..., 3)."""
    return (index[..., 0] * resolution[1] + index[..., 1]) * resolution[2] + index[..., 2]


def corners(matrix, resolution, points):
    """The 8 probes around each point and their trilinear weights: ids (Q, 8), weights (Q, 8).
    Points outside the grid take the nearest face's values (clamped)."""
    res = resolution3(resolution)
    g = np.clip(grid_coordinates(matrix, points), 0, res - 1)
    base = np.minimum(np.floor(g).astype(np.int64), np.maximum(res - 2, 0))
    frac = np.where(res > 1, g - base, 0.0)
    ids, weights = [], []
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                d = np.array([dx, dy, dz])
                idx = np.minimum(base + d, res - 1)
                w = np.prod(np.where(d == 1, frac, 1 - frac), axis=1)
                ids.append(flat_index(idx, res))
                weights.append(w)
    return np.stack(ids, 1), np.stack(weights, 1)
