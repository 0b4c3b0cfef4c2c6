"""Evaluated positions of the shared animated characters, frame by frame, through Blender.

Used by the solver's trust tests and by bench/solver_trust.py (no pytest here). Each glTF
action is played over its whole frame range; positions are those Blender's depsgraph gives
(armature skinning), in world space, on the original vertices, with the mesh's triangles.
"""

import pathlib

import numpy as np

DATA = pathlib.Path(__file__).resolve().parents[2] / "shared" / "data"
CHARACTERS = ("cesium_man.glb", "fox.glb", "rigged_figure.glb")


def _world_positions(obj, depsgraph):
    evaluated = obj.evaluated_get(depsgraph)
    count = len(obj.data.vertices)
    co = np.empty(len(evaluated.data.vertices) * 3, np.float32)
    evaluated.data.vertices.foreach_get("co", co)
    m = np.array(evaluated.matrix_world, np.float64)
    return (co.reshape(-1, 3)[:count] @ m[:3, :3].T + m[:3, 3]).astype(np.float32)


def _triangles(mesh):
    mesh.calc_loop_triangles()
    tris = np.empty(len(mesh.loop_triangles) * 3, np.uint32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    return tris.reshape(-1, 3)


def character_frames(name, step=1):
    """(triangles (M, 3), [(action name, frame, positions (V, 3))...]) of the character's
    skinned mesh over every `step`-th frame of every action."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=str(DATA / name))
    scene = bpy.context.scene
    (obj,) = [o for o in scene.objects if o.type == "MESH" and o.find_armature()]
    armature = obj.find_armature()
    armature.animation_data_create()
    for track in list(armature.animation_data.nla_tracks):  # play one action at a time
        track.mute = True
    frames = []
    for action in sorted(bpy.data.actions, key=lambda a: a.name):
        armature.animation_data.action = action
        if hasattr(armature.animation_data, "action_slot") and action.slots:
            armature.animation_data.action_slot = action.slots[0]
        start, end = (int(round(f)) for f in action.frame_range)
        for frame in range(start, end + 1, step):
            scene.frame_set(frame)
            frames.append((action.name, frame, _world_positions(obj, bpy.context.evaluated_depsgraph_get())))
    return _triangles(obj.data), frames
