"""The live path: one `hemishadow.TransferSolver` per object, kept between frames.

A solver is keyed by the object's topology (vertex and triangle counts and a hash of the
triangle indices) and the transfer settings (bands, BRDF, exponent); it is rebuilt when any
of them changes. The last transfer vectors of every object are kept, so a change of lighting
or albedo only re-shades (a matrix product), and a depsgraph update that did not move any
vertex (for instance the one our own attribute writes cause) computes nothing.

Time is split into Blender I/O (reading the evaluated mesh, writing attributes) and engine
time (transfer, shading), per object, in `last_timings`.
"""

import itertools
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from . import mesh_io


@dataclass
class _Entry:
    key: tuple
    solver: object
    fingerprint: int | None = None  # hash of the positions (and view) `transfer` was computed on
    transfer: np.ndarray | None = None
    written: int = -1  # Request.serial of `transfer`: an older request's result is never written over it
    lock: threading.Lock = field(default_factory=threading.Lock)  # one thread at a time per solver


@dataclass
class Result:
    transfer: np.ndarray
    ao: np.ndarray
    radiance: np.ndarray
    io_seconds: float = 0.0
    engine_seconds: float = 0.0


# Keyed by ID.session_uid: stable while the object lives, unlike its name.
_entries: dict[int, _Entry] = {}
#: World-space positions the last transfer was computed on (lamps light each vertex from there).
_positions: dict[int, np.ndarray] = {}
#: object name -> (vertex count, Blender I/O seconds, engine seconds) of its last computation.
last_timings: dict[str, tuple[int, float, float]] = {}


def scene_lighting(scene, bands):
    """Lighting SH (bands*bands, 3) of the scene (world.py)."""
    from .world import scene_lighting as world_lighting

    return np.asarray(world_lighting(scene, bands), np.float32)


def _albedo(obj):
    return np.asarray(obj.hemishadow.albedo, np.float32)


def _solver_for(obj, vertices, triangles):
    import hemishadow

    settings = obj.hemishadow
    phong = settings.brdf == "PHONG"
    key = (len(vertices), len(triangles), hash(triangles.tobytes()), settings.band_count, settings.brdf,
           round(settings.exponent, 6) if phong else None)
    entry = _entries.get(obj.session_uid)
    if entry is None or entry.key != key:
        # Built on the rest pose, not on this frame: results do not depend on where playback started.
        solver = hemishadow.TransferSolver(mesh_io.read_rest(obj), triangles, bands=settings.band_count,
                                           brdf=settings.brdf.lower(), exponent=settings.exponent if phong else None)
        entry = _entries[obj.session_uid] = _Entry(key, solver)
    return entry


def _view_directions(obj, scene, vertices):
    """Per-vertex unit directions towards the active camera (Phong), or None (diffuse)."""
    if obj.hemishadow.brdf != "PHONG":
        return None
    if scene.camera is None:
        raise mesh_io.SkipObject(f"{obj.name}: the Phong BRDF needs an active camera for the view direction")
    eye = np.asarray(scene.camera.matrix_world.translation, np.float32)
    view = eye - vertices
    view /= np.maximum(np.linalg.norm(view, axis=1, keepdims=True), 1e-12)
    return view


@dataclass(eq=False)
class Request:
    """One object's solver inputs, read on the main thread. It holds no Blender data, so any
    thread may solve it (jobs.py does, in a worker)."""

    uid: int
    entry: _Entry
    vertices: np.ndarray
    normals: np.ndarray | None
    view: np.ndarray | None
    fingerprint: int
    io_seconds: float
    serial: int  # order of reading: a later read has newer positions
    solve_seconds: float = 0.0  # set by solve_object


#: ID.session_uid -> seconds of the object's last solve (jobs.py tells heavy objects by it).
solve_seconds: dict[int, float] = {}
_serials = itertools.count()


