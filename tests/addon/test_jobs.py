"""Heavy meshes in the worker thread (addon/jobs.py): stale results until the new one is
written, latest wins, cancel, progress, and the synchronous paths (renders, scripts).

Headless Blender has no window, so the tests drive the machinery as the live handlers do in
a window: `jobs.update_scene(..., interactive=True)`, then `jobs.poll()` by hand where
Blender's timer would call it. The heavy case is a subdivided Suzanne with a Wave modifier
(its shape, hence its shadows, change every frame).
"""

import os
import sys
import threading
import time
import types

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import hemishadow  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT)
import addon  # noqa: E402
from addon import engine_bridge, jobs, mesh_io  # noqa: E402


class Gate:
    """Jobs wait in the worker, before the engine, until `open()`: the test decides what is
    running when. Synchronous solves (main thread) pass."""

    def __init__(self, monkeypatch):
        self.entered, self.released = threading.Event(), threading.Event()
        self.progress_calls = {}  # Request.serial -> fractions reported
        real = engine_bridge.solve_object

        def solve(request, progress=None):
            if threading.current_thread() is threading.main_thread():
                return real(request, progress)
            self.entered.set()
            assert self.released.wait(30), "the test never opened the gate"

            def counted(fraction):
                self.progress_calls.setdefault(request.serial, []).append(fraction)
                return progress(fraction)

            return real(request, counted)

        monkeypatch.setattr(engine_bridge, "solve_object", solve)

    def open(self):
        self.released.set()


@pytest.fixture
def gate(monkeypatch):
    gate = Gate(monkeypatch)
    yield gate
    gate.open()  # never leave a worker waiting


@pytest.fixture
def lower_threshold(monkeypatch):
    """Heavy from 0.01 s per solve: the 7,958-vertex Suzanne stays heavy however fast the
    engine gets (the default threshold is for people, not for tests)."""
    monkeypatch.setattr(jobs, "HEAVY_SECONDS", 0.01)


def suzanne(levels):
    """Suzanne subdivided `levels` times (2: 7,958 vertices, 3: 31,658) with a Wave modifier."""
    bpy.ops.mesh.primitive_monkey_add()
    obj = bpy.context.active_object
    if levels:
        obj.modifiers.new("subdivide", "SUBSURF").levels = levels
        bpy.ops.object.modifier_apply(modifier="subdivide")
    wave = obj.modifiers.new("wave", "WAVE")
    wave.height, wave.width, wave.speed = 0.2, 0.5, 0.05
    obj.hemishadow.enabled = True
    return obj


def radiance(obj):
    data = obj.data.attributes[mesh_io.RADIANCE].data
    out = np.empty(len(data) * 4, np.float32)
    data.foreach_get("color", out)
    return out.reshape(-1, 4)[:, :3]


def depsgraph():
    return bpy.context.evaluated_depsgraph_get()


def first_result(scene, obj):
    """Frame 1 computed synchronously: the previous result, and the solve time that makes the
    object heavy."""
    scene.frame_set(1)
    assert jobs.update_scene(scene, depsgraph(), [obj]) == {}
    assert jobs.heavy(obj) and not jobs.pending()
    return radiance(obj)


def request(scene, obj, frame, **options):
    """What the live handlers do in a window after Blender changed the frame (Live is off
    here, so the handlers themselves do nothing)."""
    scene.frame_set(frame)
    errors = jobs.update_scene(scene, depsgraph(), [obj], interactive=True, **options)
    assert errors == {}
    return jobs.pending([obj])[-1] if jobs.pending([obj]) else None


def run_jobs(timeout=60.0):
    """Poll as Blender's timer would until the jobs are done; returns the longest poll."""
    longest, deadline = 0.0, time.perf_counter() + timeout
    while True:
        t0 = time.perf_counter()
        again = jobs.poll()
        longest = max(longest, time.perf_counter() - t0)
        if again is None:
            return longest
        assert time.perf_counter() < deadline, "jobs did not finish"
        time.sleep(0.01)


