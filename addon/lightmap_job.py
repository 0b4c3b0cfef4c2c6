"""A lightmap bake in steps, for the modal Bake Lightmaps operator: Blender data is read on
the main thread (`lightmaps.prepare`), the engine runs in a worker thread (no bpy there), and
the timer's `step()` reports progress and, once the worker is done, writes files and images
on the main thread. After `cancel()` the next `step()` returns CANCELLED at once, and the worker
stops at its next progress call (the engine reports every few hundredths of a second,
`hemishadow.lightmap.bake.Steps`); its result, if any, is dropped: a cancelled bake writes
nothing (no file, no image), even when the worker had finished.
"""

import warnings

from . import lightmaps
from .worker_job import CANCELLED, FAILED, FINISHED, RUNNING, WorkerJob  # noqa: F401  (the states, for callers)


class LightmapBake(WorkerJob):
    thread_name = "hemishadow lightmaps"

    def __init__(self, scene, objects, *, out_dir=None, images=True, **settings):
        """Reads the scene (raises ValueError naming the object); starts nothing yet."""
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            self.prepared = lightmaps.prepare(scene, objects, **settings)
        super().__init__()
        self.warnings = [str(w.message) for w in caught]
        self.out_dir, self.images, self.written = out_dir, images, {}

    @property
    def names(self):
        return lightmaps.baked_names(self.prepared.targets)

    def compute(self, progress):
        return lightmaps.compute(self.prepared, progress)

    def write(self, result):
        self.written = lightmaps.finish(self.prepared, result, self.out_dir, self.images)
