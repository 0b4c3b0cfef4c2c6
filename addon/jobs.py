"""Heavy objects computed in a worker thread while the user plays or edits, so Blender stays
responsive (a 126k-vertex mesh takes tens of seconds per frame).

Only `update_scene(..., interactive=True)` sends work here, and only for heavy objects: those
whose last solve took more than HEAVY_SECONDS (before the first one: more than HEAVY_VERTICES
vertices). Light objects, renders, scripts and background mode compute synchronously, so a
rendered or scripted frame is never stale; `interactive()` tells the handlers which case is
which.

Each job is split by thread:
- main thread: engine_bridge.read_object reads the evaluated mesh into numpy (a Request);
- the worker: engine_bridge.solve_object runs the engine (which releases the GIL) with a
  progress callback that stops it when the job is cancelled; no Blender data at all;
- main thread: `poll`, a bpy.app.timers function, writes finished results with
  engine_bridge.finish_object and shows progress.

Until its result is written, an object keeps its previous result and its status says it is
stale. Latest wins: a newer request for an object replaces its waiting job and cancels its
running one (during playback the running one is let finish, so playback shows results at the
engine's pace), and engine_bridge never writes a result over one read later.
"""

import sys
import threading
import time
from dataclasses import dataclass, field

import bpy

from . import casters, engine_bridge, mesh_io

#: An object whose last solve took longer than this computes in the worker when interactive.
HEAVY_SECONDS = 0.1
#: Before an object's first solve: heavy above this many vertices.
HEAVY_VERTICES = 10_000
#: Seconds after which a running job shows progress in the window manager.
PROGRESS_AFTER = 1.0
#: Seconds between two polls of the worker while jobs are pending.
INTERVAL = 0.1


@dataclass(eq=False)
class Job:
    """One object's solve in the worker. Holds no Blender data: the object and scene are
    looked up again by `uid` and name on the main thread."""

    name: str
    scene: str
    frame: int
    request: engine_bridge.Request
    cancel: threading.Event = field(default_factory=threading.Event)
    fraction: float = 0.0               # written by the worker
    started: float | None = None        # perf_counter when the worker began
    transfer: object = None             # the result, or
    error: Exception | None = None      # what the engine raised

    @property
    def uid(self):
        return self.request.uid

    def progress(self, fraction):
        """The engine's callback, on the worker thread: False stops it."""
        self.fraction = fraction
        return not self.cancel.is_set()


_cond = threading.Condition()           # guards the four below
_waiting: dict[int, Job] = {}           # uid -> next job of that object, in order of arrival
_running: Job | None = None
_finished: list[Job] = []               # done in the worker, not yet written
_worker: threading.Thread | None = None

_shown: dict[int, int] = {}             # uid -> frame of the result on display
_status: dict[int, str] = {}            # uid -> status line of that result, restored when current again
_cancelled: dict[int, Job] = {}         # uid -> the user's last cancelled job, recomputed before a render
_errors: dict[int, str] = {}            # uid -> why its last job wrote nothing
_progress_on = False
_rendering = False


# -- deciding ----------------------------------------------------------------------------------

def heavy(obj):
    seconds = engine_bridge.solve_seconds.get(obj.session_uid)
    if seconds is None:
        return len(obj.data.vertices) > HEAVY_VERTICES
    return seconds > HEAVY_SECONDS


def _called_by_blender():
    """True when no Python code is below our handler on this thread's stack: Blender itself
    (playback, the timeline, a transform) changed the frame or the data, not a script."""
    frame = sys._getframe(1)
    while frame.f_back is not None:
        frame = frame.f_back
    name = frame.f_globals.get("__name__", "")
    return name == __package__ or name.startswith(__package__ + ".")