def wait_for(condition, timeout=30.0):
    deadline = time.perf_counter() + timeout
    while not condition():
        assert time.perf_counter() < deadline
        time.sleep(0.005)


def sync_radiance(scene, obj):
    """This frame's radiance on the synchronous path, not written (the engine answers from its
    cache when the worker solved these very positions, and computes them again otherwise)."""
    return engine_bridge.compute_object(obj, depsgraph(), scene, force=True).radiance


def writes(monkeypatch):
    """The requests whose results engine_bridge writes, in order."""
    written = []
    real = engine_bridge.finish_object

    def finish(obj, scene, request, transfer, lighting=None):
        result = real(obj, scene, request, transfer, lighting)
        if result is not None:
            written.append(request)
        return result

    monkeypatch.setattr(engine_bridge, "finish_object", finish)
    return written


# -- the heavy case ------------------------------------------------------------------------------

def test_heavy_frame_computes_in_worker_showing_stale_result(scene, monkeypatch):
    """31,658 vertices (about a second per solve): the frame change returns at once, the
    previous result stays on display marked stale with progress, polls never block, and the
    new result is that of the synchronous path. On main the same call blocks for the whole
    solve. Progress shows after 0.1 s here (1 s in Blender): a quiet machine solves this in
    under a second."""
    monkeypatch.setattr(jobs, "PROGRESS_AFTER", 0.1)
    obj = suzanne(3)
    t0 = time.perf_counter()
    before = first_result(scene, obj)
    synchronous = time.perf_counter() - t0
    t0 = time.perf_counter()
    request(scene, obj, 4)
    assert time.perf_counter() - t0 < synchronous / 10  # blocked by reading the mesh only, not by the engine
    statuses, longest, deadline, progress = set(), 0.0, time.perf_counter() + 120, set()
    while True:
        np.testing.assert_array_equal(radiance(obj), before)  # the previous result, untouched
        statuses.add(obj.hemishadow.status)
        t0 = time.perf_counter()
        again = jobs.poll()
        longest = max(longest, time.perf_counter() - t0)
        progress.add(jobs._progress_on)  # the window manager's progress, after PROGRESS_AFTER
        if again is None:
            break
        assert time.perf_counter() < deadline
        time.sleep(0.02)
    assert longest < synchronous / 10, f"a poll blocked the main thread for {longest:.3f} s"
    assert progress == {False, True} and not jobs._progress_on  # shown while it ran for seconds, then ended
    computing = [s for s in statuses if s.startswith("stale (showing frame 1): computing frame 4, ")]
    assert computing and all(s.endswith(" %") for s in computing), statuses
    assert not obj.hemishadow.status.startswith("stale") and obj.hemishadow.status.startswith("31658 vertices")
    after = radiance(obj)
    assert np.abs(after - before).max() > 0.02, "frame 4 has other shadows than frame 1"
    np.testing.assert_allclose(after, sync_radiance(scene, obj), atol=1e-5)
    assert jobs.poll() is None and jobs._worker is None


def test_live_handlers_send_heavy_objects_to_worker_in_a_window(scene, lower_threshold, monkeypatch):
    """Frame changes and edits made by Blender in a window (here: pretended) queue the heavy
    object; on main they computed it before returning."""
    obj = suzanne(2)
    before = first_result(scene, obj)
    scene.hemishadow.live = True
    monkeypatch.setattr(jobs, "interactive", lambda: True)
    scene.frame_set(2)
    assert jobs.pending([obj]) and obj.hemishadow.status.startswith("stale (showing frame 1): ")
    np.testing.assert_array_equal(radiance(obj), before)
    run_jobs()
    frame2 = radiance(obj)
    np.testing.assert_allclose(frame2, sync_radiance(scene, obj), atol=1e-5)
    obj.modifiers["wave"].height = 0.35  # an edit: depsgraph_update_post
    bpy.context.view_layer.update()
    assert jobs.pending([obj]) and obj.hemishadow.status.startswith("stale (showing frame 2): ")
    np.testing.assert_array_equal(radiance(obj), frame2)
    run_jobs()
    assert np.abs(radiance(obj) - frame2).max() > 0.01
    np.testing.assert_allclose(radiance(obj), sync_radiance(scene, obj), atol=1e-5)


