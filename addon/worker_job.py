"""A bake in steps, for a modal operator: Blender data is read on the main thread (the
subclass's constructor), the engine runs in a worker thread (`compute`, no bpy there), and
the timer's `step()` reports progress and, once the worker is done, writes on the main
thread (`write`). After `cancel()` the next `step()` returns CANCELLED at once and the worker
stops at its next progress call; its result, if any, is dropped: a cancelled or failed bake
writes nothing, even when the worker had finished.
"""

import threading
import warnings

RUNNING, FINISHED, CANCELLED, FAILED = "RUNNING", "FINISHED", "CANCELLED", "FAILED"


class WorkerJob:
    #: The worker thread's name; `write` errors of these types fail the job with a message.
    thread_name = "hemishadow bake"
    write_errors = (OSError,)

    def __init__(self):
        self.fraction, self.state, self.error = 0.0, RUNNING, None
        self.warnings = []
        self._cancel = threading.Event()
        self._result = None
        self._thread = threading.Thread(target=self._run, name=self.thread_name, daemon=True)

    def compute(self, progress):
        """The engine's part, on the worker thread: returns the result `write` takes."""
        raise NotImplementedError

    def write(self, result):
        """Writes the result on the main thread (files, images)."""
        raise NotImplementedError

    def start(self):
        self._thread.start()
        return self

    def cancel(self):
        self._cancel.set()

    def _progress(self, fraction):
        self.fraction = fraction
        return not self._cancel.is_set()

    def _run(self):
        import hemishadow

        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                self._result = self.compute(self._progress)
            self.warnings += [str(w.message) for w in caught]
        except hemishadow.Cancelled:
            pass
        except Exception as error:  # reported by step() on the main thread
            self.error = error

    def step(self, timeout=0.0):
        """RUNNING while the worker runs; then, once, writes (main thread) and returns
        FINISHED, CANCELLED (nothing written) or FAILED (`error`; nothing written)."""
        if self.state != RUNNING:
            return self.state
        if self._cancel.is_set():  # at once: the worker ends at its next report, writing nothing
            self.state, self._result = CANCELLED, None
            return self.state
        self._thread.join(timeout)
        if self._thread.is_alive():
            return RUNNING
        if self._cancel.is_set():
            self.state = CANCELLED
        elif self.error is not None or self._result is None:
            self.state = FAILED
        else:
            try:
                self.write(self._result)
                self.fraction, self.state = 1.0, FINISHED
            except self.write_errors as error:
                self.error, self.state = error, FAILED
        self._result = None
        return self.state
