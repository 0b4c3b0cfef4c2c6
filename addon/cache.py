"""Bake cache: one object's hemishadow outputs for every frame of a range.

A cache holds, per frame, the radiance (V, 3) and ambient occlusion (V,) written to the
attributes, and (optionally) the SH transfer vectors (V, K) as float16, so that a change
of lighting re-shades from the cache without recomputing transfer. It remembers what it
was made from: the topology signature of the object's mesh, the transfer settings, the
lighting coefficients and the frame range. `is_valid` compares them with the object now.

Where it lives (see docs/baking.md):
- FILE (default): `//hemishadow_cache/<object name>.npz` beside the .blend file, written
  atomically (temporary file + rename). The path is remembered on the object in the ID
  property `_hemishadow_cache_path`, so another directory can be chosen.
- PACKED: the same .npz bytes in the object's ID property `_hemishadow_cache` (a bytes
  ID property: saved with the .blend, copied with the object, undoable; the leading
  underscore keeps it out of the Custom Properties panel).

Blender data is read and written here on the main thread only.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import tempfile
import uuid
from dataclasses import dataclass, field

import numpy as np

import bpy

from . import mesh_io

__all__ = [
    "BakeCache", "DEFAULT_DIRECTORY", "apply_cached", "baking", "cache_path", "clear", "handled",
    "is_baking", "is_valid", "load", "rest_signature", "save", "signature", "transfer_settings", "why_invalid",
]

VERSION = 1
PACKED_KEY = "_hemishadow_cache"
PATH_KEY = "_hemishadow_cache_path"
TOKEN_KEY = "_hemishadow_cache_token"
DEFAULT_DIRECTORY = "//hemishadow_cache"


@dataclass
class BakeCache:
    """Per-frame outputs of one object for frames frame_start..frame_start + F - 1."""

    frame_start: int
    radiance: np.ndarray            # (F, V, 3) float32, exactly what the attribute receives
    ao: np.ndarray                  # (F, V) float32
    transfer: np.ndarray | None     # (F, V, K) float16, or None when not stored
    meta: dict = field(default_factory=dict)   # signature, settings, lighting, object, token, version

    @property
    def frame_end(self) -> int:
        return self.frame_start + len(self.radiance) - 1

    def covers(self, frame: int) -> bool:
        return self.frame_start <= frame <= self.frame_end

    def to_bytes(self) -> bytes:
        arrays = dict(radiance=self.radiance, ao=self.ao, meta=np.array(json.dumps(self.meta)))
        if self.transfer is not None:
            arrays["transfer"] = self.transfer
        buffer = io.BytesIO()
        np.savez(buffer, **arrays)
        return buffer.getvalue()

    @classmethod
    def from_bytes(cls, data: bytes) -> "BakeCache":
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            meta = json.loads(str(npz["meta"]))
            if meta.get("version") != VERSION:
                raise ValueError(f"cache version {meta.get('version')} is not {VERSION}: bake again")
            transfer = npz["transfer"] if "transfer" in npz.files else None
            return cls(int(meta["frame_start"]), npz["radiance"], npz["ao"], transfer, meta)


# ---------------------------------------------------------------------------------------
# What a cache is made from

def signature(obj) -> str:
    """Topology signature of the object's mesh: counts and a hash of the polygons' vertex
    indices (positions do not enter: a deformation does not change it)."""
    mesh = obj.data
    loops = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", loops)
    sizes = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_total", sizes)
    digest = hashlib.blake2b(loops.tobytes(), digest_size=12)
    digest.update(sizes.tobytes())
    return f"{len(mesh.vertices)}v-{len(mesh.polygons)}p-{digest.hexdigest()}"


def rest_signature(obj) -> str:
    """Hash of the mesh's own (undeformed) positions: the rest pose the solver's hierarchy is
    built from. Editing the mesh changes it; animation and modifiers do not."""
    mesh = obj.data
    positions = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", positions)
    return hashlib.blake2b(positions.tobytes(), digest_size=12).hexdigest()


#: Object settings (properties.py, `obj.hemishadow`) that change the transfer vectors.
#: Lighting-only settings are not here: a lighting change re-shades from stored transfer.
TRANSFER_SETTINGS = ("bands", "brdf", "exponent")


def transfer_settings(obj) -> dict:
    settings = getattr(obj, "hemishadow", None)
    found = {}
    for name in TRANSFER_SETTINGS:
        if settings is not None and hasattr(settings, name):
            value = getattr(settings, name)
            found[name] = round(value, 6) if isinstance(value, float) else value
    if found.get("brdf", "DIFFUSE") == "DIFFUSE":
        found.pop("exponent", None)    # no effect on diffuse transfer
    return found


# ---------------------------------------------------------------------------------------
# Saving and finding

def cache_path(obj, directory: str | None = None) -> str:
    """Blend-relative (`//...`) or absolute path of the object's cache file."""
    directory = directory or DEFAULT_DIRECTORY
    return os.path.join(directory, bpy.path.clean_name(obj.name) + ".npz").replace("\\", "/")


