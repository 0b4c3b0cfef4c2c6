"""The live path: one `hemishadow.TransferSolver` per object, kept between frames.

A solver is keyed by the object's topology (vertex and triangle counts and a hash of the
triangle indices) and the transfer settings (bands, BRDF, exponent); it is rebuilt when any
of them changes. The last transfer vectors of every object are kept, so a change of lighting
or albedo only re-shades (a matrix product), and a depsgraph update that did not move any
vertex (for instance the one our own attribute writes cause) computes nothing.

Which objects are computed (one per shared mesh; not curves or text; instances) is decided
in objects.py; every error message starts with the object's name (`named_errors`). An
object with shadow casters (casters.py) is solved with them: the state of its casters is
part of what makes a result current.

Time is split into Blender I/O (reading the evaluated mesh, writing attributes) and engine
time (transfer, shading), per object, in `last_timings`.
"""

import functools
import itertools
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from . import casters as shadow_casters
from . import mesh_io
from . import objects as scope
from . import probe_lighting, steady


@dataclass
class _Entry:
    key: tuple
    solver: object
    fingerprint: int | None = None  # hash of the positions (and view) in the object's frame, as solved
    solved: np.ndarray | None = None  # transfer in the object's frame
    placement: tuple | None = None  # the frame's rotation and offset `transfer` was turned and shaded at
    transfer: np.ndarray | None = None  # in world space
    written: int = -1  # Request.serial of `transfer`: an older request's result is never written over it
    lock: threading.Lock = field(default_factory=threading.Lock)  # one thread at a time per solver


@dataclass
class Result:
    transfer: np.ndarray
    ao: np.ndarray
    radiance: np.ndarray
    io_seconds: float = 0.0
    engine_seconds: float = 0.0
    note: str = ""  # for the status line: the casters used


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


def _solver_for(obj, vertices, triangles, frame_matrix=None):
    import hemishadow

    settings = obj.hemishadow
    phong = settings.brdf == "PHONG"
    key = (len(vertices), len(triangles), hash(triangles.tobytes()), settings.band_count, settings.brdf,
           round(settings.exponent, 6) if phong else None)
    entry = _entries.get(obj.session_uid)
    if entry is None or entry.key != key:
        # Built on the rest pose, not on this frame: results do not depend on where playback started.
        solver = hemishadow.TransferSolver(mesh_io.read_rest(obj, frame_matrix), triangles, bands=settings.band_count,
                                           brdf=settings.brdf.lower(), exponent=settings.exponent if phong else None)
        entry = _entries[obj.session_uid] = _Entry(key, solver)
    return entry


def _view_directions(obj, scene, vertices, frame=None):
    """Per-vertex unit directions towards the active camera (Phong), or None (diffuse);
    `vertices` in world space, or in the object's frame (a mesh_io.Frame)."""
    if obj.hemishadow.brdf != "PHONG":
        return None
    if scene.camera is None:
        raise mesh_io.SkipObject(f"{obj.name}: the Phong BRDF needs an active camera for the view direction")
    eye = np.asarray(scene.camera.matrix_world.translation, np.float64)
    if frame is not None and frame.rotation is not None:
        eye = frame.rotation.T @ (eye - frame.offset)
    eye = eye.astype(np.float32)
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
    name: str = ""  # the object's, for error messages
    frame: mesh_io.Frame | None = None  # `vertices` and `view` are in it
    placement: tuple | None = None  # where the frame is in the world (see read_object)
    solved: np.ndarray | None = None  # the transfer of these positions, known already: nothing to solve
    casters: shadow_casters.Use | None = None  # the other objects shadowing this one, held until solved


#: ID.session_uid -> seconds of the object's last solve (jobs.py tells heavy objects by it).
solve_seconds: dict[int, float] = {}
_serials = itertools.count()


