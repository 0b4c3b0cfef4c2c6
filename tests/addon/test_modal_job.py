"""The modal loop every bake operator shares (addon/operators/modal_job.py, over
addon/worker_job.py), driven with a stand-in window manager since modal operators cannot run
headless: timer steps report progress and end with the operator's `finished`; Esc ends it at
once with CANCELLED and nothing written, even while the worker still runs; a failing worker
reports its error and writes nothing."""

import pathlib
import sys
import threading

import pytest

pytest.importorskip("bpy")
ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from addon import worker_job  # noqa: E402
from addon.operators.modal_job import ModalJob  # noqa: E402


class Event:
    def __init__(self, type, value="NOTHING"):
        self.type, self.value = type, value


class WindowManager:
    def __init__(self):
        self.progress, self.timers, self.handlers = [], 0, 0

    def progress_begin(self, lo, hi):
        self.progress.append("begin")

    def progress_update(self, value):
        self.progress.append(value)

    def progress_end(self):
        self.progress.append("end")

    def event_timer_add(self, step, window=None):
        self.timers += 1
        return object()

    def event_timer_remove(self, timer):
        self.timers -= 1

    def modal_handler_add(self, operator):
        self.handlers += 1


class Context:
    def __init__(self):
        self.window_manager, self.window, self.workspace, self.area = WindowManager(), None, None, None


class Job(worker_job.WorkerJob):
    """Reports 0.5, then waits for `release` (or fails), then returns 42."""

    def __init__(self, fail=False):
        super().__init__()
        self.release, self.fail, self.written = threading.Event(), fail, None

    def compute(self, progress):
        progress(0.5)
        self.release.wait(5)
        if self.fail:
            raise RuntimeError("the engine said no")
        if progress(1.0) is False:
            raise __import__("hemishadow").Cancelled()
        return 42

    def write(self, result):
        self.written = result


class Operator(ModalJob):
    noun = "test"

    def __init__(self):
        self.reports, self.done = [], None

    def report(self, kind, message):
        self.reports.append((next(iter(kind)), message))

    def finished(self, context, written):
        self.done = written
        return {"FINISHED"}


def run(op, context, job, events):
    assert op.start_modal(context, job) == {"RUNNING_MODAL"}
    for event in events:
        result = op.modal(context, event)
        if result != {"RUNNING_MODAL"}:
            return result
    return result


def test_timer_steps_end_with_the_operators_finished():
    op, context, job = Operator(), Context(), Job()
    assert op.start_modal(context, job) == {"RUNNING_MODAL"}
    while job.fraction < 0.5:
        job._thread.join(0.01)
    assert op.modal(context, Event("TIMER")) == {"RUNNING_MODAL"}
    assert op.modal(context, Event("MOUSEMOVE")) == {"PASS_THROUGH"}  # the UI stays usable
    job.release.set()
    job._thread.join()
    assert op.modal(context, Event("TIMER")) == {"FINISHED"}
    assert op.done == 42 and job.written == 42
    wm = context.window_manager
    assert wm.progress[0] == "begin" and 500 in wm.progress and wm.progress[-1] == "end" and wm.timers == 0


def test_escape_cancels_at_once_and_writes_nothing():
    op, context, job = Operator(), Context(), Job()
    op.start_modal(context, job)
    assert op.modal(context, Event("ESC", "PRESS")) == {"CANCELLED"}  # the worker is still waiting
    assert job._thread.is_alive()
    job.release.set()
    job._thread.join()
    assert job.step() == worker_job.CANCELLED and job.written is None and op.done is None
    assert ("WARNING", "hemishadow: test bake cancelled; nothing was written") in op.reports
    assert context.window_manager.timers == 0


def test_a_failing_worker_reports_its_error_and_writes_nothing():
    op, context, job = Operator(), Context(), Job(fail=True)
    op.start_modal(context, job)
    job.release.set()
    job._thread.join()
    assert op.modal(context, Event("TIMER")) == {"CANCELLED"}
    assert job.written is None and op.done is None
    assert any(kind == "ERROR" and "the engine said no" in message for kind, message in op.reports)


class Area:
    def __init__(self):
        self.header = "something"

    def header_text_set(self, text):
        self.header = text


class BakeStep:
    """Stands in for bake.BakeJob: one step still running, then done with two frames."""

    def __init__(self):
        self.cancel, self.steps = threading.Event(), 0
        self.result = type("Result", (), {"cancelled": False, "frames_done": 2, "saved": {"Cube": "//c.npz"}})()

    def step(self, budget_seconds):
        self.steps += 1
        return self.steps > 1


def test_the_animation_bake_takes_its_ui_down_through_the_shared_teardown():
    from addon.operators.bake import HEMISHADOW_OT_bake_animation as Bake
    from addon.operators.modal_job import ModalUi

    class StandIn(ModalUi):  # the operator's methods, called on a stand-in: bpy makes operators itself
        def report(self, kind, message):
            self.reported = (next(iter(kind)), message)

    op, context = StandIn(), Context()
    op._job, op._area, op._timer = BakeStep(), Area(), context.window_manager.event_timer_add(0.01)
    assert Bake.modal(op, context, Event("TIMER")) == {"RUNNING_MODAL"}
    assert op._area.header == "something" and context.window_manager.timers == 1
    area = op._area
    assert Bake.modal(op, context, Event("TIMER")) == {"FINISHED"}
    assert area.header is None and op._area is None and op._timer is None
    assert context.window_manager.timers == 0 and context.window_manager.progress[-1] == "end"
    assert op.reported == ("INFO", "hemishadow: baked 2 frames: //c.npz")
