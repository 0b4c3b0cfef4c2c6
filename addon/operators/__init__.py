"""Operators, one module per job: live.py (compute, live toggle, clear, material),
bake.py (bake a frame range to a cache) and world.py (precompute World lighting)."""

import bpy

from . import bake, live, world

classes = live.classes + bake.classes + world.classes

register, unregister = bpy.utils.register_classes_factory(classes)