def test_heavy_by_vertex_count_then_by_solve_time(scene):
    light = suzanne(1)
    assert not jobs.heavy(light) and len(light.data.vertices) < jobs.HEAVY_VERTICES
    engine_bridge.solve_seconds[light.session_uid] = 2 * jobs.HEAVY_SECONDS
    assert jobs.heavy(light)
    engine_bridge.solve_seconds[light.session_uid] = jobs.HEAVY_SECONDS / 2
    assert not jobs.heavy(light)


def test_light_objects_stay_synchronous(scene):
    obj = suzanne(0)  # 507 vertices
    scene.frame_set(3)
    assert jobs.update_scene(scene, depsgraph(), [obj], interactive=True) == {}
    assert not jobs.pending() and mesh_io.RADIANCE in obj.data.attributes
    assert not jobs.heavy(obj)


# -- latest wins ----------------------------------------------------------------------------------

def test_newer_frame_cancels_running_job(scene, lower_threshold, gate, monkeypatch):
    obj = suzanne(2)
    first_result(scene, obj)
    written = writes(monkeypatch)
    old = request(scene, obj, 2)
    assert gate.entered.wait(10)
    new = request(scene, obj, 3)
    assert old.cancel.is_set() and jobs.pending() == [new]
    assert obj.hemishadow.status == "stale (showing frame 1): frame 3 waiting"
    gate.open()
    run_jobs()
    assert old.transfer is None and written == [new.request]  # the engine stopped; nothing of frame 2 written
    assert len(gate.progress_calls.get(old.request.serial, [])) <= 1
    np.testing.assert_allclose(radiance(obj), sync_radiance(scene, obj), atol=1e-5)


def test_playback_lets_running_job_finish_then_latest(scene, lower_threshold, gate, monkeypatch):
    """During playback the running job finishes (results at the engine's pace), the waiting
    one is replaced by the newest frame, and results are written in order."""
    obj = suzanne(2)
    first_result(scene, obj)
    written = writes(monkeypatch)
    running = request(scene, obj, 2, keep_running=True)
    assert gate.entered.wait(10)
    skipped = request(scene, obj, 3, keep_running=True)
    latest = request(scene, obj, 4, keep_running=True)
    assert skipped.cancel.is_set() and jobs.pending() == [running, latest]
    assert obj.hemishadow.status == "stale (showing frame 1): computing frame 2, 0 %, frame 4 next"
    gate.open()
    run_jobs()
    assert written == [running.request, latest.request]
    np.testing.assert_allclose(radiance(obj), sync_radiance(scene, obj), atol=1e-5)


def test_older_result_never_written_over_newer(scene, lower_threshold, gate, monkeypatch):
    """A job of frame 2 still running when frame 3 is computed synchronously by a path that
    does not know about jobs (the command line, Compute Now from a script): its result,
    older, is dropped."""
    obj = suzanne(2)
    first_result(scene, obj)
    written = writes(monkeypatch)
    old = request(scene, obj, 2)
    assert gate.entered.wait(10)
    scene.frame_set(3)
    assert engine_bridge.update_scene(scene, depsgraph(), [obj]) == {}
    frame3 = radiance(obj)
    gate.open()
    wait_for(lambda: jobs._worker is None)
    run_jobs()
    assert old.transfer is not None and written == []  # computed, but older: not written
    np.testing.assert_array_equal(radiance(obj), frame3)
    assert obj.hemishadow.status.startswith("7958 vertices")


def test_back_to_shown_frame_drops_job(scene, lower_threshold, gate):
    obj = suzanne(2)
    before = first_result(scene, obj)
    status = obj.hemishadow.status
    old = request(scene, obj, 2)
    assert request(scene, obj, 1) is None  # the result on display is frame 1's: current again
    assert old.cancel.is_set() and not jobs.pending()
    assert obj.hemishadow.status == status
    gate.open()
    run_jobs()
    np.testing.assert_array_equal(radiance(obj), before)


