"""Operators, one module per job: live.py (compute, live toggle, clear, material),
bake.py (bake a frame range to a cache), world.py (precompute World lighting) and jobs.py
(heavy meshes in the background)."""

import bpy

from . import bake, jobs, live, world

classes = live.classes + bake.classes + world.classes + jobs.classes

register, unregister = bpy.utils.register_classes_factory(classes)
