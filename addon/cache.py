"""Bake cache: one object's hemishadow outputs for every frame of a range.

A cache holds, per frame, the radiance (V, 3) and ambient occlusion (V,) written to the
attributes, and (optionally) the SH transfer vectors (V, K) as float16, so that a change
of lighting re-shades from the cache without recomputing transfer. It remembers what it
was made from: the topology signature of the object's mesh, the transfer settings, the
lighting coefficients and the frame range. `is_valid` compares them with the object now.

It also remembers what the animation was (staleness.py): digests of the keyframes, drivers,
constraints, modifiers and simulation settings the object's geometry depends on, and per
frame a fingerprint of the evaluated positions. A cache that no longer matches is stale: it
is not served (the live path computes instead), and the object's status, the console and the
panel say why. The digests are compared when playback starts and on the first cached frame
of a render, of a session and after any edit of animation data; the fingerprint on every
served frame.

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
from bpy.app.handlers import persistent

from . import casters, mesh_io, probe_lighting, probes, staleness

__all__ = [
    "BakeCache", "DEFAULT_DIRECTORY", "HANDLERS", "apply_cached", "baking", "cache_path", "check_directory", "clear",
    "draw_status", "handled", "is_baking", "is_valid", "load", "note_stale", "rest_signature", "save", "signature",
    "stale_reason", "transfer_settings", "why_invalid",
]

VERSION = 2   # 2: inputs digests and per-frame position fingerprints
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
    meta: dict = field(default_factory=dict)   # signature, settings, inputs, lighting, object, token, version
    fingerprint: np.ndarray | None = None      # (F, R, 3) float64 (staleness.fingerprint per frame)
    casters: np.ndarray | None = None          # (F, C, 3) float64 (casters.fingerprint per frame), or None

    @property
    def frame_end(self) -> int:
        return self.frame_start + len(self.radiance) - 1

    def covers(self, frame: int) -> bool:
        return self.frame_start <= frame <= self.frame_end

    def to_bytes(self) -> bytes:
        arrays = dict(radiance=self.radiance, ao=self.ao, meta=np.array(json.dumps(self.meta)))
        for name in ("transfer", "fingerprint", "casters"):
            if getattr(self, name) is not None:
                arrays[name] = getattr(self, name)
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
            shadows = npz["casters"] if "casters" in npz.files else None
            return cls(int(meta["frame_start"]), npz["radiance"], npz["ao"], transfer, meta, npz["fingerprint"],
                       shadows)


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


def check_directory(obj, directory: str | None = None) -> str:
    """Raise ValueError, naming the folder, when the object's cache file could not be written
    there (an unsaved .blend with `//`, a file in the way, a folder that cannot be created or
    written, a missing drive); returns the folder's absolute path. Creates nothing."""
    folder = os.path.dirname(_absolute(cache_path(obj, directory)))
    existing = folder
    while not os.path.isdir(existing):
        if os.path.lexists(existing):
            raise ValueError(f"cannot use the cache folder {folder}: {existing} is a file, not a folder")
        parent = os.path.dirname(existing)
        if parent == existing:
            raise ValueError(f"cannot use the cache folder {folder}: no part of that path exists (a missing drive?)")
        existing = parent
    try:   # access() trusts permission bits only; writing a file asks the file system itself
        with tempfile.TemporaryFile(dir=existing, prefix=".hemishadow-probe-"):
            pass
    except OSError as error:
        raise ValueError(f"cannot write the cache folder {folder}: {error.strerror or error} in {existing}") from None
    return folder


def _atomic_write(path: str, data: bytes) -> None:
    """Write beside `path`, then rename into place: a crash never leaves half a cache. The file
    gets the permissions of any new file (0666 less the umask, as the kernel applies it), not
    mkstemp's private 0600."""
    folder = os.path.dirname(path)
    os.makedirs(folder, exist_ok=True)
    temporary = os.path.join(folder, f".tmp-{uuid.uuid4().hex}.npz")
    handle = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
    try:
        with os.fdopen(handle, "wb") as file:
            file.write(data)
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