def interactive():
    """For the live handlers: may heavy objects go to the worker? Only in a window, on the
    main thread, outside renders, when Blender (not a script's frame_set) called them."""
    if bpy.app.background or _rendering or threading.current_thread() is not threading.main_thread():
        return False
    wm = bpy.context.window_manager
    return wm is not None and len(wm.windows) > 0 and _called_by_blender()


def playing():
    """True while a window plays the animation back (then running jobs are let finish)."""
    wm = bpy.context.window_manager
    return wm is not None and any(w.screen is not None and w.screen.is_animation_playing for w in wm.windows)


# -- requesting (main thread) ----------------------------------------------------------------------

def update_scene(scene, depsgraph, objects=None, *, interactive=False, force=False, keep_running=None):
    """engine_bridge.update_scene, except that with `interactive` heavy objects are queued for
    the worker instead of computed now (`keep_running` as `request`; None: while playing).
    Objects computed now drop their jobs first (their result is newer). Returns
    {name: error message} as engine_bridge.update_scene."""
    objects = engine_bridge.enabled_objects(scene) if objects is None else list(objects)
    queued = [o for o in objects if interactive and not _rendering and heavy(o)]
    now = [o for o in objects if o not in queued]
    if queued and keep_running is None:
        keep_running = playing()
    errors = {}
    with casters.one_pass():  # queued and computed objects see the same casters
        for obj in queued:
            try:
                request(obj, depsgraph, scene, force=force, keep_running=keep_running)
            except (ValueError, RuntimeError) as error:
                engine_bridge.set_status(obj, str(error))
                errors[obj.name] = str(error)
        drop(now, scene.frame_current)
        errors.update(engine_bridge.update_scene(scene, depsgraph, now, force=force))  # also prunes the dead
    return errors


def request(obj, depsgraph, scene, *, force=False, keep_running=False):
    """Queue the object's evaluated mesh for the worker and mark its result stale; returns the
    Job, or None when the result on display is current (its jobs, older, are dropped).
    `keep_running`: let the object's running job finish (playback) rather than stop it."""
    uid = obj.session_uid
    new = engine_bridge.read_object(obj, depsgraph, scene, force=force)
    with _cond:
        if new is None:
            _drop_locked({uid})
            job = None
        else:
            job = _queue_locked(Job(obj.name, scene.name, scene.frame_current, new), keep_running)
    if job is None:
        if uid in _status:
            engine_bridge.set_status(obj, _status[uid])
        _current(obj, scene.frame_current)
        return None
    _status.setdefault(uid, obj.hemishadow.status)
    engine_bridge.set_status(obj, _stale_text(obj))
    _start_timer()
    return job


def _queue_locked(job, keep_running):
    """Latest wins: a job computing the same positions is kept, any other of the object dropped
    (a running one only when not `keep_running`)."""
    same = [j for j in _jobs_locked({job.uid}) if j.request.fingerprint == job.request.fingerprint]
    if same:
        _drop_locked({job.uid}, keep=same[0])
        return same[0]
    _drop_locked({job.uid}, keep=_running if keep_running else None)
    _waiting[job.uid] = job
    _cancelled.pop(job.uid, None)
    _start_worker_locked()
    return job


def _start_worker_locked():
    global _worker
    if _worker is None:  # one at a time: a solver must not be used by two threads
        _worker = threading.Thread(target=_work, name="hemishadow-jobs", daemon=True)
        _worker.start()


def _jobs_locked(uids=None):
    jobs = [_running] if _running is not None and not _running.cancel.is_set() else []
    jobs += list(_waiting.values())
    return [j for j in jobs if uids is None or j.uid in uids]


def _drop_locked(uids, keep=None):
    for job in _jobs_locked(uids):
        if job is not keep:
            _cancel_locked(job)


def _cancel_locked(job):
    job.cancel.set()
    if _waiting.get(job.uid) is job:
        del _waiting[job.uid]


