"""A small scene for the farm tests and bench/farm.py, saved as a .blend: a waving Sheet and a
moving Ball (hemishadow enabled: the animation cache bake), a Floor and a Box with lightmap
UVs (the lightmaps), an Empty `Probes` over them (the probe grid), cameras `Cam` and `Cam2`
(panoramas), a sun and a plain World.

    python tests/farm_scene.py OUT.blend [--grid N] [--frames F]
"""

import argparse
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]


def build(path, grid=24, frames=12):
    import bpy

    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    import addon

    if not hasattr(bpy.types.Object, "hemishadow"):
        addon.register()
    from addon import lightmaps

    bpy.ops.wm.read_factory_settings(use_empty=True)
    if not hasattr(bpy.types.Object, "hemishadow"):
        addon.register()
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, frames
    scene.hemishadow.lighting_source = "UNIFORM"
    world = bpy.data.worlds.new("World")
    if bpy.app.version < (5, 0):  # 5.x always uses nodes (use_nodes deprecated)
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.6, 0.7, 0.9, 1.0)
    scene.world = world

    bpy.ops.mesh.primitive_grid_add(x_subdivisions=12, y_subdivisions=12, size=6, location=(0, 0, 0))
    floor = bpy.context.object
    floor.name = "Floor"
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(1.5, 0.5, 0.5))
    box = bpy.context.object
    box.name = "Box"
    for obj in (floor, box):
        lightmaps.make_lightmap_uv(obj)

    bpy.ops.mesh.primitive_grid_add(x_subdivisions=grid, y_subdivisions=grid, size=2, location=(-1, 0, 0.6))
    sheet = bpy.context.object
    sheet.name = "Sheet"
    wave = sheet.modifiers.new("Wave", "WAVE")
    wave.height, wave.width, wave.speed = 0.3, 0.6, 0.08
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=0.5, location=(0.5, -1, 0.5))
    ball = bpy.context.object
    ball.name = "Ball"
    ball.keyframe_insert("location", frame=1)
    ball.location = (0.5, 1.0, 0.8)
    ball.keyframe_insert("location", frame=frames)
    for obj in (sheet, ball):
        obj.hemishadow.enabled = True
        obj.select_set(False)
    floor.select_set(True)
    box.select_set(True)

    bpy.ops.object.light_add(type="SUN", rotation=(0.6, 0.2, 0.4))
    bpy.context.object.data.energy = 3.0
    bpy.ops.object.empty_add(type="CUBE", location=(0, 0, 1.2))
    probes = bpy.context.object
    probes.name = "Probes"
    probes.empty_display_size = 2.5
    for name, location in (("Cam", (0.5, -5.0, 1.6)), ("Cam2", (-3.0, 3.0, 2.0))):   # panoramas
        bpy.ops.object.camera_add(location=location)
        bpy.context.object.name = name
    scene.camera = scene.objects["Cam"]
    scene.frame_set(1)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("out")
    p.add_argument("--grid", type=int, default=24)
    p.add_argument("--frames", type=int, default=12)
    a = p.parse_args()
    build(pathlib.Path(a.out).resolve(), a.grid, a.frames)