def _why_invalid(obj, scene, frame: int, cache: BakeCache | None, depsgraph=None, *, recheck=True) -> str | None:
    """None when the cache can serve `frame`; else why not. `recheck`: compare the input digests
    even when they matched since the last edit of animation data (the API does; playback, which
    asks every frame, does not)."""
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
    if cache.meta.get("casters") != casters.describe(obj, scene):
        return "the object's shadow casters changed since the bake"
    stale = _stale_reason(obj, scene, frame, cache, depsgraph, recheck)
    if stale is not None:
        return f"the bake cache is stale: {stale}"
    volume = probe_lighting.volume_of(obj)
    if volume is not None and cache.transfer is None:
        return "Probe Lighting shades the cache's transfer vectors and this cache holds none: bake it again"
    if volume is not None and probes.PROP + "positions" not in volume:  # (probes.stored, without reading it)
        return f"its probe volume '{volume.name}' holds no baked probes"
    if cache.transfer is None and not _same_shading(cache, obj, scene):
        return "the lighting or albedo changed and the cache holds no transfer vectors to re-shade"
    return None


# ---------------------------------------------------------------------------------------
# Stale caches (staleness.py): the animation is no longer what was baked

# Keyed by (object name, cache token): a duplicated object carries the same token.
# -> why: caches whose animation inputs changed, found in this session. Forgotten on undo,
# redo and file loads, which may have brought the bake's inputs back (checked again then).
_stale: dict[tuple, str] = {}
# -> why: the last frame checked had other evaluated positions than the bake's. Per frame, not
# for the session: a cloth simulation jumped over frames shows a different drape on that frame
# only, and the cache serves again when played in order.
_mismatch: dict[tuple, str] = {}
# caches whose input digests matched since the last edit of animation data
_inputs_checked: set[tuple] = set()


def _key(obj, token) -> tuple:
    return obj.name, token


def _stale_reason(obj, scene, frame: int | None, cache: BakeCache, depsgraph, recheck: bool) -> str | None:
    """Why the cache does not match the animation, or None. The digests of the inputs are
    compared (memoised until animation data is edited; a mismatch marks the cache stale for the
    session); on the current frame, the fingerprint of the evaluated positions too."""
    token = _key(obj, cache.meta.get("token"))
    if token in _stale:
        return _stale[token]
    if recheck or token not in _inputs_checked:
        try:
            current = staleness.inputs(obj, scene)
            reason = staleness.changed_inputs(cache.meta.get("inputs", {}), current, obj.name)
        except Exception as error:   # data this code does not know: it cannot vouch for the cache
            reason = f"its animation inputs could not be read ({type(error).__name__}: {error})"
        if reason is not None:
            _mark(obj, _stale, token, reason)
            return reason
        _inputs_checked.add(token)
    if frame != scene.frame_current:
        return None
    reason = _positions_differ(obj, scene, cache, frame, depsgraph)
    if reason is None:
        _mismatch.pop(token, None)
    elif _mismatch.get(token) is None:
        _mark(obj, _mismatch, token, reason)
    else:
        _mismatch[token] = reason
    return reason


def _eye(obj, scene):
    """The camera position when the shading depends on it (Phong), as engine_bridge uses it."""
    if obj.hemishadow.brdf != "PHONG" or scene.camera is None:
        return None
    return tuple(scene.camera.matrix_world.translation)


def _positions_differ(obj, scene, cache: BakeCache, frame: int, depsgraph) -> str | None:
    if depsgraph is None:
        depsgraph = bpy.context.evaluated_depsgraph_get()
    vertices = staleness.evaluated_positions(obj, depsgraph)
    if vertices is None:
        return f"the evaluated mesh at frame {frame} has fewer vertices than the object's mesh"
    current = staleness.fingerprint(vertices, _eye(obj, scene))
    if staleness.fingerprint_mismatch(cache.fingerprint[frame - cache.frame_start], current) is not None:
        return (f"the evaluated positions at frame {frame} are not the bake's (animation, modifiers, simulation "
                "or placement changed)")
    stored = None if cache.casters is None else cache.casters[frame - cache.frame_start]
    moved = casters.fingerprint_mismatch(stored, casters.fingerprint(obj, scene, depsgraph))
    return None if moved is None else f"at frame {frame} {moved}"


