"""Stale bake caches: what playback shows after the animation changed, against live computing.

    .venv/bin/python bench/stale_cache.py [ADDON_ROOT]      (default: this repository)

Bakes the walking figure (../shared/data/rigged_figure.glb, frames 1-5) or a 289-vertex cloth
falling on a cube (frames 1-15), edits the animation (a key of the torso's rotation, the
Armature modifier disabled, a Limit Rotation constraint, the cloth's air damping), steps to the
frame with Live on and prints the largest difference between what the attributes show and
what live computing gives. A cache that serves stale values shows a difference; one that is
detected as stale computes live and shows none.
"""

import pathlib
import sys
import tempfile

import numpy as np

import bpy

ROOT = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else pathlib.Path(__file__).resolve().parents[1])
FIGURE = ROOT.resolve().parent / "shared" / "data" / "rigged_figure.glb"
if not FIGURE.is_file():
    FIGURE = pathlib.Path(__file__).resolve().parents[2] / "shared" / "data" / "rigged_figure.glb"
sys.path.insert(0, str(ROOT))
import addon  # noqa: E402

addon.register()
from addon import engine_bridge  # noqa: E402
from addon.operators.bake import bake_range  # noqa: E402


def outputs(obj):
    mesh = obj.data
    rgba = np.empty(len(mesh.vertices) * 4, np.float32)
    mesh.color_attributes["hemishadow_radiance"].data.foreach_get("color", rgba)
    ao = np.empty(len(mesh.vertices), np.float32)
    mesh.attributes["hemishadow_ao"].data.foreach_get("value", ao)
    return rgba.reshape(-1, 4)[:, :3].copy(), ao


def figure():
    bpy.ops.import_scene.gltf(filepath=str(FIGURE))
    return bpy.context.scene.objects["Proxy"], 5


def cloth():
    bpy.ops.mesh.primitive_cube_add(size=1)
    bpy.context.object.modifiers.new("Collision", "COLLISION")
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=16, y_subdivisions=16, size=2, location=(0, 0, 1))
    bpy.context.object.modifiers.new("Cloth", "CLOTH")
    return bpy.context.object, 15


def shown_against_live(make, edit):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    obj, last = make()
    scene = bpy.context.scene
    obj.hemishadow.enabled = True
    scene.hemishadow.lighting_source = "BUILTIN"
    scene.frame_set(1)
    bpy.ops.wm.save_as_mainfile(filepath=tempfile.mkdtemp() + "/scene.blend")
    bake_range(scene, [obj], 1, last)
    scene.hemishadow.live = True
    edit(obj)
    for frame in range(1, last + 1):   # in order, as playback does (a simulation needs it)
        scene.frame_set(frame)
    shown = outputs(obj)
    engine_bridge.forget()
    engine_bridge.update_scene(scene, bpy.context.evaluated_depsgraph_get(), [obj], force=True)
    live = outputs(obj)
    return last, np.abs(shown[0] - live[0]).max(), np.abs(shown[1] - live[1]).max()


def torso_key(obj):
    action = obj.find_armature().animation_data.action
    curve = [c for layer in action.layers for strip in layer.strips for bag in strip.channelbags for c in bag.fcurves
             if c.data_path == 'pose.bones["torso_joint_1"].rotation_quaternion' and c.array_index == 1][0]
    for key in curve.keyframe_points:
        for point in (key.co, key.handle_left, key.handle_right):
            point.y += 0.3
    curve.update()


def armature_off(obj):
    obj.modifiers["Armature"].show_viewport = False


def limit_rotation(obj):
    limit = obj.find_armature().pose.bones["torso_joint_1"].constraints.new("LIMIT_ROTATION")
    limit.use_limit_x = limit.use_limit_y = limit.use_limit_z = True


def cloth_air_damping(obj):
    obj.modifiers["Cloth"].settings.air_damping = 20.0


for make, edit in ((figure, torso_key), (figure, armature_off), (figure, limit_rotation), (cloth, cloth_air_damping)):
    frame, radiance, ao = shown_against_live(make, edit)
    print(f"{make.__name__:6s} {edit.__name__:14s} frame {frame:2d}: shown - live: max |radiance| {radiance:.4f}, "
          f"max |AO| {ao:.4f}")
