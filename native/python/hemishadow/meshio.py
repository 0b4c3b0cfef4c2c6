"""Mesh files in and out: loading with trimesh, writing vertex-colored GLB / PLY and .npz.

Vertices are kept exactly as stored in the file (no welding, no axis change): seams
stay split, and the engine welds by position itself.

Vertex colors in written files:
- GLB: COLOR_0 as float32 RGB, *linear*, clipped to [0, 1]. The glTF 2.0 spec defines
  COLOR_0 as linear, and Blender's glTF importer and web viewers read it that way.
- PLY: 8-bit RGBA, *sRGB*-encoded from the linear input, clipped to [0, 1], as Blender's
  PLY importer and most viewers expect byte colors to be.

Files are written atomically (a temporary file beside the target, then renamed) and get the
permissions of any new file: 0666 less the umask (usually 0644), not the private 0600 of
`tempfile.mkstemp`.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import struct
import uuid

import numpy as np

__all__ = ["colored_mesh_bytes", "load_mesh", "npz_bytes", "save_colored_mesh", "save_npz", "linear_to_srgb8",
           "write_files"]


def load_mesh(path):
    """Load a mesh file (OBJ, PLY, glTF/GLB, anything trimesh reads).

    Returns (vertices float32 (N, 3), triangles uint32 (M, 3), normals float32 (N, 3) or
    None when the file has none). Scenes are flattened with their node transforms.
    """
    import trimesh

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ValueError(f"{path}: no such mesh file")
    try:
        # process=False: keep vertices as stored (no merging, no reordering).
        loaded = trimesh.load(path, process=False)
    except Exception as exc:
        raise ValueError(f"{path}: cannot read mesh ({type(exc).__name__}: {exc})") from None
    parts = _scene_parts(loaded) if isinstance(loaded, trimesh.Scene) else [(loaded, None)]
    parts = [(m, t) for m, t in parts if isinstance(m, trimesh.Trimesh) and len(m.faces)]
    if not parts:
        raise ValueError(f"{path}: no triangles in file")
    verts, tris, norms, offset = [], [], [], 0
    for mesh, transform in parts:
        v, f, n = _transformed(mesh, transform)
        verts.append(v)
        tris.append(f + offset)
        norms.append(n)
        offset += len(v)
    vertices = np.ascontiguousarray(np.concatenate(verts), dtype=np.float32)
    triangles = np.ascontiguousarray(np.concatenate(tris), dtype=np.uint32)
    normals = None
    if all(n is not None for n in norms):
        normals = np.ascontiguousarray(np.concatenate(norms), dtype=np.float32)
    if not np.isfinite(vertices).all():
        raise ValueError(f"{path}: vertex positions contain NaN or infinity")
    return vertices, triangles, normals


def _scene_parts(scene):
    """(mesh, 4x4 world transform) for every mesh instance of a scene."""
    parts = []
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        parts.append((scene.geometry[name], transform))
    return parts


def _transformed(mesh, transform):
    """Vertices, faces and file normals (or None) of one mesh, with transform applied."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)
    # Only normals that came from the file: mesh.vertex_normals would compute
    # area-weighted ones on demand, which hides "the file has none".
    n = mesh._cache["vertex_normals"]  # None when absent
    n = None if n is None or len(n) != len(v) else np.asarray(n, dtype=np.float64)
    if transform is not None and not np.allclose(transform, np.eye(4)):
        linear = transform[:3, :3]
        v = v @ linear.T + transform[:3, 3]
        if n is not None:
            n = n @ np.linalg.inv(linear)  # normals transform by the inverse transpose
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
        if np.linalg.det(linear) < 0:
            f = f[:, ::-1]  # a mirroring transform flips the winding; keep faces outward
    return v, f, n


def linear_to_srgb8(colors) -> np.ndarray:
    """Linear float colors -> sRGB-encoded uint8 (clipped to [0, 1] first)."""
    c = np.clip(np.nan_to_num(np.asarray(colors, dtype=np.float64)), 0.0, 1.0)
    srgb = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1.0 / 2.4) - 0.055)
    return np.round(srgb * 255.0).astype(np.uint8)


def save_colored_mesh(path, vertices, triangles, colors) -> None:
    """Write a mesh with per-vertex linear RGB colors (N, 3) as .glb or .ply, atomically."""
    write_files({path: colored_mesh_bytes(path, vertices, triangles, colors)})


