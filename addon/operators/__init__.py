"""Operators, one module per job: live.py (compute, live toggle, clear, material) and
bake.py (bake a frame range to a cache)."""

import bpy

from . import bake, live

classes = live.classes + bake.classes


def register():
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