# -- cancel --------------------------------------------------------------------------------------

def test_cancel_keeps_previous_result_with_clear_status(scene, lower_threshold, gate):
    obj = suzanne(2)
    before = first_result(scene, obj)
    job = request(scene, obj, 2)
    assert gate.entered.wait(10)
    assert jobs.cancel() == 1
    assert obj.hemishadow.status == "cancelled: frame 2 not computed; showing frame 1 (stale)"
    gate.open()
    wait_for(lambda: jobs._worker is None)
    assert job.transfer is None and len(gate.progress_calls.get(job.request.serial, [])) <= 1  # stopped at once
    run_jobs()
    np.testing.assert_array_equal(radiance(obj), before)
    assert obj.hemishadow.status == "cancelled: frame 2 not computed; showing frame 1 (stale)"


def live_on_quietly(scene):
    """Live on without its update callback, which would compute at once (in a window the
    handlers would have queued the job that the test queues by hand)."""
    scene.hemishadow["live"] = True
    assert scene.hemishadow.live


def test_live_off_cancels(scene, lower_threshold, gate):
    obj = suzanne(2)
    first_result(scene, obj)
    request(scene, obj, 2)
    live_on_quietly(scene)
    scene.hemishadow.live = False
    assert not jobs.pending() and obj.hemishadow.status.startswith("cancelled: frame 2 not computed")


def test_cancel_operator(scene, lower_threshold, gate):
    obj = suzanne(2)
    first_result(scene, obj)
    assert not bpy.ops.hemishadow.cancel_jobs.poll()
    request(scene, obj, 2)
    assert bpy.ops.hemishadow.cancel_jobs() == {"FINISHED"}
    assert not jobs.pending() and obj.hemishadow.status.startswith("cancelled")


# -- the synchronous paths ----------------------------------------------------------------------

def test_scripted_frame_set_is_synchronous_and_wins(scene, lower_threshold, gate):
    obj = suzanne(2)
    first_result(scene, obj)
    old = request(scene, obj, 2)
    scene.hemishadow.live = True
    scene.frame_set(3)  # from a script: computed before frame_set returns
    assert old.cancel.is_set() and not jobs.pending()
    np.testing.assert_allclose(radiance(obj), sync_radiance(scene, obj), atol=1e-5)
    assert obj.hemishadow.status.startswith("7958 vertices")


def test_only_blender_itself_is_interactive(scene):
    """A script's frame_set has Python below the handler; Blender's playback has none."""
    assert not jobs.interactive()  # background mode, and called from Python
    assert not jobs._called_by_blender()
    seen = []
    code = compile("seen.append(jobs._called_by_blender())", "handlers.py", "exec")
    as_handler = types.FunctionType(code, {"__name__": f"{jobs.__package__}.handlers", "jobs": jobs, "seen": seen})
    import _thread

    _thread.start_new_thread(as_handler, ())  # no Python frame below it, as when Blender calls
    wait_for(lambda: seen)
    assert seen == [True]


def test_rendering_is_synchronous(scene, lower_threshold):
    obj = suzanne(2)
    first_result(scene, obj)
    jobs.set_rendering(True)
    try:
        assert request(scene, obj, 2) is None and mesh_io.RADIANCE in obj.data.attributes
        np.testing.assert_allclose(radiance(obj), sync_radiance(scene, obj), atol=1e-5)
    finally:
        jobs.set_rendering(False)


