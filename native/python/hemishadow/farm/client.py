"""The farm's client: connect (or start a local cluster), plan on a worker, submit the units,
show progress, merge. Ctrl-C cancels: queued units are removed, running ones are abandoned
(their results are dropped), nothing is written.

Errors a user can act on are `FarmError`s with one clear line: the scheduler cannot be
reached, a worker has no add-on, the workers cannot open the .blend, a unit failed (named).
A worker lost mid-job is not an error: the scheduler runs its units again elsewhere, and units
are deterministic, so the outputs are the same.
"""

from __future__ import annotations

import importlib
import os
import sys
import time

from . import merge, units
from .worker import FarmError

LOOPBACK = "tcp://127.0.0.1:8786"


def default_addon_dir():
    """The checkout this package belongs to, when it has the add-on (native/python/hemishadow/farm)."""
    root = os.path.abspath(os.path.join(os.path.dirname(__file__), *[os.pardir] * 4))
    return root if os.path.isfile(os.path.join(root, "addon", "__init__.py")) else None


def connect(scheduler=None, local=None, timeout=10):
    """(dask Client, LocalCluster or None). `local`: N worker processes on loopback, one
    thread each (bpy is one scene per process)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise FarmError("the farm needs Dask's `distributed` package in this Python: pip install distributed") from None
    if local:
        cluster = LocalCluster(n_workers=int(local), threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None)
        return Client(cluster), cluster
    address = scheduler or LOOPBACK
    try:
        return Client(address, timeout=timeout), None
    except (OSError, TimeoutError) as error:
        raise FarmError(f"cannot reach the Dask scheduler at {address}: {error}".rstrip(": ")) from None


class Job:
    """One farm job. `task`: worker.run (bpy in the worker) or worker.run_subprocess."""

    def __init__(self, kind, blend, args, *, addon=None, worker_mode="bpy", blender="blender", send_blend=False,
                 frames_per_unit=None, probes_per_unit=None, cameras=None, out=sys.stderr):
        from . import worker

        self.kind, self.args, self.addon = kind, list(args), addon
        self.blend = os.path.abspath(blend)
        self.send_blend, self.cameras = send_blend, cameras
        self.sizes = dict(frames_per_unit=frames_per_unit, probes_per_unit=probes_per_unit)
        if worker_mode == "bpy":
            self.task, self.task_kwargs = worker.run, {}
        elif worker_mode == "subprocess":
            self.task, self.task_kwargs = worker.run_subprocess, dict(blender=blender)
        else:
            raise FarmError(f"--worker-mode must be bpy or subprocess, got {worker_mode!r}")
        self.out = out
        self.results, self.futures = [], []

    def say(self, text):
        print(f"hemishadow farm: {text}", file=self.out, flush=True)

    def run(self, client):
        """Plan, run the units, merge, write. Returns {name: path written}."""
        blend_data = None
        if self.send_blend:
            with open(self.blend, "rb") as handle:
                blend_data = client.scatter(handle.read(), broadcast=True)
        unit_base = units.base(self.kind, self.blend, self.args, self.addon)
        plan = self._submit([units.plan_unit(self.kind, self.blend, self.args, self.addon, self.cameras)],
                            blend_data, "plan")
        plan = plan[0]["plan"]
        merge.check_writable(self._outputs(plan))
        workers = max(1, len(client.scheduler_info().get("workers", {})))
        work = units.make(plan, unit_base, workers, **self.sizes)
        if plan.get("simulated"):
            self.say(f"simulated objects ({', '.join(plan['simulated'])}): frames are baked in order, one unit per object")
        self.say(f"{len(work)} units on {workers} workers")
        t0 = time.perf_counter()
        self.results = self._submit(work, blend_data, "units", progress=True)
        self.say(f"units done in {time.perf_counter() - t0:.2f} s; {self.overhead_line()}")
        return self._merge(plan)

    def _submit(self, work, blend_data, what, progress=False):
        from distributed import as_completed

        self.futures = [self._future(unit, blend_data) for unit in work]
        order = {f.key: i for i, f in enumerate(self.futures)}
        results = [None] * len(work)
        done = 0
        for future in as_completed(self.futures):
            if future.status == "error":
                error = future.exception()
                self.cancel()
                raise FarmError(str(error) if isinstance(error, FarmError) else
                                f"{units.describe(work[order[future.key]])}: {type(error).__name__}: {error}")
            result = future.result()
            results[order[future.key]] = result
            done += 1
            if progress:
                s = result["seconds"]
                self.say(f"[{done}/{len(work)}] {units.describe(work[order[future.key]])}: open {s['open']:.2f} s, "
                         f"setup {s['setup']:.2f} s, work {s['work']:.2f} s ({result['worker']})")
        self.futures = []
        return results

    def _future(self, unit, blend_data):
        client = _client()
        return client.submit(self.task, unit, blend_data, key=units.key(unit), pure=False, **self.task_kwargs)

    def cancel(self):
        """Queued units are removed; running ones finish on their worker, their results unused."""
        if self.futures:
            _client().cancel(self.futures, force=True)
            self.futures = []

    def overhead_line(self):
        ratios = [(r["seconds"]["open"] + r["seconds"]["setup"]) / max(r["seconds"]["work"], 1e-9) for r in self.results]
        total = sum(r["seconds"]["work"] for r in self.results)
        return (f"per-unit overhead (open + setup) / work: mean {100 * sum(ratios) / len(ratios):.1f} %, "
                f"max {100 * max(ratios):.1f} %; work {total:.2f} s in all")

    # -- outputs ----------------------------------------------------------------------------

    def _outputs(self, plan):
        if self.kind == "bake":
            return [merge.resolve(p, self.blend) for p in plan["outputs"].values()]
        if self.kind == "lightmaps":
            folder = merge.resolve(plan["folder"], self.blend)
            return [os.path.join(folder, f"{merge._safe(n)}.exr") for n in plan["outputs"]]
        if self.kind == "panorama":
            return [merge.resolve(path, self.blend) for _, path in plan["outputs"]]
        return [merge.resolve(plan["output"], self.blend)]

    def _merge(self, plan):
        if self.kind == "bake":
            cache = _addon_module(self.addon, "cache")
            caches = merge.bake_caches(plan, self.results, cache)
            if plan["pack"] or plan["save"]:
                return _store_in_blend(self.blend, plan, caches, self.addon)
            written = merge.write_caches(plan, caches, self.blend)
            a, b = plan["frames"]
            for name, path in written.items():
                print(f"hemishadow: {name}: frames {a}..{b} -> {path}")
            return written
        if self.kind == "lightmaps":
            for r in self.results:
                for warning in r["warnings"]:
                    print(f"hemishadow: warning: {warning}", file=sys.stderr)
            written = merge.write_lightmaps(plan, self.results, self.blend)
            for name, path in written.items():
                print(f"hemishadow: {name} -> {path}")
            return written
        if self.kind == "panorama":
            written = merge.write_panoramas(plan, self.results, self.blend)
            for name, path in written.items():
                print(f"hemishadow: panorama {name or ''} -> {path}".replace("  ", " "))
            return written
        result = merge.probe_result(plan, self.results)
        path = merge.write_probes(plan, result, self.blend)
        p, bad, moved = len(result["positions"]), int((~result["valid"]).sum()), int(result["moved"].sum())
        print(f"hemishadow: {p} probes ({bad} invalid, left out; {moved} moved out of geometry) -> {path}")
        for note in result["notes"]:
            print(f"hemishadow: note: {note}")
        return {"probes": path}


_current = None


def _client():
    return _current


def _addon_module(addon_dir, name):
    """An add-on module in this process (bpy imported): the caches' own writer."""
    if not addon_dir:
        raise FarmError("the merge of caches needs the add-on's source here: give --addon DIR")
    if addon_dir not in sys.path:
        sys.path.insert(0, addon_dir)
    import bpy  # noqa: F401  (the add-on's modules need it)

    return importlib.import_module(f"addon.{name}")


