"""Bake animation: compute a frame range of hemishadow outputs into per-object caches.

`BakeJob` does the work in small steps on the main thread (step a frame, read each object's
evaluated mesh into numpy arrays) and hands each frame's arrays to one worker thread that
runs the engine, which releases the GIL; Blender data is touched on the main thread only.
`bake_range` drives a job to the end (scripts, the command line, tests); the modal operator
`hemishadow.bake_animation` drives it from a timer, so the UI stays responsive and Esc
cancels.
"""

from __future__ import annotations

import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

import bpy

from .. import cache, casters, engine_bridge, lamps, mesh_io, staleness, world_render
from .modal_job import ModalUi

__all__ = ["BakeJob", "BakeResult", "bake_range", "HEMISHADOW_OT_bake_animation", "HEMISHADOW_OT_clear_bake", "classes"]

#: Frames read ahead of the engine: one computing, one waiting.
_AHEAD = 2


class BakeResult:
    """What a bake did: per object the place its cache went, frames done, times."""

    def __init__(self):
        self.saved: dict[str, str] = {}
        self.frames_done = 0
        self.cancelled = False
        self.engine_seconds = 0.0     # worker time in the engine (transfer + shading)
        self.blender_seconds = 0.0    # main-thread time: frame_set, reading meshes, saving

    def __repr__(self):
        return (f"BakeResult(frames_done={self.frames_done}, cancelled={self.cancelled}, saved={self.saved}, "
                f"engine={self.engine_seconds:.3f}s, blender={self.blender_seconds:.3f}s)")


def _scene_of(context_or_scene):
    return context_or_scene if isinstance(context_or_scene, bpy.types.Scene) else context_or_scene.scene