def drop(objects, frame):
    """The objects get this frame's result another way (computed now, or from a bake cache):
    stop their jobs, which are older, and take back the stale mark."""
    with _cond:
        _drop_locked({o.session_uid for o in objects})
    for obj in objects:
        if obj.session_uid in _status:
            engine_bridge.set_status(obj, _status[obj.session_uid])
        _current(obj, frame)


def _current(obj, frame):
    uid = obj.session_uid
    _shown[uid] = frame
    _status.pop(uid, None)
    _cancelled.pop(uid, None)
    _errors.pop(uid, None)


# -- the worker (no Blender data here) ---------------------------------------------------------------

def _work():
    global _running, _worker
    try:
        while True:
            with _cond:
                if not _waiting:
                    _worker = None  # in the same lock as the check: a new job then starts a new worker
                    _cond.notify_all()
                    return
                job = _waiting.pop(next(iter(_waiting)))
                _running = job
            try:
                _solve(job)
            finally:  # whatever happens, nobody waits for this job forever
                with _cond:
                    _running = None
                    _finished.append(job)
                    _cond.notify_all()
    except BaseException:
        with _cond:
            _worker = None
            _cond.notify_all()
        raise


def _solve(job):
    import hemishadow

    job.started = time.perf_counter()
    if job.cancel.is_set():
        return
    try:
        job.transfer = engine_bridge.solve_object(job.request, job.progress)
    except hemishadow.Cancelled:
        job.cancel.set()
    except Exception as error:  # noqa: BLE001 -- handed to the main thread, which reports it
        job.error = error


# -- results and progress (main thread) -------------------------------------------------------------

def poll():
    """The timer (tests call it by hand): write finished results, show progress. Returns the
    seconds until the next call, or None once idle, which ends the timer."""
    if _rendering:
        return INTERVAL  # the render computes synchronously; results wait for it to end
    _write_finished()
    return INTERVAL if _show_progress() else None


def _write_finished():
    with _cond:
        done = list(_finished)
        _finished.clear()
    for job in done:
        if not job.cancel.is_set():
            _write(job)


def _write(job):
    obj, scene = _object(job.uid), bpy.data.scenes.get(job.scene)
    if obj is None or scene is None:
        return  # deleted meanwhile
    result, message = None, None
    if job.error is not None:  # the engine's, raised in the worker
        message = str(job.error)
        engine_bridge.set_status(obj, message)
    else:
        try:
            result = engine_bridge.finish_object(obj, scene, job.request, job.transfer)
        except (ValueError, RuntimeError) as error:  # finish_object set the status
            message = str(error)
    if message is not None:
        _errors[job.uid] = message
        print(f"hemishadow: {obj.name}: {message}")
    elif result is not None:
        _current(obj, job.frame)
    elif not pending([obj]):
        _status.pop(job.uid, None)  # obsolete: whatever wrote the newer result set the status


def _object(uid):
    return next((o for o in bpy.data.objects if o.session_uid == uid), None)


def _show_progress():
    """Status lines of objects with jobs, and the window manager's progress once a job runs
    longer than PROGRESS_AFTER. Returns True while jobs are pending."""
    global _progress_on
    with _cond:
        obsolete = [j for j in _jobs_locked() if engine_bridge.obsolete(j.request)]
        for job in obsolete:  # a newer result was written another way, which set the status
            _cancel_locked(job)
        jobs, running = _jobs_locked(), _running
    for uid in {j.uid for j in obsolete} - {j.uid for j in jobs}:
        _status.pop(uid, None)
    for uid in {j.uid for j in jobs}:
        obj = _object(uid)
        if obj is not None:
            engine_bridge.set_status(obj, _stale_text(obj))
    wm = bpy.context.window_manager
    slow = running is not None and running.started is not None and not running.cancel.is_set() \
        and time.perf_counter() - running.started > PROGRESS_AFTER
    if slow and wm is not None:
        if not _progress_on:
            wm.progress_begin(0, 100)
            _progress_on = True
        wm.progress_update(int(running.fraction * 100))
    elif not jobs:
        _end_progress()
    if wm is not None:
        for window in wm.windows:
            for area in window.screen.areas if window.screen else ():
                if area.type in {"VIEW_3D", "PROPERTIES"}:
                    area.tag_redraw()
    return bool(jobs)