def read_object(obj, depsgraph, scene, *, force=False):
    """Main thread: the Request for the object's evaluated mesh; None when the positions (and
    view) are those of the last computation and `force` is false. Raises mesh_io.SkipObject."""
    t0 = time.perf_counter()
    vertices, triangles, normals = mesh_io.read_evaluated(obj, depsgraph)
    view = _view_directions(obj, scene, vertices)
    t1 = time.perf_counter()
    entry = _solver_for(obj, vertices, triangles)
    fingerprint = hash((vertices.tobytes(), None if view is None else view.tobytes()))
    written = mesh_io.RADIANCE in obj.data.attributes  # gone after Clear, or undone
    if not force and written and entry.transfer is not None and entry.fingerprint == fingerprint:
        entry.written = next(_serials)  # still current: results of requests read before this one are older
        return None
    return Request(obj.session_uid, entry, vertices, normals, view, fingerprint, t1 - t0, next(_serials))


def solve_object(request, progress=None):
    """Any thread, no Blender data: the transfer vectors of a Request. `progress` as the
    engine's (returning False raises hemishadow.Cancelled)."""
    with request.entry.lock:
        t0 = time.perf_counter()
        transfer = request.entry.solver.solve(request.vertices, request.normals, request.view, progress=progress)
        request.solve_seconds = seconds = time.perf_counter() - t0
    # The engine answers a repeated solve of the same positions from a cache in no time:
    # decay rather than forget, so a heavy object does not pass for light after one.
    solve_seconds[request.uid] = max(seconds, solve_seconds.get(request.uid, 0.0) / 2)
    return transfer


def _shade_request(obj, scene, request, transfer, lighting):
    t0 = time.perf_counter()
    entry = request.entry
    entry.transfer, entry.fingerprint, entry.written = transfer, request.fingerprint, request.serial
    result = _shade(obj, scene, transfer, lighting, request.vertices)
    result.io_seconds = request.io_seconds
    result.engine_seconds = request.solve_seconds + time.perf_counter() - t0
    return result


def compute_object(obj, depsgraph, scene, *, force=False, lighting=None):
    """Transfer, AO and radiance of the object's evaluated mesh, as a Result; None when the
    positions (and view) are those of the last computation and `force` is false.
    Raises mesh_io.SkipObject, or the engine's ValueError / RuntimeError."""
    request = read_object(obj, depsgraph, scene, force=force)
    if request is None:
        return None
    request.entry.transfer, request.entry.fingerprint = None, None  # never keep a stale pair if solve raises
    return _shade_request(obj, scene, request, solve_object(request), lighting)


def obsolete(request):
    """True when a Request's result must not be written: the object's solver changed, or the
    result of a request read later has been written (or found current) already."""
    entry = request.entry
    return _entries.get(request.uid) is not entry or entry.written > request.serial


def finish_object(obj, scene, request, transfer, lighting=None):
    """Main thread: shade and write a transfer that solve_object computed elsewhere; returns
    the Result, or None when it is obsolete: the object's solver changed meanwhile, or a
    request read later has been written already. Errors are raised as by update_object, the
    status line is set either way."""
    if obsolete(request):
        return None
    try:
        mesh_io.check_computable(obj)
        result = _shade_request(obj, scene, request, transfer, lighting)
    except (ValueError, RuntimeError) as error:
        set_status(obj, str(error))
        raise
    _publish(obj, result)
    return result


def _shade(obj, scene, transfer, lighting=None, vertices=None):
    """Environment and suns (`lighting`, default the scene's) plus the lamps at `vertices`
    (default: the positions of the object's last computation)."""
    import hemishadow

    from . import lighting as scene_lights

    if lighting is None:
        lighting = scene_lighting(scene, obj.hemishadow.band_count)
    if vertices is not None:
        _positions[obj.session_uid] = vertices
    radiance = scene_lights.shade(scene, transfer, lighting, _albedo(obj), _positions.get(obj.session_uid))
    return Result(transfer, hemishadow.ambient_occlusion(transfer), radiance)


