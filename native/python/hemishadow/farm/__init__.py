"""Bakes on a Dask cluster (issue 14): `python -m hemishadow farm bake|lightmaps|probes FILE.blend
--scheduler ADDRESS | --local N [the subcommand's own options]`. See docs/farm.md.

units.py cuts a job into deterministic work units, worker.py runs one on a worker, client.py
submits them and follows them, merge.py assembles exactly what a single-machine bake writes.
Nothing here imports dask until a job is submitted (the extension's wheel ships this package
too, and Blender's Python has no dask).
"""
