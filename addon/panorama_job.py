"""A panorama bake in steps, for the modal Bake Panorama operator (as lightmap_job.py): Blender
is read and Cycles renders the primary visibility on the main thread (`panorama_bake.prepare`),
the engine bakes in a worker thread (no bpy there), and the timer's `step()` reports progress
and, once the worker is done, writes the files on the main thread (worker_job.py: cancel and
failure write nothing).
"""

from . import panorama_bake
from .worker_job import CANCELLED, FAILED, FINISHED, RUNNING, WorkerJob  # noqa: F401  (the states, for callers)


class PanoramaBake(WorkerJob):
    thread_name = "hemishadow panorama"
    write_errors = (OSError, ValueError)

    def __init__(self, scene, path, **settings):
        """Checks the output and reads the scene (raises ValueError naming the problem)."""
        panorama_bake.check_writable(path)
        self.path, self.written = path, None
        self.prepared = panorama_bake.prepare(scene, **settings)
        super().__init__()

    def compute(self, progress):
        return panorama_bake.compute(self.prepared, progress)

    def write(self, result):
        self.written = panorama_bake.write(result, self.path)
