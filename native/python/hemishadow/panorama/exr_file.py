"""The float form of a panorama: one OpenEXR file, written atomically (temp file + rename).

Channels: sh00.R/G/B .. sh{k-1}.R/G/B (HALF), P.X/Y/Z and N.X/Y/Z (FLOAT), depth.Z (FLOAT,
inf for background), A (HALF), optional bounce.R/G/B (HALF); the header attribute
`hemishadow_panorama` holds JSON {"format", "version", "origin", "rotation", "bands"}.
"""

import json
import os

import numpy as np

FORMAT = "hemishadow-panorama"
ATTRIBUTE = "hemishadow_panorama"


def channels(panorama):
    out = {}
    for i in range(panorama.coefficient_count):
        for c, name in enumerate("RGB"):
            out[f"sh{i:02d}.{name}"] = panorama.coefficients[:, :, i, c].astype(np.float16)
    for layer, data in (("P", panorama.position), ("N", panorama.normal)):
        for c, name in enumerate("XYZ"):
            out[f"{layer}.{name}"] = np.ascontiguousarray(data[..., c], dtype=np.float32)
    out["depth.Z"] = np.ascontiguousarray(panorama.depth, dtype=np.float32)
    out["A"] = panorama.alpha.astype(np.float16)
    if panorama.bounce is not None:
        for c, name in enumerate("RGB"):
            out[f"bounce.{name}"] = panorama.bounce[..., c].astype(np.float16)
    return {k: np.ascontiguousarray(v) for k, v in out.items()}


def write(path, panorama):
    import OpenEXR

    from ..environment import _atomic_write

    meta = {"format": FORMAT, "version": 1, "origin": panorama.origin.tolist(),
            "rotation": panorama.rotation.tolist(), "bands": panorama.bands}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, ATTRIBUTE: json.dumps(meta)}
    data = channels(panorama)
    try:
        _atomic_write(path, lambda tmp: OpenEXR.File(header, data).write(tmp))
    except OSError as exc:
        raise ValueError(f"cannot write {os.fspath(path)}: {exc.strerror or exc}") from None
    return {"path": os.fspath(path), "bytes": os.path.getsize(path)}


def read(path):
    import OpenEXR

    from .panorama import Panorama

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ValueError(f"{path}: no such panorama file")
    try:
        with OpenEXR.File(path, separate_channels=True) as exr:
            meta = exr.header().get(ATTRIBUTE)
            ch = {name: np.asarray(c.pixels) for name, c in exr.channels().items()}
    except Exception as exc:
        raise ValueError(f"{path}: not a readable OpenEXR file ({exc})") from None
    if meta is None:
        raise ValueError(f"{path}: not a hemishadow panorama (no {ATTRIBUTE} header attribute)")
    meta = json.loads(meta)
    k = meta["bands"] ** 2
    coefficients = np.stack([np.stack([ch[f"sh{i:02d}.{c}"] for c in "RGB"], -1) for i in range(k)], axis=2)
    rgb = lambda layer, names: np.stack([ch[f"{layer}.{c}"] for c in names], -1).astype(np.float32)  # noqa: E731
    bounce = rgb("bounce", "RGB") if "bounce.R" in ch else None
    return Panorama(coefficients=coefficients.astype(np.float32), position=rgb("P", "XYZ"), normal=rgb("N", "XYZ"),
                    depth=ch["depth.Z"].astype(np.float32), alpha=ch["A"].astype(np.float32), origin=meta["origin"],
                    rotation=meta["rotation"], bands=meta["bands"], bounce=bounce)