def _mark(obj, table: dict, token: tuple, reason: str) -> None:
    table[token] = reason
    print(f"hemishadow: {obj.name}: bake cache not used, it is stale: {reason}; computing live instead "
          "(bake again, or Clear Bake)")
    _set_status(obj, _note(reason))


def _note(reason: str) -> str:
    return f"Bake cache stale, computed live ({reason})"


def _set_status(obj, message: str) -> None:
    from . import engine_bridge

    engine_bridge.set_status(obj, message)


def stale_reason(obj) -> str | None:
    """Why the object's cache was last found stale, or None (cheap: for the UI)."""
    token = obj.get(TOKEN_KEY)
    return (_stale.get(_key(obj, token)) or _mismatch.get(_key(obj, token))) if token else None


def note_stale(objects) -> None:
    """After the live path computed `objects` (and set their status lines): prefix the status of
    those whose cache is stale with that news, so it is not lost under the vertex counts."""
    for obj in objects:
        if not obj.get(TOKEN_KEY):
            continue
        reason = stale_reason(obj)
        if reason is not None:
            note = _note(reason)
            status = obj.hemishadow.status
            if not status.startswith(note):
                _set_status(obj, f"{note} | {status}" if status else note)


def draw_status(layout, obj) -> None:
    """For the object panels: a warning line when the object's cache is stale."""
    reason = stale_reason(obj)
    if reason is not None:
        layout.label(text="Bake cache stale: not used, computed live", icon="ERROR")
        layout.label(text=reason)
        layout.label(text="Bake Animation again, or Clear Bake")


def check_scene(scene) -> list[str]:
    """Compare the input digests of every enabled object's cache with the scene now (playback
    start), before any frame is evaluated; returns the names of stale ones."""
    _inputs_checked.clear()
    found = []
    for obj in _enabled(scene):
        if not _has_cache(obj):
            continue
        cache = load(obj)
        if cache is not None and _stale_reason(obj, scene, None, cache, None, True) is not None:
            found.append(obj.name)
    return found


def _albedo(obj) -> np.ndarray:
    return np.asarray(getattr(obj.hemishadow, "albedo", (0.8, 0.8, 0.8)), np.float32)[:3]


def _same_shading(cache: BakeCache, obj, scene) -> bool:
    """Lighting and albedo as at the bake: the cached radiance can be copied as it is. Never
    under Probe Lighting: its light depends on where the object is on each frame."""
    if probe_lighting.volume_of(obj) is not None:
        return False
    stored = np.asarray(cache.meta.get("lighting"), np.float32)
    current = _current_lighting(scene, int(round(np.sqrt(stored.shape[0]))))
    from . import lamps

    return (stored.shape == current.shape and np.array_equal(stored, current)
            and np.array_equal(np.asarray(cache.meta.get("albedo"), np.float32), _albedo(obj))
            and cache.meta.get("lamps", "") == lamps.lamps_key(scene))


def is_valid(obj, scene, frame: int | None = None, depsgraph=None) -> bool:
    """True when the object's cache was made from this topology, these settings and this
    animation (not stale), covers `frame` (default: the scene's current frame) and can produce
    this lighting. On the current frame the evaluated positions are compared too."""
    if obj is None or obj.type != "MESH":
        return False
    return why_invalid(obj, scene, frame, depsgraph) is None


def why_invalid(obj, scene, frame: int | None = None, depsgraph=None) -> str | None:
    """None when `is_valid`, else a sentence for the UI."""
    frame = scene.frame_current if frame is None else int(frame)
    return _why_invalid(obj, scene, frame, load(obj), depsgraph)


def apply_cached(obj, frame: int, scene=None) -> bool:
    """Copy the cached outputs of `frame` into the object's attributes. With `scene`, when
    its lighting or the object's albedo differ from the bake's, re-shade the stored transfer
    vectors instead, and refuse a cache that does not match the scene's animation.
    Returns False (and writes nothing) when the cache does not cover the frame or is stale."""
    cache = load(obj)
    frame = int(frame)
    if cache is None or not cache.covers(frame) or _key(obj, cache.meta.get("token")) in _stale:
        return False   # a mismatch of positions is checked again: it may have been another frame
    if scene is not None and _stale_reason(obj, scene, frame, cache, None, False) is not None:
        return False
    _apply(obj, cache, frame, scene)
    return True