def _end_progress():
    global _progress_on
    wm = bpy.context.window_manager
    if _progress_on and wm is not None:
        wm.progress_end()
    _progress_on = False


def _percent(job):
    return int(job.fraction * 20) * 5  # in steps of 5 %: fewer status updates


def _showing(obj):
    if mesh_io.RADIANCE not in obj.data.attributes:
        return "no result yet"
    uid = obj.session_uid
    return f"showing frame {_shown[uid]}" if uid in _shown else "showing the previous result"


def _stale_text(obj):
    uid = obj.session_uid
    with _cond:
        running = _running if _running is not None and _running.uid == uid and not _running.cancel.is_set() else None
        waiting = _waiting.get(uid)
    parts = []
    if running is not None:
        parts.append(f"computing frame {running.frame}, {_percent(running)} %")
    if waiting is not None:
        parts.append(f"frame {waiting.frame} next" if running else f"frame {waiting.frame} waiting")
    shown = _showing(obj)
    return (shown if shown == "no result yet" else f"stale ({shown})") + ": " + ", ".join(parts)


def _start_timer():
    if not bpy.app.timers.is_registered(poll):
        bpy.app.timers.register(poll, first_interval=INTERVAL)


# -- for operators, panels and handlers ----------------------------------------------------------------

def pending(objects=None):
    """The jobs not yet written (running first), of `objects` or of all."""
    uids = None if objects is None else {o.session_uid for o in objects}
    with _cond:
        return _jobs_locked(uids)


def error(obj):
    """Why the object's last job wrote nothing (the engine's or the object's error), or None."""
    return _errors.get(obj.session_uid)


def cancel(objects=None):
    """The user stops the jobs of `objects` (all when None): their previous results stay,
    marked stale. Returns the number of objects whose computation stopped."""
    uids = None if objects is None else {o.session_uid for o in objects}
    with _cond:
        stopped = {j.uid: j for j in _jobs_locked(uids)}  # the object's latest job last
        _drop_locked(set(stopped))
    for uid, job in stopped.items():
        _cancelled[uid] = job
        obj = _object(uid)
        if obj is not None:
            engine_bridge.set_status(obj, f"cancelled: frame {job.frame} not computed; {_showing(obj)} (stale)")
    if not pending():
        _end_progress()
    return len(stopped)


def finish_all(recompute_cancelled=False):
    """Wait for every job and write its result (before a render: a rendered frame is never
    stale); with `recompute_cancelled`, the jobs the user cancelled run again first."""
    with _cond:
        if recompute_cancelled:
            for uid, old in _cancelled.items():
                if uid not in _waiting:
                    _waiting[uid] = Job(old.name, old.scene, old.frame, old.request)
            if _waiting:
                _start_worker_locked()
        _cancelled.clear()
        _cond.wait_for(lambda: _worker is None and _running is None)
    _write_finished()  # the window manager's progress ends at the next poll, on the main thread


def set_rendering(rendering):
    """Between render_init and render_complete / render_cancel everything is synchronous."""
    global _rendering
    _rendering = bool(rendering)


def rendering():
    return _rendering


def reset():
    """Forget every job and what was shown (a file was loaded, or the add-on goes): stop
    the worker, wait for it and drop its results."""
    with _cond:
        _drop_locked(None)
        _cond.wait_for(lambda: _worker is None)
        _finished.clear()
    _shown.clear()
    _status.clear()
    _cancelled.clear()
    _errors.clear()
    _end_progress()
    set_rendering(False)
    if bpy.app.timers.is_registered(poll):
        bpy.app.timers.unregister(poll)
