"""Environment maps: reading and writing OpenEXR files, and the HDRIs that ship with Blender.

Images are float32 arrays of shape (H, W, 3); row 0 is the top row of the image as
stored in the file (the first row of its data window), column 0 its left edge.
"""

from __future__ import annotations

import glob
import importlib.util
import os
import pathlib
import tempfile

import numpy as np

__all__ = ["read_exr", "write_exr", "builtin_hdris", "default_hdri"]

# Preferred default lighting, first existing one wins.
_DEFAULT_ORDER = ("forest", "courtyard", "city", "sunrise", "sunset", "interior", "studio", "night")


def read_exr(path) -> np.ndarray:
    """Read the R, G, B channels of an EXR file as float32 (H, W, 3)."""
    import OpenEXR

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ValueError(f"{path}: no such EXR file")
    try:
        # separate_channels=True gives plain "R", "G", "B" keys; the default groups
        # them into one "RGB"/"RGBA" array (or "layer" for "layer.R" ...).
        with OpenEXR.File(path, separate_channels=True) as exr:
            channels = {name: ch.pixels for name, ch in exr.channels().items()}
    except Exception as exc:  # OpenEXR raises RuntimeError with a cluttered message
        raise ValueError(f"{path}: not a readable OpenEXR file ({exc})") from None
    missing = [c for c in "RGB" if c not in channels]
    if missing:
        raise ValueError(
            f"{path}: no {','.join(missing)} channel(s); found {sorted(channels)}")
    rgb = [np.asarray(channels[c]) for c in "RGB"]
    if any(c.ndim != 2 or c.shape != rgb[0].shape for c in rgb):
        raise ValueError(f"{path}: R, G, B channels differ in size (subsampled channels?)")
    return np.ascontiguousarray(np.stack(rgb, axis=-1), dtype=np.float32)


def write_exr(path, channels: dict) -> None:
    """Write 2-D float channels {name: (H, W)} as a float32 EXR, atomically.

    A (H, W, 3) or (H, W, 4) array under one name is split into name.R, name.G, ...
    (plain R, G, B, A when the name is empty).
    """
    import OpenEXR

    flat = {}
    for name, data in channels.items():
        data = np.asarray(data, dtype=np.float32)
        if data.ndim == 3 and data.shape[2] in (3, 4):
            for i, c in enumerate("RGBA"[: data.shape[2]]):
                flat[f"{name}.{c}" if name else c] = data[..., i]
        elif data.ndim == 2:
            flat[name] = data
        else:
            raise ValueError(f"channel {name!r}: expected a 2-D array, got shape {data.shape}")
    if not flat:
        raise ValueError("write_exr: no channels given")
    shapes = {a.shape for a in flat.values()}
    if len(shapes) != 1:
        raise ValueError(f"write_exr: channels differ in size: {sorted(shapes)}")
    flat = {k: np.ascontiguousarray(v) for k, v in flat.items()}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    _atomic_write(path, lambda tmp: OpenEXR.File(header, flat).write(tmp))


def _atomic_write(path, write) -> None:
    """Call write(tmp_path) on a temp file beside path, then rename it into place,
    so readers never see a half-written file."""
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tmp-", suffix=os.path.splitext(path)[1])
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def builtin_hdris() -> dict[str, pathlib.Path]:
    """Name -> path of the studio-light HDRIs shipped with the `bpy` module ({} without bpy).

    Found through the package's location, without importing bpy (slow, heavy).
    """
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        return {}
    found = {}
    for root in spec.submodule_search_locations:
        # e.g. site-packages/bpy/5.0/datafiles/studiolights/world/forest.exr
        for p in sorted(glob.glob(os.path.join(root, "*", "datafiles", "studiolights", "world", "*.exr"))):
            found.setdefault(pathlib.Path(p).stem, pathlib.Path(p))
    return found


def default_hdri() -> pathlib.Path:
    """The default lighting: Blender's "forest" HDRI (or another shipped one)."""
    hdris = builtin_hdris()
    if not hdris:
        raise FileNotFoundError(
            "no default environment map: the `bpy` module (which ships Blender's HDRIs) "
            "is not installed; pass an EXR file explicitly")
    for name in _DEFAULT_ORDER:
        if name in hdris:
            return hdris[name]
    return next(iter(hdris.values()))
