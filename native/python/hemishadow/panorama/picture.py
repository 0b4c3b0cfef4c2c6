"""Relit pictures to files: float EXR (linear radiance R, G, B) or an 8-bit sRGB PNG with
Blender's Standard view transform (clip to 0..1, the sRGB transfer function, no look), and
sampling an equirectangular HDRI in given directions (background pixels)."""

import os

import numpy as np

from .. import png


def srgb(linear):
    """Blender's Standard view transform of linear values: sRGB-encoded 8-bit."""
    x = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    encoded = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.rint(encoded * 255.0).astype(np.uint8)


def write(path, image):
    """`*.exr` (float32 R, G, B) or `*.png` (sRGB, Standard view); atomic either way."""
    from ..environment import _atomic_write, write_exr

    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    try:
        if ext == ".exr":
            write_exr(path, {"": np.asarray(image, np.float32)})
        elif ext == ".png":
            data = png.encode(srgb(image))

            def put(tmp):
                with open(tmp, "wb") as f:
                    f.write(data)

            _atomic_write(path, put)
        else:
            raise ValueError(f"{path}: the output must be .exr (linear) or .png (sRGB)")
    except OSError as exc:
        raise ValueError(f"cannot write {path}: {exc.strerror or exc}") from None


def sample_equirectangular(image, directions, rotation=None):
    """Nearest pixels of an equirectangular image (H, W, 3) seen along world `directions`
    (..., 3), mapped as Blender's Environment Texture maps them; `rotation` (3x3) is the
    World's Mapping node (the lookup vector is rotated before sampling)."""
    d = np.asarray(directions, dtype=np.float64)
    if rotation is not None:
        d = d @ np.asarray(rotation, dtype=np.float64).T
    u = -np.arctan2(d[..., 1], d[..., 0]) / (2 * np.pi) + 0.5
    v = np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1])) / np.pi + 0.5
    h, w = image.shape[:2]
    col = np.clip((u * w).astype(np.int64), 0, w - 1)
    row = np.clip(((1.0 - v) * h).astype(np.int64), 0, h - 1)
    return np.asarray(image, np.float32)[row, col, :3]