def read_object(obj, depsgraph, scene, *, force=False):
    """Main thread: the Request for the object's evaluated mesh; None when the positions (and
    view) are those of the last computation and `force` is false. Raises mesh_io.SkipObject
    (or the engine's ValueError building a solver), the message starting with the object's name."""
    t0 = time.perf_counter()
    try:
        vertices, triangles, normals, frame = mesh_io.read_in_frame(obj, depsgraph)
    except mesh_io.TopologyChanged as error:
        raise mesh_io.TopologyChanged(_drop_stale(obj, error)) from error
    view = _view_directions(obj, scene, vertices, frame)
    t1 = time.perf_counter()
    with named_errors(obj):
        entry = _solver_for(obj, vertices, triangles, frame.matrix)
        casters = shadow_casters.for_object(obj, scene, depsgraph)
    fingerprint = hash((vertices.tobytes(), None if view is None else view.tobytes(),
                        None if casters is None else casters.key(frame)))
    # Where the frame is in the world: turning changes the transfer, moving the lamps' light.
    placement = None if frame.rotation is None else (frame.rotation.tobytes(), frame.offset.tobytes())
    solved = entry.solved is not None and entry.fingerprint == fingerprint
    written = mesh_io.RADIANCE in obj.data.attributes  # gone after Clear, or undone
    if not force and written and solved and entry.transfer is not None and entry.placement == placement:
        entry.written = next(_serials)  # still current: results of requests read before this one are older
        return None
    return Request(obj.session_uid, entry, vertices, normals, view, fingerprint, t1 - t0, next(_serials),
                   name=obj.name, frame=frame, placement=placement,
                   solved=entry.solved if solved and not force else None, casters=casters)


def solve_object(request, progress=None):
    """Any thread, no Blender data: the transfer vectors of a Request. `progress` as the
    engine's (returning False raises hemishadow.Cancelled). In the object's frame: see
    `to_world_transfer`. A rigid motion of the object needs no solve."""
    if request.solved is not None:
        return request.solved
    casters = {} if request.casters is None else request.casters.solve_arguments(request.frame)
    with request.entry.lock, _named(request.name):
        t0 = time.perf_counter()
        transfer = request.entry.solver.solve(request.vertices, request.normals, request.view, progress=progress,
                                              **casters)
        if request.casters is not None:  # a cancelled request may run again (jobs.finish_all): held till dropped
            request.casters.release()
        request.solve_seconds = seconds = time.perf_counter() - t0
    # The engine answers a repeated solve of the same positions from a cache in no time:
    # decay rather than forget, so a heavy object does not pass for light after one.
    solve_seconds[request.uid] = max(seconds, solve_seconds.get(request.uid, 0.0) / 2)
    return transfer


def _shade_request(obj, scene, request, transfer, lighting):
    t0 = time.perf_counter()
    entry, frame = request.entry, request.frame
    entry.solved, entry.fingerprint, entry.written = transfer, request.fingerprint, request.serial
    entry.transfer, entry.placement = to_world_transfer(transfer, frame.rotation), request.placement
    result = _shade(obj, scene, entry.transfer, lighting, mesh_io.frame_to_world(request.vertices, frame))
    result.io_seconds = request.io_seconds
    result.note = "" if request.casters is None else request.casters.note()
    result.engine_seconds = request.solve_seconds + time.perf_counter() - t0
    return result


def compute_object(obj, depsgraph, scene, *, force=False, lighting=None, progress=None):
    """Transfer, AO and radiance of the object's evaluated mesh, as a Result; None when the
    positions (and view) are those of the last computation and `force` is false. `progress`
    is the engine's (hemishadow.Cancelled when it returns False).
    Raises mesh_io.SkipObject, or the engine's ValueError / RuntimeError, each message
    starting with the object's name.

    The engine computes in the object's frame (mesh_io.object_frame): a turned or mirrored
    object gets exactly the turned or mirrored transfer, and a rigid motion solves nothing."""
    with named_errors(obj):
        request = read_object(obj, depsgraph, scene, force=force)
        if request is None:
            return None
        if request.solved is None:  # never keep a stale pair if solve raises
            request.entry.solved, request.entry.transfer, request.entry.fingerprint = None, None, None
        return _shade_request(obj, scene, request, solve_object(request, progress), lighting)


def to_world_transfer(transfer, rotation):
    """Transfer (V, K) computed in an object frame, turned into world space by the frame's
    rotation (3, 3) (None: already there). Exact: rotations and mirrors keep each SH band."""
    if rotation is None:
        return transfer
    turn = _turn(np.asarray(rotation, np.float64).tobytes(), transfer.shape[1])
    return np.ascontiguousarray(mesh_io.matmul(transfer, turn.T), dtype=np.float32)


@functools.lru_cache(maxsize=64)
def _turn(rotation: bytes, k: int) -> np.ndarray:
    """(K, K) taking coefficients to the turned ones; kept, as objects seldom turn every frame
    (a least-squares fit: about 1 ms, as much as a small mesh's shading)."""
    import hemishadow

    turn = hemishadow.rotate_sh(np.eye(k, dtype=np.float32), np.frombuffer(rotation).reshape(3, 3))
    turn.flags.writeable = False
    return turn


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
        with named_errors(obj):
            mesh_io.check_computable(obj)
            result = _shade_request(obj, scene, request, transfer, lighting)
    except (ValueError, RuntimeError) as error:
        set_status(obj, str(error))
        raise
    _publish(obj, result, _note(obj, scope.shared_users(scene, [obj])))
    return result


