"""8-bit PNG files without dependencies (Blender's Python has no Pillow, and the extension
ships no image library): grey, RGB or RGBA, data as stored (no gAMA, sRGB or iCCP chunk);
read back only filter types 0-2. Used by the panoramas' compact maps and pictures and by the
lightmaps' 8-bit encodings."""

import struct
import zlib

import numpy as np

_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_KINDS = {3: 2, 4: 6}  # channels -> PNG colour type (grey is 0)


def encode(image):
    """(H, W), (H, W, 3) or (H, W, 4) uint8 -> PNG bytes (rows top to bottom, filter Up:
    smooth maps compress better)."""
    a = np.ascontiguousarray(image, dtype=np.uint8)
    if a.ndim == 2:
        a, kind = a[..., None], 0
    elif a.ndim == 3 and a.shape[2] in _KINDS:
        kind = _KINDS[a.shape[2]]
    else:
        raise ValueError(f"PNG: expected (H, W), (H, W, 3) or (H, W, 4) uint8, got {a.shape}")
    h, w = a.shape[:2]
    rows = a.reshape(h, -1)
    up = rows.copy()
    up[1:] = rows[1:] - rows[:-1]  # uint8 wraps, as PNG's filter does
    raw = np.concatenate([np.full((h, 1), 2, np.uint8), up], axis=1).tobytes()

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    return (_SIGNATURE + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, kind, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))


def decode(data, name="PNG"):
    """PNG bytes written by `encode` (or any 8-bit grey/RGB/RGBA, non-interlaced, filters 0-2)."""
    if data[:8] != _SIGNATURE:
        raise ValueError(f"{name}: not a PNG file")
    pos, idat, header = 8, [], None
    while pos < len(data):
        length, tag = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        if tag == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif tag == b"IDAT":
            idat.append(body)
        pos += 12 + length
    if header is None:
        raise ValueError(f"{name}: no IHDR chunk")
    w, h, depth, kind, _, _, interlace = header
    channels = {0: 1, 2: 3, 6: 4}.get(kind)
    if depth != 8 or channels is None or interlace:
        raise ValueError(f"{name}: only 8-bit grey, RGB or RGBA PNGs without interlacing are read")
    raw = np.frombuffer(zlib.decompress(b"".join(idat)), np.uint8).reshape(h, 1 + w * channels)
    filters, rows = raw[:, 0], raw[:, 1:].copy()
    if (filters > 2).any():
        raise ValueError(f"{name}: PNG filter {int(filters.max())} is not supported (re-save without filters)")
    if (filters == 2).all():  # what `encode` writes: undo Up for all rows at once
        return _shaped(np.cumsum(rows, axis=0, dtype=np.uint8), h, w, channels)
    for r in range(h):
        if filters[r] == 1:
            line = rows[r].reshape(w, channels)
            rows[r] = np.cumsum(line, axis=0, dtype=np.uint64).astype(np.uint8).reshape(-1)
        elif filters[r] == 2 and r > 0:
            rows[r] += rows[r - 1]
    return _shaped(rows, h, w, channels)


def _shaped(rows, h, w, channels):
    return rows.reshape(h, w) if channels == 1 else rows.reshape(h, w, channels)