class BakeJob:
    """A bake of `objects` over frame_start..frame_end (inclusive), advanced by `step()`.

    location: "FILE" (npz per object in `directory`, default `//hemishadow_cache`) or "PACKED".
    store_transfer: keep the transfer vectors (float16) so lighting can change after the bake.
    progress: called on the main thread as progress(frames_done, frame_count).
    cancel: a threading.Event; when set, the job stops (the engine between chunks of vertices of
        the frame in flight) and saves nothing.
    Raises ValueError for objects that cannot be baked (not meshes, in Edit Mode, empty range)
    and for a cache folder that cannot be written, before any frame is computed.
    """

    def __init__(self, context_or_scene, objects, frame_start, frame_end, *, location="FILE", directory=None,
                 store_transfer=True, progress=None, cancel=None):
        self.scene = _scene_of(context_or_scene)
        self.objects = list(objects)
        self.frame_start, self.frame_end = int(frame_start), int(frame_end)
        self.location, self.directory = location, directory
        self.store_transfer = store_transfer
        self.progress = progress
        self.cancel = cancel or threading.Event()
        self.result = BakeResult()
        self._check()
        if location == "FILE":
            for obj in self.objects:   # fail now, not after the last frame
                cache.check_directory(obj, directory)
        self._restore_frame = self.scene.frame_current
        self._next_frame = self.frame_start
        self._pending: list[tuple[int, Future]] = []
        self._frames: dict[str, dict[int, tuple]] = {obj.name: {} for obj in self.objects}
        self._fingerprints: dict[str, dict[int, np.ndarray]] = {obj.name: {} for obj in self.objects}
        self._casters: dict[str, dict[int, np.ndarray | None]] = {obj.name: {} for obj in self.objects}
        self._meta = {obj.name: self._object_meta(obj) for obj in self.objects}
        self._solvers = {}
        # An animated World is rendered for every frame now: the frame handlers cannot.
        world_render.precompute(self.scene, range(self.frame_start, self.frame_end + 1))
        self._shading = {obj.name: _shading_of(obj, self.scene) for obj in self.objects}
        self._lamps: dict[int, tuple] = {}   # frame -> (lamps, their key)
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="hemishadow-bake")
        self._inflight = 0.0    # fraction of the frame the worker is computing (it writes, we read)
        self._fraction = 0.0
        self._baking = cache.baking()
        self._baking.__enter__()
        self.finished = False

    @property
    def frame_count(self) -> int:
        return self.frame_end - self.frame_start + 1

    @property
    def fraction_done(self) -> float:
        """Main thread: the fraction of the range done, within frames too (the engine's progress
        through the vertices of the frame it computes); never goes back."""
        now = (self.result.frames_done + min(self._inflight, 1.0)) / self.frame_count
        self._fraction = max(self._fraction, min(now, 1.0))
        return self._fraction

    def _engine_progress(self, fraction: float) -> bool:
        """Worker thread, from the engine: note the frame's progress; False (stop) once cancelled."""
        self._inflight = fraction
        return not self.cancel.is_set()

    def _check(self):
        if self.frame_end < self.frame_start:
            raise ValueError(f"the frame range {self.frame_start}..{self.frame_end} is empty")
        if not self.objects:
            raise ValueError("no objects to bake: enable hemishadow on a mesh or pass its name")
        for obj in self.objects:
            if obj is None or getattr(obj, "type", None) != "MESH":
                raise ValueError(f"{getattr(obj, 'name', obj)!r} is not a mesh object")
            mesh_io.check_computable(obj)   # SkipObject (a ValueError) says why not
        if self.location not in ("FILE", "PACKED"):
            raise ValueError(f"cache location must be FILE or PACKED, got {self.location!r}")

    def _frame_input(self, obj, depsgraph) -> "FrameInput":
        vertices, triangles, normals, frame = mesh_io.read_in_frame(obj, depsgraph)
        # The topology can change inside a range (a modifier switched by animation): rebuild then.
        # The key is kept here: a solver is busy in the worker thread and must not be asked.
        key = (len(vertices), hash(triangles.tobytes()))
        known = self._solvers.get(obj.name)
        if known is None or known[0] != key:
            known = self._solvers[obj.name] = (key, _make_solver(obj, vertices, triangles, frame.matrix))
        solver = known[1]
        _, albedo = self._shading[obj.name]
        lighting = engine_bridge.scene_lighting(self.scene, obj.hemishadow.band_count)   # this frame's
        view = engine_bridge._view_directions(obj, self.scene, vertices, frame)   # None for diffuse
        self._fingerprints[obj.name][self.scene.frame_current] = staleness.fingerprint(
            mesh_io.frame_to_world(vertices, frame), cache._eye(obj, self.scene))
        self._casters[obj.name][self.scene.frame_current] = casters.fingerprint(obj, self.scene, depsgraph)
        frame_lamps = self._lamps[self.scene.frame_current][0]
        with engine_bridge.named_errors(obj):
            shadows = casters.for_object(obj, self.scene, depsgraph)   # held until the worker solved it
        return FrameInput(solver, vertices, normals, view, lighting, albedo, frame_lamps, frame, shadows)

    def _object_meta(self, obj) -> dict:
        return dict(version=cache.VERSION, object=obj.name, frame_start=self.frame_start,
                    signature=cache.signature(obj), rest=cache.rest_signature(obj),
                    settings=cache.transfer_settings(obj), inputs=staleness.inputs(obj, self.scene),
                    casters=casters.describe(obj, self.scene))

    # -- the steps --------------------------------------------------------------------------

    def step(self, budget_seconds=0.05) -> bool:
        """Main thread: collect finished frames, read ahead, report progress; returns True when
        the job is over (done or cancelled). Blocks at most about `budget_seconds` on the engine."""
        if self.finished:
            return True
        self._collect(block=False)
        if self.cancel.is_set():
            return self._finish(cancelled=True)
        if self._next_frame <= self.frame_end and len(self._pending) < _AHEAD:
            self._submit(self._next_frame)
            self._next_frame += 1
        elif self._pending:
            self._collect(block=True, timeout=budget_seconds)
        if not self._pending and self._next_frame > self.frame_end:
            return self._finish(cancelled=self.cancel.is_set())
        return False

    def _submit(self, frame: int):
        t0 = time.perf_counter()
        self.scene.frame_set(frame)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        found = lamps.scene_lamps(self.scene)
        self._lamps[frame] = (found, lamps.lamps_key(self.scene))
        with casters.one_pass():
            inputs = [self._frame_input(obj, depsgraph) for obj in self.objects]
        self.result.blender_seconds += time.perf_counter() - t0
        self._pending.append((frame, self._executor.submit(_compute_frame, inputs, self.store_transfer,
                                                           self._engine_progress)))

    def _collect(self, block: bool, timeout: float = 0.0):
        while self._pending:
            frame, future = self._pending[0]
            if not future.done():
                if not block:
                    return
                try:
                    future.result(timeout=timeout)
                except TimeoutError:
                    return
                except Exception:
                    pass   # raised again below
            if self.cancel.is_set() and _was_cancelled(future):
                return   # the engine stopped for the cancel: step() finishes the job
            self._pending.pop(0)
            outputs, seconds = future.result()
            self._inflight = 0.0
            self.result.engine_seconds += seconds
            for obj, output in zip(self.objects, outputs):
                self._frames[obj.name][frame] = output
            self.result.frames_done += 1
            if self.progress is not None:
                self.progress(self.result.frames_done, self.frame_count)
            block = False

    def _finish(self, cancelled: bool) -> bool:
        self.finished = True
        self.result.cancelled = cancelled
        for _, future in self._pending:
            future.cancel()
        self._executor.shutdown(wait=True)
        self._pending.clear()
        self._baking.__exit__(None, None, None)
        t0 = time.perf_counter()
        if not cancelled:
            for obj in self.objects:
                self.result.saved[obj.name] = cache.save(obj, self._assemble(obj), location=self.location,
                                                         directory=self.directory)
        self.scene.frame_set(self._restore_frame)
        self.result.blender_seconds += time.perf_counter() - t0
        return True

    def abort(self):
        """Stop at once (exceptions, operator cancel): nothing is saved."""
        if not self.finished:
            self.cancel.set()
            self._finish(cancelled=True)

    def _assemble(self, obj) -> cache.BakeCache:
        frames = self._frames[obj.name]
        order = range(self.frame_start, self.frame_end + 1)
        radiance = np.stack([frames[f][0] for f in order]).astype(np.float32)
        ao = np.stack([frames[f][1] for f in order]).astype(np.float32)
        transfer = np.stack([frames[f][2] for f in order]) if self.store_transfer else None
        meta = dict(self._meta[obj.name])
        first = frames[self.frame_start]
        meta["lighting"] = np.asarray(first[3], np.float32).tolist()
        meta["albedo"] = np.asarray(first[4], np.float32).tolist()
        meta["lamps"] = self._lamps[self.frame_start][1]
        fingerprint = np.stack([self._fingerprints[obj.name][f] for f in order])
        shadows = [self._casters[obj.name][f] for f in order]
        shadows = None if shadows[0] is None else np.stack(shadows)   # the same collection on every frame
        return cache.BakeCache(self.frame_start, radiance, ao, transfer, meta, fingerprint, shadows)