def _store_in_blend(blend, plan, caches, addon_dir):
    """--pack or --save: the caches stored through the add-on (packed or files), the .blend saved."""
    import bpy

    cache = _addon_module(addon_dir, "cache")
    if not hasattr(bpy.types.Object, "hemishadow"):
        importlib.import_module("addon").register()
    bpy.ops.wm.open_mainfile(filepath=blend, load_ui=False)

    location = "PACKED" if plan["pack"] else "FILE"
    written = {}
    for name, baked in caches.items():
        obj = bpy.data.objects[name]
        obj.hemishadow.enabled = True   # as the single-machine bake's object list does
        written[name] = cache.save(obj, baked, location=location, directory=plan["cache_dir"])
        print(f"hemishadow: {name}: frames {plan['frames'][0]}..{plan['frames'][1]} -> {written[name]}")
    bpy.ops.wm.save_mainfile()
    print(f"hemishadow: saved {blend}")
    return written


def run_job(job, scheduler=None, local=None, timeout=10):
    """Connect, run, close. Ctrl-C: cancel, write nothing, exit code 130."""
    global _current
    client, cluster = connect(scheduler, local, timeout)
    _current = client
    try:
        return job.run(client)
    except KeyboardInterrupt:
        job.cancel()
        raise
    finally:
        _current = None
        client.close()
        if cluster is not None:
            cluster.close()
