"""Benchmark meshes, made and animated with the `bpy` module, returned as numpy frames.

Every mesh is welded once by the exact positions of its first frame (seams, triangle soups),
and the same map is applied to every frame, so hemishadow, Embree, Cycles and the reference
all see one identical welded mesh per frame: (frames (F, V, 3) float32 world space,
triangles (M, 3) uint32). Frame 0 is always the rest pose (flat cloth, undeformed Suzanne,
bind pose), the pose a live solver is built from; the animated frames follow.
"""

import math
import pathlib

import numpy as np

DATA = pathlib.Path(__file__).resolve().parents[2] / "shared" / "data"


def _reset():
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


def _triangles(mesh):
    mesh.calc_loop_triangles()
    out = np.empty(len(mesh.loop_triangles) * 3, np.int64)
    mesh.loop_triangles.foreach_get("vertices", out)
    return out.reshape(-1, 3)


def _positions(mesh, matrix):
    out = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", out)
    m = np.asarray(matrix, np.float64)
    return (out.reshape(-1, 3).astype(np.float64) @ m[:3, :3].T + m[:3, 3]).astype(np.float32)


def _evaluated(objects):
    """World-space evaluated positions of several mesh objects, concatenated."""
    import bpy

    depsgraph = bpy.context.evaluated_depsgraph_get()
    parts = []
    for obj in objects:
        ev = obj.evaluated_get(depsgraph)
        mesh = ev.to_mesh()
        parts.append(_positions(mesh, ev.matrix_world))
        ev.to_mesh_clear()
    return np.concatenate(parts)


def weld_frames(frames, triangles, key=None):
    """Weld by exact positions in `key` (default: the first frame; for skinned meshes the
    rest pose, since skinning moves copies of a vertex apart by rounding); keep used vertices
    only; drop collapsed triangles. Returns (frames (F, V', 3) float32, triangles uint32)."""
    first = frames[0] if key is None else key
    used = np.unique(triangles)
    _, first_index, inverse = np.unique(first[used], axis=0, return_index=True, return_inverse=True)
    remap = np.full(len(first), -1, np.int64)
    remap[used] = inverse.ravel()
    representative = used[first_index]
    tris = remap[triangles]
    keep = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 2] != tris[:, 0])
    welded = np.ascontiguousarray(np.stack([f[representative] for f in frames]), dtype=np.float32)
    return welded, np.ascontiguousarray(tris[keep], dtype=np.uint32)


def cloth(n_side=36, frames=(1, 24, 28, 32, 36, 40, 44, 48), quick=False):
    """A (n_side + 1)^2-vertex grid of 2 x 2 m dropped by Blender's cloth solver onto a sphere."""
    import bpy

    scene = _reset()
    last = max(frames)
    scene.frame_start, scene.frame_end = 1, last
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.55, location=(0.0, 0.0, 0.0), segments=32, ring_count=16)
    sphere = bpy.context.object
    sphere.modifiers.new("Collision", "COLLISION")
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=n_side, y_subdivisions=n_side, size=2.0, location=(0.05, 0.1, 0.9))
    sheet = bpy.context.object
    sheet.rotation_euler = (0.08, 0.05, 0.3)
    modifier = sheet.modifiers.new("Cloth", "CLOTH")
    settings = modifier.settings
    settings.quality = 4 if quick else 5
    settings.mass = 0.3
    settings.bending_stiffness = 0.05
    modifier.collision_settings.distance_min = 0.01
    modifier.point_cache.frame_start, modifier.point_cache.frame_end = 1, last
    tris = _triangles(sheet.data)
    out = []
    for f in range(1, last + 1):  # stepping frames in order runs (and caches) the simulation
        scene.frame_set(f)
        if f in frames:
            out.append(_evaluated([sheet]))
    return weld_frames(np.stack(out), tris)


def suzanne(level, n_frames=7):
    """Suzanne, Subdivision Surface `level` applied, bent and twisted per frame in numpy."""
    import bpy

    _reset()
    bpy.ops.mesh.primitive_monkey_add(size=2.0)
    obj = bpy.context.object
    if level > 0:  # a level-0 modifier is disabled and cannot be applied
        modifier = obj.modifiers.new("Subdivision", "SUBSURF")
        modifier.levels = level
        bpy.ops.object.modifier_apply(modifier=modifier.name)
    tris = _triangles(obj.data)
    rest = _positions(obj.data, obj.matrix_world).astype(np.float64)
    frames = [rest.astype(np.float32)]
    for k in range(n_frames):
        a = 0.35 * math.sin(2.0 * math.pi * k / n_frames)  # bend about X, by height
        b = 0.5 * math.sin(2.0 * math.pi * k / n_frames + 1.0)  # twist about Z, by height
        x, y, z = rest.T
        twist = b * z
        x, y = x * np.cos(twist) - y * np.sin(twist), x * np.sin(twist) + y * np.cos(twist)
        bend = a * z
        y, z = y * np.cos(bend) - z * np.sin(bend), y * np.sin(bend) + z * np.cos(bend)
        frames.append(np.stack([x, y, z], axis=1).astype(np.float32))
    return weld_frames(np.stack(frames), tris)


def character(name, n_frames=7):
    """An animated glTF character: evaluated (skinned) meshes at n_frames frames spread over
    its first action."""
    import bpy

    scene = _reset()
    bpy.ops.import_scene.gltf(filepath=str(DATA / name))
    shapes = {b.custom_shape for o in scene.objects if o.type == "ARMATURE" for b in o.pose.bones}
    meshes = [o for o in scene.objects if o.type == "MESH" and o not in shapes]  # not the bone shapes
    start, end = scene.frame_start, scene.frame_end
    for obj in scene.objects:
        action = obj.animation_data.action if obj.animation_data else None
        if action is not None:
            start, end = action.frame_range
            break
    tris, base = [], 0
    for obj in meshes:
        tris.append(_triangles(obj.data) + base)
        base += len(obj.data.vertices)
    tris = np.concatenate(tris)
    rest = np.concatenate([_positions(o.data, o.matrix_world) for o in meshes])
    out = [rest]
    for k in range(n_frames):
        scene.frame_set(int(round(start + (end - start) * k / n_frames)))
        out.append(_evaluated(meshes))
    return weld_frames(np.stack(out), tris, key=rest)
