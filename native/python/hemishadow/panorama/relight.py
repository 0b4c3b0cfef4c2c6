"""Relighting a baked panorama in the engine (Rust: AVX2 when the CPU has it, all cores):
outgoing radiance = sum_i c_i L_i per pixel, suns and environments folded into one linear
combination of the maps, point lights evaluated per pixel from the position map.

maps: "8bit" reads the compact form's bytes (scale and offset folded into the weights),
"float16" the EXR's half floats; None picks 8bit for a panorama loaded from the compact form,
float16 otherwise.
"""

import numpy as np

from .. import _native
from .compact import quantize
from .lights import weights

MAPS = ("8bit", "float16")


def make_relighter(panorama, maps):
    """The engine's Relighter over the panorama's maps in the given storage."""
    h, w, k = panorama.height, panorama.width, panorama.coefficient_count
    position = np.ascontiguousarray(panorama.position, dtype=np.float32)
    hit = np.ascontiguousarray(panorama.mask)
    rotation = np.ascontiguousarray(panorama.rotation, dtype=np.float64)
    if maps == "8bit":
        if panorama.quantized is not None:
            q, scale, offset = panorama.quantized
        else:
            parts = [quantize(panorama.coefficients[:, :, i, :]) for i in range(k)]
            q = np.stack([p[0] for p in parts])
            scale = np.stack([p[1] for p in parts])
            offset = np.stack([p[2] for p in parts])
        return _native.Relighter(np.ascontiguousarray(q, dtype=np.uint8), None, np.ascontiguousarray(scale, np.float32),
                                 np.ascontiguousarray(offset, np.float32), position, hit, rotation)
    if maps == "float16":
        half = np.ascontiguousarray(np.moveaxis(panorama.coefficients, 2, 0).astype(np.float16)).view(np.uint16)
        return _native.Relighter(None, half, None, None, position, hit, rotation)
    raise ValueError(f"maps must be one of {MAPS}, got {maps!r}")


def relight(panorama, lights, *, exposure=0.0, background=None, maps=None, bounce=False, out=None, simd=True):
    """Linear radiance (H, W, 3) float32 of the panorama under `lights` (Sun, Point,
    Environment; summed), times 2^exposure.

    background: None (background pixels show the environments' SH in their direction, black
    for lamps) or an (H, W, 3) image for them (e.g. the HDRI itself). bounce: add the baked
    bounce term. out: an (H, W, 3) float32 array to fill (no allocation per frame).
    simd=False forces the portable code (the same result to the bit).
    """
    if maps is None:
        maps = "8bit" if panorama.quantized is not None else "float16"
    if not np.isfinite(exposure):
        raise ValueError(f"exposure must be finite, got {exposure!r}")
    scale = float(2.0 ** exposure)
    uniform, points, background_sh = weights(list(lights), panorama.coefficient_count, scale)
    engine = panorama.relighter(maps)
    image = engine.relight(uniform, points, background_sh if background_sh.any() else None, out, simd)
    if bounce:
        if panorama.bounce is None:
            raise ValueError("this panorama has no bounce term")
        image += panorama.bounce * np.float32(scale)
    if background is not None:
        bg = np.asarray(background, dtype=np.float32)
        if bg.shape != image.shape:
            raise ValueError(f"background must have shape {image.shape}, got {bg.shape}")
        miss = ~panorama.mask
        image[miss] = bg[miss] * np.float32(scale)
    return image
