"""Scenes shared by the probe-lighting add-on tests."""

import bpy
import numpy as np


def yard(addon):
    """A floor, a 2 m wall at x = 2 and a low sun from +x, 30 degrees up (the wall's shadow
    reaches about 3.5 m west of it), under a dim uniform World; a probe volume "Volume" over
    the sunlit and the shaded part, baked direct only. Returns the scene."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.world.clear_cache()
    addon.engine_bridge.forget()
    scene = bpy.context.scene
    scene.world = bpy.data.worlds.new("World")
    if bpy.app.version < (5, 0):  # 5.x always uses nodes (use_nodes deprecated)
        scene.world.use_nodes = True
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.3
    bpy.ops.mesh.primitive_plane_add(size=12.0)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(2.0, 0.0, 1.0))
    bpy.context.active_object.scale = (0.2, 6.0, 2.0)
    bpy.ops.object.light_add(type="SUN", rotation=(0.0, np.radians(60.0), 0.0))
    bpy.context.active_object.name = "Sun"
    bpy.context.active_object.data.energy = 3.0
    bpy.ops.object.add(type="LIGHT_PROBE")
    volume = bpy.context.active_object
    if volume.data.type != "VOLUME":
        volume.data = bpy.data.lightprobes.new("Volume", "VOLUME")
    volume.name = "Volume"
    volume.location, volume.scale = (-1.0, 0.0, 1.0), (3.5, 2.0, 1.0)
    volume.data.resolution_x, volume.data.resolution_y, volume.data.resolution_z = 6, 2, 2
    bpy.context.view_layer.update()
    addon.probes.bake_probes(scene, volume, bounces=0)
    return scene
