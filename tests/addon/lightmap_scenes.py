"""Scenes shared by the lightmap add-on tests: an empty file under a uniform World, and
planes with a `lightmap` UV map."""

import bpy


def white_world(world, color=(1, 1, 1, 1), strength=1.0):
    """A factory-empty file whose World is a uniform `color` (None: Blender's default grey)
    (`world`: the add-on's world module, whose projection cache is cleared)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    world.clear_cache()
    scene = bpy.context.scene
    scene.world = bpy.data.worlds.new("World")
    if scene.world.node_tree is None:  # Blender before 5.0
        scene.world.use_nodes = True
    background = scene.world.node_tree.nodes["Background"]
    if color is not None:
        background.inputs["Color"].default_value = color
    background.inputs["Strength"].default_value = strength
    return scene


def plane(name="Floor", size=4.0, uv="lightmap", location=(0, 0, 0)):
    """A plane with `uv` (a copy of the active UV map: the unit square), or none."""
    bpy.ops.mesh.primitive_plane_add(size=size, location=location)
    obj = bpy.context.active_object
    obj.name = name
    if uv:
        obj.data.uv_layers.new(name=uv)
    return obj