def _apply(obj, cache: BakeCache, frame: int, scene) -> None:
    i = frame - cache.frame_start
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


def _reshade(obj, scene, cache: BakeCache, i: int) -> np.ndarray:
    import hemishadow

    from . import evaluated, lamps

    transfer = cache.transfer[i].astype(np.float32)
    bands = int(round(np.sqrt(transfer.shape[1])))
    if probe_lighting.volume_of(obj) is not None:  # the grid's light where the object is now, as live
        vertices, _, _ = mesh_io.read_evaluated(obj, evaluated.depsgraph())
        return hemishadow.shade(transfer, probe_lighting.lighting(obj, scene, vertices, bands), _albedo(obj))
    lighting = _current_lighting(scene, bands)
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


def handled(obj, scene, depsgraph=None) -> bool:
    """For handlers.py, per enabled object on frame change: True when the live path must
    not compute it, because a bake is stepping frames or because a valid cache covers the
    current frame (its values have then been copied into the attributes). A stale cache is
    reported (status, console) and not used."""
    if _baking:
        return True
    if not _has_cache(obj):
        return False
    cache, frame = load(obj), scene.frame_current
    if _why_invalid(obj, scene, frame, cache, depsgraph, recheck=False) is not None:
        return False
    _apply(obj, cache, frame, scene)
    return True


def _has_cache(obj) -> bool:
    return bool(obj.get(TOKEN_KEY) or PACKED_KEY in obj or os.path.isfile(_cache_file_or_empty(obj)))


def _cache_file_or_empty(obj) -> str:
    try:
        return _absolute(obj.get(PATH_KEY) or cache_path(obj))
    except ValueError:
        return ""


# ---------------------------------------------------------------------------------------
# Handlers (registered by handlers.py with its own)

# Edits of these data blocks can change the animation's inputs: their digests are compared
# again on the next cached frame. Objects count when their transform or constraints changed;
# their geometry updates are what writing the attributes causes every frame.
_ANIMATION_TYPES = (bpy.types.Action, bpy.types.Key, bpy.types.Armature, bpy.types.ParticleSettings,
                    bpy.types.Curve, bpy.types.Lattice, bpy.types.NodeTree)


@persistent
def on_playback_start(scene, *_):
    check_scene(scene)


@persistent
def on_render_init(scene, *_):
    """A render may run this on its own thread: no data is written here; the first frame the
    render takes from a cache compares the digests (handled(), in the frame handler)."""
    _inputs_checked.clear()


def _enabled(scene) -> list:
    from . import engine_bridge

    return engine_bridge.enabled_objects(scene)


@persistent
def on_frame_changed(scene, *_):
    """After the live handler (registered after it): status lines of stale caches say so."""
    if (_stale or _mismatch) and not _baking:
        note_stale(_enabled(scene))


@persistent
def on_edit(scene, depsgraph):
    """After the live handler: an edit of animation data makes the next cached frame compare
    the input digests again; status lines of stale caches say so."""
    if any(isinstance(u.id, _ANIMATION_TYPES) or (isinstance(u.id, bpy.types.Object) and u.is_updated_transform)
           for u in depsgraph.updates):
        _inputs_checked.clear()
    on_frame_changed(scene)


@persistent
def on_reset(*_):
    """Undo, redo, a file load: what was stale may not be any more, and the reverse."""
    _stale.clear()
    _mismatch.clear()
    _inputs_checked.clear()


#: For handlers.py, after its own live handlers (the order of a handler list is the call order).
HANDLERS = (
    (bpy.app.handlers.frame_change_post, on_frame_changed),
    (bpy.app.handlers.animation_playback_pre, on_playback_start),
    (bpy.app.handlers.render_init, on_render_init),
    (bpy.app.handlers.depsgraph_update_post, on_edit),
    (bpy.app.handlers.undo_post, on_reset),
    (bpy.app.handlers.redo_post, on_reset),
    (bpy.app.handlers.load_post, on_reset),
)
