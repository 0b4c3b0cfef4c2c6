"""Draws docs/images/probes_preview.png: the probe preview (`hemishadow.probe_preview`) of a
Light Probe Volume baked over the scene of bench/probes_cycles.py (floor, box, wall, white
World, a sun; 2 bounces), rendered by Workbench with flat lighting and the spheres' colour
attribute, so the colours are the n-squared values (Standard view, exposure -1: values halved).
Run: PYTHONPATH=native/python .venv/bin/python docs/probes_figure.py"""

import math
import pathlib
import sys
import tempfile

import bpy

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
from addon import probes  # noqa: E402
import probes_cycles  # noqa: E402

OUT = ROOT / "docs" / "images" / "probes_preview.png"


def main():
    scene = probes_cycles.build(0.8, cuts=16)
    bpy.ops.object.add(type="LIGHT_PROBE")
    volume = bpy.context.active_object
    if volume.data.type != "VOLUME":
        volume.data = bpy.data.lightprobes.new("Volume", "VOLUME")
    volume.name = "Volume"
    volume.location, volume.scale = (0.0, 0.0, 1.0), (3.0, 2.0, 1.0)
    volume.data.resolution_x, volume.data.resolution_y, volume.data.resolution_z = 9, 6, 3
    bpy.context.view_layer.update()
    with tempfile.TemporaryDirectory() as folder:
        result, _ = probes.bake_probes(scene, volume, bounces=2, out=str(pathlib.Path(folder) / "v.npz"))
    preview = probes.preview(scene, volume, radius=0.12)
    preview.hide_render = False  # a viewport aid, rendered here for the figure only
    for obj in scene.objects:
        if obj.type == "MESH" and obj != preview:
            obj.hide_render = True  # the scene would hide probes: only the probes are drawn
    bpy.ops.object.camera_add(location=(7.5, -7.0, 6.0))
    cam = bpy.context.active_object
    direction = -cam.location
    cam.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    scene.camera = cam
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.shading.light = "FLAT"
    scene.display.shading.color_type = "VERTEX"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.exposure = -1.0  # sides reach 1.8 (sunlit floor below): halve them to show the range
    scene.render.resolution_x, scene.render.resolution_y = 900, 560
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(OUT)
    bpy.ops.render.render(write_still=True)
    print(f"{OUT}: {len(result['positions'])} probes, {int((~result['valid']).sum())} invalid, "
          f"{int(result['moved'].sum())} moved, sides {result['cube'].min():.3f} .. {result['cube'].max():.3f}")


if __name__ == "__main__":
    main()