def _absolute(path: str) -> str:
    if path.startswith("//") and not bpy.data.filepath:
        raise ValueError("the .blend file is not saved, so `//` has no folder: save it first, "
                         "choose an absolute cache directory, or pack the cache into the .blend")
    return os.path.abspath(bpy.path.abspath(path))


def _atomic_write(path: str, data: bytes) -> None:
    os.makedirs(os.path.dirname(path), exist_ok=True)
    handle, temporary = tempfile.mkstemp(prefix=".tmp-", suffix=".npz", dir=os.path.dirname(path))
    try:
        with os.fdopen(handle, "wb") as file:
            file.write(data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o666 & ~umask)   # mkstemp makes it private; a cache is an ordinary file
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        raise


# Parsed caches, so that playback does not re-read a file or an ID property every frame.
# object name -> (source key, BakeCache); the key changes when the stored cache does.
_loaded: dict[str, tuple[tuple, BakeCache]] = {}


def save(obj, cache: BakeCache, *, location: str = "FILE", directory: str | None = None) -> str:
    """Store `cache` for `obj`: location "FILE" (npz beside the .blend, or in `directory`)
    or "PACKED" (bytes ID property in the .blend). Returns where it went. Replaces any
    earlier cache of the object, in either location."""
    if location not in ("FILE", "PACKED"):
        raise ValueError(f"cache location must be FILE or PACKED, got {location!r}")
    cache.meta["token"] = uuid.uuid4().hex
    data = cache.to_bytes()
    if location == "FILE":
        path = cache_path(obj, directory)
        _atomic_write(_absolute(path), data)
        obj.pop(PACKED_KEY, None)
        obj[PATH_KEY] = path
        where = path
    else:
        obj[PACKED_KEY] = data
        obj.pop(PATH_KEY, None)
        where = "packed in the .blend"
    obj[TOKEN_KEY] = cache.meta["token"]
    _loaded.pop(obj.name, None)
    return where


def load(obj) -> BakeCache | None:
    """The object's cache (packed or file), or None when it has none or it cannot be read."""
    token = obj.get(TOKEN_KEY)
    if PACKED_KEY in obj:
        key = ("PACKED", token)
        remembered = _loaded.get(obj.name)
        if remembered and remembered[0] == key:
            return remembered[1]
        data = bytes(obj[PACKED_KEY])
    else:
        try:
            path = _absolute(obj.get(PATH_KEY) or cache_path(obj))
            stat = os.stat(path)
        except (OSError, ValueError):
            return None
        key = ("FILE", path, stat.st_mtime_ns, stat.st_size)
        remembered = _loaded.get(obj.name)
        if remembered and remembered[0] == key:
            return remembered[1]
        with open(path, "rb") as file:
            data = file.read()
    try:
        cache = BakeCache.from_bytes(data)
    except (ValueError, KeyError, OSError) as error:
        print(f"hemishadow: ignoring the cache of {obj.name!r}: {error}")
        return None
    _loaded[obj.name] = (key, cache)
    return cache


def clear(obj, *, delete_file: bool = True) -> None:
    """Forget the object's cache (packed bytes, and the file when `delete_file`)."""
    if delete_file and PACKED_KEY not in obj:
        with contextlib.suppress(OSError, ValueError):
            os.unlink(_absolute(obj.get(PATH_KEY) or cache_path(obj)))
    for key in (PACKED_KEY, PATH_KEY, TOKEN_KEY):
        obj.pop(key, None)
    _loaded.pop(obj.name, None)


# ---------------------------------------------------------------------------------------
# Using it

def _current_lighting(scene, bands: int) -> np.ndarray:
    from . import engine_bridge

    return np.asarray(engine_bridge.scene_lighting(scene, bands), np.float32)