def named_errors(obj):
    """Re-raise ValueError / RuntimeError (the engine's, Blender's) with the object's name in
    front, so every message path says which object failed; an engine that cannot be imported
    becomes a RuntimeError saying so."""
    return _named(obj.name)


@contextmanager
def _named(name):
    try:
        yield
    except ImportError as error:  # a broken install: say so where the user looks (the status)
        raise RuntimeError(f"{name}: the hemishadow engine could not be loaded ({error}); "
                           "reinstall the extension for this Blender and platform") from error
    except (ValueError, RuntimeError) as error:
        if not name or str(error).startswith(f"{name}: "):
            raise
        try:
            named = type(error)(f"{name}: {error}")
        except TypeError:  # an exception class with another constructor
            named = RuntimeError(f"{name}: {error}")
        raise named from error


def _shade(obj, scene, transfer, lighting=None, vertices=None):
    """Environment and suns (`lighting`, default the scene's) plus the lamps at `vertices`
    (default: the positions of the object's last computation); for an object with Probe
    Lighting, the probes' light at its place instead (probe_lighting.py)."""
    import hemishadow

    from . import lighting as scene_lights

    if vertices is not None:
        _positions[obj.session_uid] = vertices
    positions, found = _positions.get(obj.session_uid), None
    if probe_lighting.volume_of(obj) is not None:  # the grid's light here: World and lamps as baked
        lighting, found = probe_lighting.lighting(obj, scene, positions, obj.hemishadow.band_count), []
    elif lighting is None:
        lighting = scene_lighting(scene, obj.hemishadow.band_count)
    radiance = scene_lights.shade(scene, transfer, lighting, _albedo(obj), positions, found)
    return Result(transfer, hemishadow.ambient_occlusion(transfer), radiance)


def _write(obj, result):
    settings = obj.hemishadow
    t0 = time.perf_counter()
    mesh_io.write_outputs(obj, result.radiance, result.ao if settings.write_ao else None,
                          result.transfer if settings.write_sh else None)
    if not settings.write_ao:
        mesh_io.remove_ao(obj)  # an AO left from earlier would no longer follow the shadows
    mesh_io.remove_sh_layers(obj, keep=result.transfer.shape[1] if settings.write_sh else 0)
    return time.perf_counter() - t0


def set_status(obj, message):
    # Assigning an ID property tags the object for re-evaluation: only when it changes.
    if obj.hemishadow.status != message:
        obj.hemishadow.status = message


def _summary(obj, result):
    if obj.hemishadow.brdf == "PHONG":
        peak = float(result.radiance.max()) if len(result.radiance) else 0.0
        return f"{len(result.ao)} vertices, radiance up to {peak:.2f} (Phong: no AO, it is a diffuse quantity)"
    return f"{len(result.ao)} vertices, AO {float(result.ao.min()):.2f}..{float(result.ao.max()):.2f}"


def _drop_stale(obj, error):
    """The object stopped mapping onto its mesh: remove its outputs rather than let the last
    ones render as if current, and say so."""
    forget(obj)
    mesh_io.clear_outputs(obj)
    return f"{error}; its hemishadow outputs are removed until it can be computed again (they would be stale)"


def update_object(obj, depsgraph, scene, *, force=False, lighting=None, note="", progress=None):
    """Compute and write one object's outputs; returns the Result or None (nothing moved).
    Errors are raised as by compute_object; the status line is set either way (`note` is
    appended to it on success)."""
    try:
        result = compute_object(obj, depsgraph, scene, force=force, lighting=lighting, progress=progress)
    except (ValueError, RuntimeError) as error:
        set_status(obj, str(error))
        raise
    if result is None:
        return None
    _publish(obj, result, note)
    return result


def _publish(obj, result, note=""):
    result.io_seconds += _write(obj, result)
    last_timings[obj.name] = (len(result.ao), result.io_seconds, result.engine_seconds)
    set_status(obj, _summary(obj, result) + result.note + note)


def enabled_objects(scene):
    """The enabled mesh objects hemishadow computes: one per mesh (see objects.py)."""
    return scope.owners(scene, [o for o in scene.objects if o.type == "MESH" and o.hemishadow.enabled])[0]


#: name -> note on instances from the last full pass (Live switched on, Compute).
_instance_notes: dict[str, str] = {}


