"""Multi-layer OpenEXR files of baked maps, written atomically (temp file + os.replace).

RGB float32 layers `flat`, `b0`, `b1`, `b2`, `sh0`..`sh3` (channels flat.R, flat.G, flat.B,
...) and single-channel float32 layers `ao` and `coverage`; rows top to bottom, texel
(r, c) at u = (c + 0.5) / R, v = 1 - (r + 0.5) / R.
"""

import numpy as np

from ..environment import write_exr

RGB_LAYERS = ("flat", "b0", "b1", "b2", "sh0", "sh1", "sh2", "sh3")
SINGLE_LAYERS = ("ao", "coverage")


def write(path, maps):
    """Writes the maps of one object (a dict from `bake`) to `path`; other keys are ignored."""
    channels = {}
    for name in RGB_LAYERS:
        if name in maps:
            data = np.asarray(maps[name], dtype=np.float32)
            if data.ndim != 3 or data.shape[2] != 3:
                raise ValueError(f"layer {name!r} must be (H, W, 3), got {data.shape}")
            channels[name] = data
    for name in SINGLE_LAYERS:
        if name in maps:
            data = np.asarray(maps[name], dtype=np.float32)
            if data.ndim != 2:
                raise ValueError(f"layer {name!r} must be (H, W), got {data.shape}")
            channels[name] = data
    if not channels:
        raise ValueError(f"{path}: no map to write (expected some of {RGB_LAYERS + SINGLE_LAYERS})")
    write_exr(path, channels)


def read(path):
    """The layers of a file written by `write`: name -> (H, W, 3) or (H, W) float32."""
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as exr:
        channels = {name: np.asarray(ch.pixels, dtype=np.float32) for name, ch in exr.channels().items()}
    out = {}
    for name in RGB_LAYERS:
        if f"{name}.R" in channels:
            out[name] = np.stack([channels[f"{name}.{c}"] for c in "RGB"], axis=-1)
    for name in SINGLE_LAYERS:
        if name in channels:
            out[name] = channels[name]
    return out