def colored_mesh_bytes(path, vertices, triangles, colors) -> bytes:
    """The bytes `save_colored_mesh` writes; the format is chosen by `path`'s extension."""
    vertices = np.asarray(vertices, dtype=np.float32).reshape(-1, 3)
    triangles = np.asarray(triangles, dtype=np.uint32).reshape(-1, 3)
    colors = np.asarray(colors, dtype=np.float32)
    if colors.ndim != 2 or colors.shape[0] != len(vertices) or colors.shape[1] not in (3, 4):
        raise ValueError(f"colors must be (N, 3) with N = {len(vertices)}, got {colors.shape}")
    colors = colors[:, :3]
    if len(triangles) and int(triangles.max()) >= len(vertices):
        raise ValueError("triangle indices out of range")
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext == ".glb":
        data = _glb_bytes(vertices, triangles, colors)
    elif ext == ".ply":
        data = _ply_bytes(vertices, triangles, colors)
    else:
        raise ValueError(f"{path}: unsupported mesh format {ext!r} (use .glb or .ply)")
    return data


def _ply_bytes(vertices, triangles, colors) -> bytes:
    import trimesh

    rgba = np.concatenate([linear_to_srgb8(colors), np.full((len(colors), 1), 255, np.uint8)], axis=1)
    mesh = trimesh.Trimesh(vertices, triangles, vertex_colors=rgba, process=False)
    return mesh.export(file_type="ply", encoding="binary")


def _glb_bytes(vertices, triangles, colors) -> bytes:
    """A minimal glTF 2.0 binary: one mesh, POSITION + float COLOR_0 + uint32 indices.

    Written by hand because trimesh stores COLOR_0 as 8-bit, which bands dark shadows
    when the values are linear.
    """
    colors = np.clip(np.nan_to_num(colors), 0.0, 1.0).astype(np.float32)
    blobs = [vertices.tobytes(), colors.tobytes(), triangles.tobytes()]
    views, offset = [], 0
    for blob, target in zip(blobs, (34962, 34962, 34963)):  # ARRAY_BUFFER / ELEMENT_ARRAY_BUFFER
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(blob), "target": target})
        offset += len(blob)  # all blobs are 4-byte multiples, so alignment holds
    n = len(vertices)
    accessors = [
        {"bufferView": 0, "componentType": 5126, "count": n, "type": "VEC3",
         "min": vertices.min(axis=0).tolist() if n else [0, 0, 0],
         "max": vertices.max(axis=0).tolist() if n else [0, 0, 0]},
        {"bufferView": 1, "componentType": 5126, "count": n, "type": "VEC3"},
        {"bufferView": 2, "componentType": 5125, "count": triangles.size, "type": "SCALAR"},
    ]
    gltf = {
        "asset": {"version": "2.0", "generator": "hemishadow"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "COLOR_0": 1},
                                    "indices": 2, "mode": 4}]}],
        "buffers": [{"byteLength": offset}],
        "bufferViews": views,
        "accessors": accessors,
    }
    js = json.dumps(gltf, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)  # chunks are padded to 4 bytes (JSON with spaces)
    binary = b"".join(blobs)
    binary += b"\0" * (-len(binary) % 4)
    total = 12 + 8 + len(js) + 8 + len(binary)
    return b"".join([
        struct.pack("<4sII", b"glTF", 2, total),
        struct.pack("<I4s", len(js), b"JSON"), js,
        struct.pack("<I4s", len(binary), b"BIN\0"), binary,
    ])


def save_npz(path, **arrays) -> None:
    """np.savez_compressed, atomically (path should end in .npz)."""
    write_files({path: npz_bytes(**arrays)})


def npz_bytes(**arrays) -> bytes:
    buffer = io.BytesIO()   # a file object also stops numpy from appending ".npz"
    np.savez_compressed(buffer, **arrays)
    return buffer.getvalue()


def write_files(files: dict) -> None:
    """Write {path: bytes}: every file to a temporary file beside its target first, then all
    renamed into place, so that a failure while writing leaves none of them (and no temporary
    file). New files get 0666 less the umask, as the kernel applies it."""
    staged = []
    try:
        for path, data in files.items():
            path = os.fspath(path)
            folder = os.path.dirname(os.path.abspath(path))
            os.makedirs(folder, exist_ok=True)
            temporary = os.path.join(folder, f".tmp-{uuid.uuid4().hex}{os.path.splitext(path)[1]}")
            handle = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
            staged.append((temporary, path))
            with os.fdopen(handle, "wb") as file:
                file.write(data)
        while staged:
            temporary, path = staged[0]
            os.replace(temporary, path)
            staged.pop(0)
    finally:
        for temporary, _ in staged:
            with contextlib.suppress(OSError):
                os.unlink(temporary)