def test_render_waits_for_jobs(scene, lower_threshold, gate):
    """A still render of a frame whose heavy object is still computing: render_init and
    render_pre wait for the job and write it, so the render is not stale."""
    obj = suzanne(2)
    first_result(scene, obj)
    request(scene, obj, 2)
    seen = []

    def record(render_scene, *_):
        seen.append((jobs.rendering(), radiance(obj).copy(), obj.hemishadow.status))

    bpy.app.handlers.render_post.append(record)
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(camera)
    scene.camera, camera.location = camera, (0, -5, 0)
    camera.rotation_euler = (1.5708, 0, 0)
    render = scene.render
    render.engine, render.resolution_x, render.resolution_y = "CYCLES", 8, 8
    scene.cycles.device, scene.cycles.samples = "CPU", 1
    threading.Timer(0.3, gate.open).start()
    try:
        bpy.ops.render.render()
    finally:
        bpy.app.handlers.render_post.remove(record)
    (rendering, rendered, status), = seen
    assert rendering and not jobs.rendering() and not jobs.pending()
    assert status.startswith("7958 vertices")
    np.testing.assert_allclose(rendered, sync_radiance(scene, obj), atol=1e-5)


def test_recomputes_cancelled_before_render(scene, lower_threshold, gate):
    obj = suzanne(2)
    first_result(scene, obj)
    request(scene, obj, 2)
    live_on_quietly(scene)
    jobs.cancel()
    gate.open()
    addon.handlers.on_render_init(scene)
    addon.handlers.on_render_pre(scene)
    addon.handlers.on_render_end(scene)
    assert obj.hemishadow.status.startswith("7958 vertices")
    np.testing.assert_allclose(radiance(obj), sync_radiance(scene, obj), atol=1e-5)


def test_compute_operator_without_window_is_synchronous(scene, lower_threshold):
    obj = suzanne(2)
    engine_bridge.solve_seconds[obj.session_uid] = 1.0  # heavy
    bpy.context.view_layer.objects.active = obj
    assert bpy.ops.hemishadow.compute("INVOKE_DEFAULT") == {"FINISHED"}
    assert not jobs.pending() and obj.hemishadow.status.startswith("7958 vertices")


# -- threads -------------------------------------------------------------------------------------

def test_worker_never_touches_blender_data(scene, lower_threshold, monkeypatch):
    obj = suzanne(2)
    first_result(scene, obj)
    threads = {}
    for module, name in ((mesh_io, "read_in_frame"), (mesh_io, "write_outputs"), (engine_bridge, "set_status"),
                         (engine_bridge, "read_object"), (engine_bridge, "finish_object"),
                         (engine_bridge, "solve_object")):
        real = getattr(module, name)

        def spy(*args, _real=real, _name=name, **kwargs):
            threads.setdefault(_name, set()).add(threading.current_thread().name)
            return _real(*args, **kwargs)

        monkeypatch.setattr(module, name, spy)
    calls = []

    def profile(frame, event, arg):  # every Python and C call of threads started from now on
        if event == "call":
            calls.append(frame.f_globals.get("__name__", ""))
        elif event == "c_call":
            owner = getattr(arg, "__self__", None)
            calls.append("bpy data" if isinstance(owner, (bpy.types.bpy_struct, bpy.types.bpy_prop_collection))
                         else getattr(arg, "__module__", None) or "")

    wait_for(lambda: jobs._worker is None)
    threading.setprofile(profile)
    try:
        job = request(scene, obj, 2)
        run_jobs()
    finally:
        threading.setprofile(None)
    main = threading.main_thread().name
    assert threads["solve_object"] == {"hemishadow-jobs"}
    for name in ("read_in_frame", "write_outputs", "set_status", "read_object", "finish_object"):
        assert threads[name] == {main}, name
    assert f"{jobs.__package__}.engine_bridge" in calls  # the profile saw the worker
    assert not [c for c in calls if c == "bpy data" or c.startswith(("bpy", "bl_"))], set(calls)
    payload = list(vars(job).values()) + list(vars(job.request).values()) + list(vars(job.request.entry).values())
    assert not [v for v in payload if isinstance(v, (bpy.types.bpy_struct, bpy.types.bpy_prop_collection))]
    assert isinstance(job.transfer, np.ndarray) and isinstance(job.request.entry.solver, hemishadow.TransferSolver)