def scan_instances(scene, depsgraph):
    """Look for enabled objects drawn through instances (a walk over every instance: on explicit
    actions only); keeps the notes for the status of those computed and returns
    {name: message} of those that cannot be (not in the scene), with their status set."""
    import bpy

    _instance_notes.clear()
    refused = {}
    for name, (computed, note) in scope.instance_notes(scene, depsgraph).items():
        if computed:
            _instance_notes[name] = note
        else:
            refused[name] = f"{name}: {note}"
            set_status(bpy.data.objects[name], refused[name])
    return refused


def _note(obj, shared):
    note = scope.owner_note(obj, shared)
    instanced = _instance_notes.get(obj.name)
    return note + (f"; {instanced}" if instanced else "")


def update_scene(scene, depsgraph, objects=None, *, force=False, progress=None):
    """update_object for each object (default: the enabled ones); returns {name: error message}
    for those that were not computed, without raising (hemishadow.Cancelled excepted: `progress`
    is given the fraction of all objects done, and stops the work by returning False). Of objects sharing a mesh only the owner
    is computed (objects.py): the others asked for are returned with a message naming it.
    By default (Live switched on) also reports enabled objects that are not meshes or that are
    only instanced from outside the scene."""
    prune()
    errors = {}
    if objects is None:
        objects = [o for o in scene.objects if o.hemishadow.enabled]
        errors.update(scan_instances(scene, depsgraph))
    errors.update({o.name: mesh_io.not_a_mesh_message(o) for o in objects if o.type != "MESH"})
    computed, followers = scope.owners(scene, objects)
    errors.update(followers)
    for obj in objects:
        if obj.name in errors:
            set_status(obj, errors[obj.name])
    shared = scope.shared_users(scene, computed)
    with shadow_casters.one_pass():  # each casters collection is brought to this frame once
        _update_each(scene, depsgraph, computed, shared, errors, force=force, progress=progress)
    return errors


def _update_each(scene, depsgraph, computed, shared, errors, *, force, progress):
    lighting = {}
    for i, obj in enumerate(computed):
        share = None if progress is None else (lambda f, i=i: progress((i + f) / len(computed)))
        bands = obj.hemishadow.band_count
        try:
            with named_errors(obj):
                if bands not in lighting:
                    lighting[bands] = scene_lighting(scene, bands)
            update_object(obj, depsgraph, scene, force=force, lighting=lighting[bands], note=_note(obj, shared),
                          progress=share)
        except (ValueError, RuntimeError) as error:
            errors[obj.name] = str(error)
            set_status(obj, str(error))
        _mark_followers(obj, shared)


def compute_now(scene, depsgraph, objects=None):
    """What the Compute Now operator does: update_scene forced on `objects` (default: every
    enabled object), then (computed names, {name: error}, [warnings]); warnings name the
    objects that show another's result (shared meshes) and the instances of computed objects."""
    errors = update_scene(scene, depsgraph, objects, force=True)
    asked = [o for o in scene.objects if o.hemishadow.enabled] if objects is None else objects
    computed, followers = scope.owners(scene, asked)
    shared = scope.shared_users(scene, computed)
    warnings = [scope.sharing_warning(o, shared) for o in computed if o.name not in errors]
    warnings += [f"{name}: {note}" for name, note in _instance_notes.items()]
    for name in followers:
        errors.pop(name, None)
    return [o.name for o in computed if o.name not in errors], errors, [w for w in warnings if w]


def _mark_followers(owner, shared):
    for user in shared.get(owner.data.session_uid, ()):
        if user.session_uid != owner.session_uid:
            forget(user)  # a former owner must not re-shade the shared mesh with its own transfer
            solve_seconds.pop(user.session_uid, None)  # nor be sent to the worker as a heavy object
            set_status(user, scope.follower_status(user, owner))


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
        shadow_casters.forget()
        probe_lighting.forget()
        steady.forget()
    else:
        _entries.pop(obj.session_uid, None)
        _positions.pop(obj.session_uid, None)


def forget_positions():
    """Make the next update of every object compute and write again (after undo or redo the
    attributes may hold other values than the last ones computed), keeping the solvers."""
    steady.forget()
    for entry in _entries.values():
        entry.fingerprint = None


def prune():
    """Drop entries of objects that no longer exist (deleted, or a new file was loaded)."""
    import bpy

    alive = {o.session_uid for o in bpy.data.objects}
    for uid in [u for u in _entries if u not in alive]:
        del _entries[uid]
        _positions.pop(uid, None)
    steady.forget(alive)


def has_transfer(obj):
    entry = _entries.get(obj.session_uid)
    return entry is not None and entry.transfer is not None
