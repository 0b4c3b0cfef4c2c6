"""8-bit encodings of HDR maps for engines without float textures: RGBM and LogLuv (RGBA8),
and a dependency-free PNG writer (atomic, like the EXR writer).

RGBM (range R, default 8): a = ceil(max(r, g, b) / R * 255) / 255, rgb' = rgb / (a R);
decode rgb = rgb' * a * R. Values above R are clipped; linear, no gamma.
LogLuv (Ward's LogLuv as used in real-time engines): with the matrix M below,
(X', Y, Z') = rgb M; (u, v) = (X', Y) / Z'; Le = 2 log2(Y) + 127, split into a high byte
z = floor(Le) / 255 and a low byte w = frac(Le); decode Le = 255 z + w (stored bytes / 255),
Y = 2^((Le - 127) / 2), Z' = Y / v, X' = u Z', rgb = max((X', Y, Z') M^-1, 0). Covers
luminance 2^-63.5 .. 2^64 with about 0.3 % steps.
"""

import os
import tempfile

import numpy as np

from .. import png

LOGLUV_M = np.array([[0.2209, 0.3390, 0.4184], [0.1138, 0.6780, 0.7319], [0.0102, 0.1130, 0.2969]])
LOGLUV_M_INV = np.linalg.inv(LOGLUV_M)


def _bytes(values):
    return np.clip(np.round(values * 255.0), 0, 255).astype(np.uint8)


def rgbm_encode(rgb, max_range=8.0):
    """(H, W, 3) float -> (H, W, 4) uint8."""
    rgb = np.clip(np.asarray(rgb, np.float64) / max_range, 0.0, 1.0)
    a = np.ceil(np.clip(rgb.max(axis=-1), 1e-6, 1.0) * 255.0) / 255.0
    return np.concatenate([_bytes(rgb / a[..., None]), _bytes(a)[..., None]], axis=-1)


def rgbm_decode(rgbm, max_range=8.0):
    x = np.asarray(rgbm, np.float64) / 255.0
    return (x[..., :3] * x[..., 3:4] * max_range).astype(np.float32)


def logluv_encode(rgb):
    """(H, W, 3) float -> (H, W, 4) uint8."""
    xyz = np.maximum(np.asarray(rgb, np.float64) @ LOGLUV_M, 1e-6)
    uv = xyz[..., :2] / xyz[..., 2:3]
    le = np.clip(2.0 * np.log2(xyz[..., 1]) + 127.0, 0.0, 255.0 + 254.0 / 255.0)
    high = np.floor(le)
    low = le - high
    return np.concatenate([_bytes(np.clip(uv, 0, 1)), high[..., None].astype(np.uint8), _bytes(low)[..., None]],
                          axis=-1)


def logluv_decode(logluv):
    x = np.asarray(logluv, np.float64)
    le = x[..., 2] + x[..., 3] / 255.0
    y = np.exp2((le - 127.0) / 2.0)
    u, v = x[..., 0] / 255.0, np.maximum(x[..., 1] / 255.0, 1e-6)
    z = y / v
    xyz = np.stack([u * z, y, z], axis=-1)
    return np.maximum(xyz @ LOGLUV_M_INV, 0.0).astype(np.float32)


def write_png(path, rgba):
    """An (H, W, 4) uint8 image as an 8-bit RGBA PNG, rows top to bottom; atomically."""
    rgba = np.ascontiguousarray(rgba, dtype=np.uint8)
    if rgba.ndim != 3 or rgba.shape[2] != 4:
        raise ValueError(f"write_png: expected (H, W, 4) uint8, got {rgba.shape}")
    data = png.encode(rgba)
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tmp-", suffix=".png")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
