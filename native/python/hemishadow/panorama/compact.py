"""The paper's compact form: k 8-bit RGB PNG maps, each with a per-channel scale and offset
(value = offset + scale * byte / 255), in a folder with panorama.json, written atomically: the
files are built in a temporary folder beside the target, which then becomes the target (or,
if the target folder exists, each file is moved in, the JSON last, so a reader that opens the
JSON never finds a map missing).

Files: shNN.png (linear data, no gamma), alpha.png (255 hit, 0 background), normal.png
(n * 127.5 + 127.5), position.f32 (raw little-endian float32 H x W x 3, row 0 top: point
lights need the precision), bounce.png (optional, with its own scale and offset).
"""

import json
import os
import shutil
import tempfile

import numpy as np

from .. import png

FORMAT = "hemishadow-panorama"


def quantize(values):
    """(H, W, 3) floats -> (bytes (H, W, 3) uint8, scale (3,), offset (3,)); the range holds 0
    so that background pixels stay exact. Error per value <= scale / 510."""
    lo = np.minimum(values.reshape(-1, 3).min(axis=0), 0.0).astype(np.float64)
    hi = np.maximum(values.reshape(-1, 3).max(axis=0), 0.0).astype(np.float64)
    scale = hi - lo
    safe = np.where(scale > 0, scale, 1.0)
    q = np.rint((values - lo) / safe * 255.0)
    return np.clip(q, 0, 255).astype(np.uint8), scale.astype(np.float32), lo.astype(np.float32)


def dequantize(q, scale, offset):
    return (np.asarray(offset, np.float32) + np.asarray(scale, np.float32) * (q.astype(np.float32) / np.float32(255.0)))


def write(path, panorama):
    """Writes the folder of `path` (a .json file); returns sizes and the quantization error."""
    path = os.path.abspath(os.fspath(path))
    folder, name = os.path.split(path)
    parent = os.path.dirname(folder)
    try:
        os.makedirs(parent, exist_ok=True)
        tmp = tempfile.mkdtemp(dir=parent, prefix=".tmp-panorama-")
    except OSError as exc:
        raise ValueError(f"cannot write {path}: {exc.strerror or exc}") from None
    try:
        meta, report = _fill(tmp, name, panorama)
        _move_in(tmp, folder, name)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    report.update(path=path, bytes=sum(os.path.getsize(os.path.join(folder, f)) for f in report["files"]))
    return report


def _fill(tmp, name, panorama):
    """Writes every file into tmp; returns (the JSON dict, a report)."""
    h, w, k = panorama.height, panorama.width, panorama.coefficient_count
    maps, files, worst = [], [], 0.0
    mask = panorama.mask
    for i in range(k):
        values = panorama.coefficients[:, :, i, :]
        q, scale, offset = quantize(values)
        error = np.abs(dequantize(q, scale, offset) - values)[mask]
        worst = max(worst, float(error.max()) if error.size else 0.0)
        files.append(_put(tmp, f"sh{i:02d}.png", png.encode(q)))
        maps.append({"file": files[-1], "scale": scale.tolist(), "offset": offset.tolist()})
    files.append(_put(tmp, "alpha.png", png.encode(np.where(mask, 255, 0).astype(np.uint8))))
    normal = np.clip(np.rint(panorama.normal * 127.5 + 127.5), 0, 255).astype(np.uint8)
    files.append(_put(tmp, "normal.png", png.encode(normal)))
    files.append(_put(tmp, "position.f32", np.ascontiguousarray(panorama.position, dtype="<f4").tobytes()))
    meta = {"format": FORMAT, "version": 1, "width": w, "height": h, "bands": panorama.bands, "coefficients": k,
            "origin": panorama.origin.tolist(), "rotation": panorama.rotation.tolist(), "maps": maps,
            "position": {"file": "position.f32"}, "alpha": {"file": "alpha.png"}, "normal": {"file": "normal.png"}}
    if panorama.bounce is not None:
        q, scale, offset = quantize(panorama.bounce)
        files.append(_put(tmp, "bounce.png", png.encode(q)))
        meta["bounce"] = {"file": "bounce.png", "scale": scale.tolist(), "offset": offset.tolist()}
    files.append(_put(tmp, name, json.dumps(meta, indent=1).encode()))
    map_bytes = sum(os.path.getsize(os.path.join(tmp, m["file"])) for m in maps)
    return meta, {"files": files, "map_bytes": map_bytes, "max_quantization_error": worst}


def _put(folder, name, data):
    with open(os.path.join(folder, name), "wb") as f:
        f.write(data)
    return name


def _move_in(tmp, folder, name):
    if not os.path.exists(folder):
        os.replace(tmp, folder)
        return
    if not os.path.isdir(folder):
        raise ValueError(f"cannot write {os.path.join(folder, name)}: {folder} is not a folder")
    for f in sorted(os.listdir(tmp), key=lambda f: f == name):  # the JSON last
        os.replace(os.path.join(tmp, f), os.path.join(folder, f))
    os.rmdir(tmp)


def read(path):
    from .panorama import Panorama

    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    try:
        with open(path, "rb") as f:
            meta = json.loads(f.read())
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: not a readable panorama JSON ({exc})") from None
    if meta.get("format") != FORMAT:
        raise ValueError(f"{path}: not a hemishadow panorama (format {meta.get('format')!r})")
    h, w, k = meta["height"], meta["width"], meta["coefficients"]

    def load(entry):
        with open(os.path.join(folder, entry["file"]), "rb") as f:
            return png.decode(f.read(), entry["file"])

    q = np.stack([load(m) for m in meta["maps"]])  # (k, H, W, 3)
    if q.shape != (k, h, w, 3):
        raise ValueError(f"{path}: maps of shape {q.shape[1:]}, expected ({h}, {w}, 3)")
    scale = np.asarray([m["scale"] for m in meta["maps"]], np.float32)
    offset = np.asarray([m["offset"] for m in meta["maps"]], np.float32)
    coefficients = np.stack([dequantize(q[i], scale[i], offset[i]) for i in range(k)], axis=2)
    position = np.fromfile(os.path.join(folder, meta["position"]["file"]), dtype="<f4")
    if position.size != h * w * 3:
        raise ValueError(f"{path}: position.f32 holds {position.size} values, expected {h * w * 3}")
    position = position.reshape(h, w, 3).astype(np.float32)
    alpha = (load(meta["alpha"]) > 127).astype(np.float32)
    normal = load(meta["normal"]).astype(np.float32) / 127.5 - 1.0 if "normal" in meta else np.zeros_like(position)
    origin = np.asarray(meta["origin"], np.float64)
    depth = np.where(alpha > 0, np.linalg.norm(position - origin.astype(np.float32), axis=-1), np.inf).astype(np.float32)
    bounce = dequantize(load(meta["bounce"]), meta["bounce"]["scale"], meta["bounce"]["offset"]) if "bounce" in meta else None
    return Panorama(coefficients=coefficients, position=position, normal=normal, depth=depth, alpha=alpha,
                    origin=origin, rotation=meta["rotation"], bands=meta["bands"], bounce=bounce,
                    quantized=(np.ascontiguousarray(q), scale, offset))
