"""Blender's equirectangular mapping of panorama pixels to directions (World HDRIs; a
panoramic camera rotated (90, 0, -90) degrees).

Arrays are (H, W, ...) with row 0 the TOP row. Pixel (r, c) has centre u = (c + 0.5) / W,
v = 1 - (r + 0.5) / H and, in the viewpoint's frame, looks along
    phi = (0.5 - u) 2 pi,  theta = (v - 0.5) pi,
    d = (cos theta cos phi, cos theta sin phi, sin theta):
the centre column looks along +X, the left quarter along +Y, the top row along +Z. A
viewpoint's rotation is a 3x3 matrix whose columns are its frame's X, Y, Z in world.
"""

import numpy as np


def rotation_matrix(rotation):
    """A checked proper rotation (3, 3) float64; identity for None."""
    if rotation is None:
        return np.eye(3)
    r = np.asarray(rotation, dtype=np.float64)
    if r.shape != (3, 3) or not np.isfinite(r).all():
        raise ValueError(f"rotation must be a finite 3x3 matrix, got shape {r.shape}")
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-4) or np.linalg.det(r) < 0:
        raise ValueError("rotation must be a proper rotation matrix (orthonormal, determinant +1)")
    return r


def panorama_size(size):
    """(width, height) checked: positive integers, at most 8192 x 4096."""
    try:
        width, height = (int(s) for s in size)
    except (TypeError, ValueError):
        raise ValueError(f"size must be (width, height), got {size!r}") from None
    if not (1 <= width <= 8192 and 1 <= height <= 4096) or tuple(size) != (width, height):
        raise ValueError(f"size must be two integers, width 1..8192 and height 1..4096, got {size!r}")
    return width, height


def directions(width, height, rotation=None):
    """World directions (H, W, 3) float32 of the pixel centres."""
    width, height = panorama_size((width, height))
    u = (np.arange(width) + 0.5) / width
    v = 1.0 - (np.arange(height) + 0.5) / height
    phi = (0.5 - u) * 2.0 * np.pi
    theta = (v - 0.5) * np.pi
    ct, st = np.cos(theta)[:, None], np.sin(theta)[:, None]
    local = np.stack(np.broadcast_arrays(ct * np.cos(phi)[None, :], ct * np.sin(phi)[None, :], st), axis=-1)
    return (local @ rotation_matrix(rotation).T).astype(np.float32)
