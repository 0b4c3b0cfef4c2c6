"""A panorama bake in steps, for the modal Bake Panorama operator (as lightmap_job.py): Blender
is read and Cycles renders the primary visibility on the main thread (`panorama_bake.prepare`),
the engine bakes in a worker thread (no bpy there), and the timer's `step()` reports progress
and, once the worker is done, writes the files on the main thread. `cancel()` stops the worker
at its next progress call; a cancelled or failed bake writes nothing.
"""

import threading

from . import panorama_bake

RUNNING, FINISHED, CANCELLED, FAILED = "RUNNING", "FINISHED", "CANCELLED", "FAILED"


class PanoramaBake:
    def __init__(self, scene, path, **settings):
        """Checks the output and reads the scene (raises ValueError naming the problem)."""
        panorama_bake.check_writable(path)
        self.path = path
        self.prepared = panorama_bake.prepare(scene, **settings)
        self.fraction, self.state, self.error, self.written = 0.0, RUNNING, None, None
        self._cancel = threading.Event()
        self._result = None
        self._thread = threading.Thread(target=self._run, name="hemishadow panorama", daemon=True)

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
            self._result = panorama_bake.compute(self.prepared, self._progress)
        except hemishadow.Cancelled:
            pass
        except Exception as error:  # reported by step() on the main thread
            self.error = error

    def step(self, timeout=0.0):
        """RUNNING while the worker runs; then, once, writes (main thread) and returns
        FINISHED, CANCELLED (nothing written) or FAILED (`error`; nothing written)."""
        if self.state != RUNNING:
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
                self.written = panorama_bake.write(self._result, self.path)
                self.fraction, self.state = 1.0, FINISHED
            except (OSError, ValueError) as error:
                self.error, self.state = error, FAILED
        self._result = None
        return self.state
