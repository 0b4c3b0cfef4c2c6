"""Operators, one module per job: live.py (compute, live toggle, clear, material),
bake.py (bake a frame range to a cache), world.py (precompute World lighting), jobs.py
(heavy meshes in the background) lightmaps.py (bake lightmaps), probes.py (bake probes, preview)
and panorama.py (bake, relight, save)."""

import bpy

from . import bake, jobs, lightmaps, live, panorama, probes, world

classes = (live.classes + bake.classes + world.classes + jobs.classes + lightmaps.classes + probes.classes
           + panorama.classes)

register, unregister = bpy.utils.register_classes_factory(classes)