def _write(obj, result):
    settings = obj.hemishadow
    t0 = time.perf_counter()
    mesh_io.write_outputs(obj, result.radiance, result.ao if settings.write_ao else None,
                          result.transfer if settings.write_sh else None)
    mesh_io.remove_sh_layers(obj, keep=result.transfer.shape[1] if settings.write_sh else 0)
    return time.perf_counter() - t0


def set_status(obj, message):
    # Assigning an ID property tags the object for re-evaluation: only when it changes.
    if obj.hemishadow.status != message:
        obj.hemishadow.status = message


def update_object(obj, depsgraph, scene, *, force=False, lighting=None):
    """Compute and write one object's outputs; returns the Result or None (nothing moved).
    Errors are raised as by compute_object; the status line is set either way."""
    try:
        result = compute_object(obj, depsgraph, scene, force=force, lighting=lighting)
    except (ValueError, RuntimeError) as error:
        set_status(obj, str(error))
        raise
    if result is None:
        return None
    _publish(obj, result)
    return result


def _publish(obj, result):
    result.io_seconds += _write(obj, result)
    last_timings[obj.name] = (len(result.ao), result.io_seconds, result.engine_seconds)
    set_status(obj, f"{len(result.ao)} vertices, AO {float(result.ao.min()):.2f}..{float(result.ao.max()):.2f}")


def enabled_objects(scene):
    return [o for o in scene.objects if o.type == "MESH" and o.hemishadow.enabled]


def update_scene(scene, depsgraph, objects=None, *, force=False):
    """update_object for each object (default: the enabled ones); returns {name: error message}
    for those that failed, without raising."""
    prune()
    errors, lighting = {}, {}
    for obj in enabled_objects(scene) if objects is None else objects:
        bands = obj.hemishadow.band_count
        try:
            if bands not in lighting:
                lighting[bands] = scene_lighting(scene, bands)
            update_object(obj, depsgraph, scene, force=force, lighting=lighting[bands])
        except (ValueError, RuntimeError) as error:
            errors[obj.name] = str(error)
    return errors


def reshade_object(obj, scene, lighting=None):
    """Re-shade from the last transfer vectors (lighting or albedo changed); False when the
    object has none yet."""
    entry = _entries.get(obj.session_uid)
    if entry is None or entry.transfer is None or obj.type != "MESH" or obj.mode == "EDIT":
        return False
    if len(entry.transfer) != len(obj.data.vertices):
        return False
    t0 = time.perf_counter()
    result = _shade(obj, scene, entry.transfer, lighting)
    engine = time.perf_counter() - t0
    mesh_io.write_outputs(obj, result.radiance)
    last_timings[obj.name] = (len(result.ao), time.perf_counter() - t0 - engine, engine)
    return True


def reshade_scene(scene, objects=None):
    """Re-shade every object of the scene (or of `objects`) that has transfer vectors; errors
    go to the status."""
    lighting = {}
    for obj in scene.objects if objects is None else objects:
        if obj.session_uid in _entries:
            try:
                bands = obj.hemishadow.band_count
                if bands not in lighting:
                    lighting[bands] = scene_lighting(scene, bands)
                reshade_object(obj, scene, lighting[bands])
            except (ValueError, RuntimeError) as error:
                set_status(obj, str(error))


def forget(obj=None):
    """Drop the solver and transfer of one object (all when None)."""
    if obj is None:
        _entries.clear()
        _positions.clear()
    else:
        _entries.pop(obj.session_uid, None)
        _positions.pop(obj.session_uid, None)


def forget_positions():
    """Make the next update of every object compute and write again (after undo or redo the
    attributes may hold other values than the last ones computed), keeping the solvers."""
    for entry in _entries.values():
        entry.fingerprint = None


def prune():
    """Drop entries of objects that no longer exist (deleted, or a new file was loaded)."""
    import bpy

    alive = {o.session_uid for o in bpy.data.objects}
    for uid in [u for u in _entries if u not in alive]:
        del _entries[uid]
        _positions.pop(uid, None)


def has_transfer(obj):
    entry = _entries.get(obj.session_uid)
    return entry is not None and entry.transfer is not None