def _why_invalid(obj, scene, frame: int, cache: BakeCache | None) -> str | None:
    if cache is None:
        return "no cache"
    if not cache.covers(frame):
        return f"frame {frame} is outside the cached {cache.frame_start}..{cache.frame_end}"
    if obj.mode == "EDIT":
        return "the object is in Edit Mode"
    if cache.meta.get("signature") != signature(obj):
        return "the mesh's topology changed since the bake"
    if cache.meta.get("rest") != rest_signature(obj):
        return "the mesh was edited since the bake"
    if cache.meta.get("settings") != transfer_settings(obj):
        return "the object's settings changed since the bake"
    if cache.transfer is None and not _same_shading(cache, obj, scene):
        return "the lighting or albedo changed and the cache holds no transfer vectors to re-shade"
    return None


def _albedo(obj) -> np.ndarray:
    return np.asarray(getattr(obj.hemishadow, "albedo", (0.8, 0.8, 0.8)), np.float32)[:3]


def _same_shading(cache: BakeCache, obj, scene) -> bool:
    """Lighting and albedo as at the bake: the cached radiance can be copied as it is."""
    stored = np.asarray(cache.meta.get("lighting"), np.float32)
    current = _current_lighting(scene, int(round(np.sqrt(stored.shape[0]))))
    from . import lamps

    return (stored.shape == current.shape and np.array_equal(stored, current)
            and np.array_equal(np.asarray(cache.meta.get("albedo"), np.float32), _albedo(obj))
            and cache.meta.get("lamps", "") == lamps.lamps_key(scene))


def is_valid(obj, scene, frame: int | None = None) -> bool:
    """True when the object's cache was made from this topology and these settings, covers
    `frame` (default: the scene's current frame) and can produce this lighting."""
    if obj is None or obj.type != "MESH":
        return False
    frame = scene.frame_current if frame is None else int(frame)
    return _why_invalid(obj, scene, frame, load(obj)) is None


def why_invalid(obj, scene, frame: int | None = None) -> str | None:
    """None when `is_valid`, else a sentence for the UI."""
    frame = scene.frame_current if frame is None else int(frame)
    return _why_invalid(obj, scene, frame, load(obj))


def apply_cached(obj, frame: int, scene=None) -> bool:
    """Copy the cached outputs of `frame` into the object's attributes. With `scene`, when
    its lighting or the object's albedo differ from the bake's, re-shade the stored transfer
    vectors instead.
    Returns False (and writes nothing) when the cache does not cover the frame."""
    cache = load(obj)
    if cache is None or not cache.covers(int(frame)):
        return False
    i = int(frame) - cache.frame_start
    radiance = cache.radiance[i]
    if scene is not None and cache.transfer is not None and not _same_shading(cache, obj, scene):
        radiance = _reshade(obj, scene, cache, i)
    settings = obj.hemishadow
    transfer = None
    if settings.write_sh and cache.transfer is not None:
        transfer = cache.transfer[i].astype(np.float32)
    mesh_io.write_outputs(obj, radiance, cache.ao[i] if settings.write_ao else None, transfer)
    if transfer is None:
        mesh_io.remove_sh_layers(obj, keep=0)
    return True


def _reshade(obj, scene, cache: BakeCache, i: int) -> np.ndarray:
    import hemishadow

    from . import evaluated, lamps

    transfer = cache.transfer[i].astype(np.float32)
    lighting = _current_lighting(scene, int(round(np.sqrt(transfer.shape[1]))))
    radiance = hemishadow.shade(transfer, lighting, _albedo(obj))
    found = lamps.scene_lamps(scene)
    if found:   # lamps light each vertex from where it is this frame
        vertices, _, _ = mesh_io.read_evaluated(obj, evaluated.depsgraph())
        radiance += _albedo(obj) / np.pi * lamps.lamp_irradiance(transfer, vertices, found)
    return radiance


# ---------------------------------------------------------------------------------------
# The live path's hook

_baking = 0


@contextlib.contextmanager
def baking():
    """While a bake steps frames, the live handlers leave objects alone (see `handled`)."""
    global _baking
    _baking += 1
    try:
        yield
    finally:
        _baking -= 1


def is_baking() -> bool:
    return _baking > 0


def handled(obj, scene) -> bool:
    """For handlers.py, per enabled object on frame change: True when the live path must
    not compute it, because a bake is stepping frames or because a valid cache covers the
    current frame (its values have then been copied into the attributes)."""
    if _baking:
        return True
    if not (obj.get(TOKEN_KEY) or PACKED_KEY in obj or os.path.isfile(_cache_file_or_empty(obj))):
        return False
    if not is_valid(obj, scene):
        return False
    return apply_cached(obj, scene.frame_current, scene)


def _cache_file_or_empty(obj) -> str:
    try:
        return _absolute(obj.get(PATH_KEY) or cache_path(obj))
    except ValueError:
        return ""