class FrameInput:
    """One object's arrays for one frame, and the solver that turns them into transfer."""

    __slots__ = ("solver", "vertices", "normals", "view", "lighting", "albedo", "lamps", "frame", "casters")

    def __init__(self, solver, vertices, normals, view, lighting, albedo, lamps=(), frame=None, casters=None):
        """`vertices` (and `view`) in the object's frame (mesh_io.read_in_frame); `casters` a
        casters.Use (None: self-shadowing only)."""
        self.solver, self.vertices, self.normals, self.view = solver, vertices, normals, view
        self.lighting, self.albedo, self.lamps, self.frame = lighting, albedo, lamps, frame
        self.casters = casters

    def compute(self, progress=None):
        """Worker thread: (transfer (V, K), radiance (V, 3), ao (V,)). `progress` is the engine's
        (a False return stops it with hemishadow.Cancelled)."""
        import hemishadow

        shadows = {} if self.casters is None else self.casters.solve_arguments(self.frame)
        solved = self.solver.solve(self.vertices, self.normals, view=self.view, progress=progress, **shadows)
        if self.casters is not None:
            self.casters.release()   # else when the input is dropped
        transfer = engine_bridge.to_world_transfer(solved, self.frame.rotation)
        radiance = hemishadow.shade(transfer, self.lighting, self.albedo)
        if self.lamps:   # numpy only: safe in the worker
            radiance += np.asarray(self.albedo, np.float32) / np.pi * lamps.lamp_irradiance(
                transfer, mesh_io.frame_to_world(self.vertices, self.frame), self.lamps)
        return transfer, radiance, hemishadow.ambient_occlusion(transfer)


