"""Operators, one module per job: live.py (compute, live toggle, clear, material) and
bake.py (bake a frame range to a cache)."""

import bpy

from . import bake, live

classes = live.classes + bake.classes

register, unregister = bpy.utils.register_classes_factory(classes)
