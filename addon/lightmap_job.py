"""A lightmap bake in steps, for the modal Bake Lightmaps operator: Blender data is read on
the main thread (`lightmaps.prepare`), the engine runs in a worker thread (no bpy there), and
the timer's `step()` reports progress and, once the worker is done, writes files and images
on the main thread. After `cancel()` the next `step()` returns CANCELLED at once, and the worker
stops at its next progress call (the engine reports every few hundredths of a second,
`hemishadow.lightmap.bake.Steps`); its result, if any, is dropped: a cancelled bake writes
nothing (no file, no image), even when the worker had finished.
"""

import threading
import warnings

from . import lightmaps

RUNNING, FINISHED, CANCELLED, FAILED = "RUNNING", "FINISHED", "CANCELLED", "FAILED"


class LightmapBake:
    def __init__(self, scene, objects, *, out_dir=None, images=True, **settings):
        """Reads the scene (raises ValueError naming the object); starts nothing yet."""
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            self.prepared = lightmaps.prepare(scene, objects, **settings)
        self.warnings = [str(w.message) for w in caught]
        self.out_dir, self.images = out_dir, images
        self.fraction, self.state, self.error, self.written = 0.0, RUNNING, None, {}
        self._cancel = threading.Event()
        self._result = None
        self._thread = threading.Thread(target=self._run, name="hemishadow lightmaps", daemon=True)

    @property
    def names(self):
        return lightmaps.baked_names(self.prepared.targets)

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
                self._result = lightmaps.compute(self.prepared, self._progress)
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
                self.written = lightmaps.finish(self.prepared, self._result, self.out_dir, self.images)
                self.fraction, self.state = 1.0, FINISHED
            except OSError as error:
                self.error, self.state = error, FAILED
        self._result = None
        return self.state