def _compute_frame(inputs, store_transfer, progress=None):
    """Worker thread: no bpy here, only numpy arrays and the engine. `progress(fraction of the
    frame)` as the engine's."""
    t0 = time.perf_counter()
    outputs = []
    for i, item in enumerate(inputs):
        share = None if progress is None else (lambda f, i=i: progress((i + f) / len(inputs)))
        transfer, radiance, ao = item.compute(share)
        outputs.append((radiance, ao, transfer.astype(np.float16) if store_transfer else None,
                        item.lighting, item.albedo))
    return outputs, time.perf_counter() - t0


def _was_cancelled(future) -> bool:
    import hemishadow

    return future.done() and isinstance(future.exception(), hemishadow.Cancelled)


# -- the live path's pieces (mesh_io, engine_bridge), used the same way -------------------------

def _make_solver(obj, vertices, triangles, frame_matrix=None):
    import hemishadow

    settings = obj.hemishadow
    phong = settings.brdf == "PHONG"
    # Built from the same rest pose as the live path's solver, so both compute the same values.
    return hemishadow.TransferSolver(mesh_io.read_rest(obj, frame_matrix), triangles, bands=settings.band_count,
                                     brdf=settings.brdf.lower(),
                                     exponent=settings.exponent if phong else None)


def _shading_of(obj, scene):
    lighting = np.asarray(engine_bridge.scene_lighting(scene, obj.hemishadow.band_count), np.float32)
    return lighting, np.asarray(obj.hemishadow.albedo, np.float32)


def bake_range(context_or_scene, objects, frame_start, frame_end, *, progress=None, cancel=None, location="FILE",
               directory=None, store_transfer=True, fraction=None) -> BakeResult:
    """Bake `objects` over frame_start..frame_end (inclusive) into their caches and return a
    `BakeResult`. Blocks until done; `cancel` (threading.Event) stops it early, saving nothing.
    `fraction`: called on this thread with `BakeJob.fraction_done` whenever it grew (for a
    progress bar that moves within the frames of a heavy mesh). Other arguments as `BakeJob`."""
    job = BakeJob(context_or_scene, objects, frame_start, frame_end, progress=progress, cancel=cancel,
                  location=location, directory=directory, store_transfer=store_transfer)
    shown = -1.0
    if fraction is not None:  # 0 first, even when the first step already finishes a frame
        shown = 0.0
        fraction(shown)
    try:
        while not job.step(budget_seconds=0.1 if fraction else 0.5):
            if fraction is not None and job.fraction_done > shown:
                shown = job.fraction_done
                fraction(shown)
        if fraction is not None and job.fraction_done > shown:
            fraction(job.fraction_done)   # the last frames, collected by the final step
    except BaseException:
        job.abort()
        raise
    return job.result


def bakeable_objects(context):
    """The objects the operator bakes: selected meshes with hemishadow enabled, else all enabled."""
    enabled = engine_bridge.enabled_objects(context.scene)
    selected = [o for o in enabled if o.select_get()]
    return selected or enabled


class HEMISHADOW_OT_bake_animation(ModalUi, bpy.types.Operator):
    """Compute the scene's frame range into a cache per object; playback and animation renders then copy it"""

    bl_idname = "hemishadow.bake_animation"
    bl_label = "Bake Animation"
    bl_options = {"REGISTER"}

    frame_start: bpy.props.IntProperty(name="Start", description="First frame (-1: the scene's start)", default=-1)
    frame_end: bpy.props.IntProperty(name="End", description="Last frame (-1: the scene's end)", default=-1)
    location: bpy.props.EnumProperty(
        name="Cache", default="FILE",
        items=[("FILE", "Beside the .blend", "//hemishadow_cache/<object>.npz"),
               ("PACKED", "Packed in the .blend", "Stored inside the .blend file")])
    store_transfer: bpy.props.BoolProperty(
        name="Keep Transfer", default=True,
        description="Also store the transfer vectors (float16), so lighting changes re-shade from the cache")

    _job = None

    @classmethod
    def poll(cls, context):
        return bool(bakeable_objects(context))

    def _range(self, scene):
        start = scene.frame_start if self.frame_start < 0 else self.frame_start
        end = scene.frame_end if self.frame_end < 0 else self.frame_end
        return start, end

    def _start(self, context):
        start, end = self._range(context.scene)
        return BakeJob(context, bakeable_objects(context), start, end, location=self.location,
                       store_transfer=self.store_transfer, progress=self._progress)

    def _progress(self, done, count):
        bpy.context.window_manager.progress_update(done)
        self._status(bpy.context, f"Hemishadow: baking frame {done} of {count}  (Esc to cancel)")

    def execute(self, context):
        # Without a window (scripts, background mode): bake in one go.
        start, end = self._range(context.scene)
        try:
            result = bake_range(context, bakeable_objects(context), start, end, location=self.location,
                                store_transfer=self.store_transfer)
        except (ValueError, RuntimeError, OSError) as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        self.report({"INFO"}, f"hemishadow: baked {result.frames_done} frames of {len(result.saved)} objects")
        return {"FINISHED"}

    def invoke(self, context, event):
        if context.window is None:
            return self.execute(context)
        try:
            self._job = self._start(context)
        except (ValueError, RuntimeError, OSError) as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        self._area = context.area
        wm = context.window_manager
        wm.progress_begin(0, self._job.frame_count)
        self._timer = wm.event_timer_add(0.01, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC":
            self._job.cancel.set()
        if event.type not in {"TIMER", "ESC"}:
            return {"PASS_THROUGH"}
        try:
            done = self._job.step(budget_seconds=0.03)
        except Exception as error:   # reported once, the job stopped, nothing saved
            self._job.abort()
            self._end(context)
            self.report({"ERROR"}, f"hemishadow: bake failed: {error}")
            return {"CANCELLED"}
        if not done:
            return {"RUNNING_MODAL"}
        self._end(context)
        result = self._job.result
        if result.cancelled:
            self.report({"WARNING"}, f"hemishadow: bake cancelled after {result.frames_done} frames; nothing saved")
            return {"CANCELLED"}
        self.report({"INFO"}, f"hemishadow: baked {result.frames_done} frames: " + ", ".join(result.saved.values()))
        return {"FINISHED"}

    def cancel(self, context):
        # Blender cancels a running modal operator when it loads another file or quits.
        if self._job is not None:
            self._job.abort()
        self._end(context)


class HEMISHADOW_OT_clear_bake(bpy.types.Operator):
    """Delete the bake cache of the selected (or active) objects"""

    bl_idname = "hemishadow.clear_bake"
    bl_label = "Clear Bake"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        objects = [o for o in (context.selected_objects or [context.active_object]) if o is not None]
        for obj in objects:
            cache.clear(obj)
        return {"FINISHED"}


classes = (HEMISHADOW_OT_bake_animation, HEMISHADOW_OT_clear_bake)
