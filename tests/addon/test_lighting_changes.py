"""Lighting that changes over time (issue 7, case 6): a keyframed sun, a moving lamp, a
keyframed World strength, a hidden sun and an animation render re-shade static objects from
their stored transfer (no new transfer), frame by frame.

Before: `handlers._lighting_updated` only looked for World/Light datablocks in depsgraph
updates, so a static object kept the radiance of the frame it was first computed on.
"""

import math
import pathlib
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import hemishadow  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
import addon  # noqa: E402
from addon import engine_bridge, lamps, mesh_io  # noqa: E402
from spies import count_solves  # noqa: E402


@pytest.fixture
def scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()
    scene = bpy.context.scene
    scene.hemishadow.lighting_source = "UNIFORM"
    scene.hemishadow.uniform_color = (0, 0, 0)
    scene.frame_start, scene.frame_end = 1, 5
    yield scene
    addon.unregister()


def ground(scene):
    """A static ground with a box standing on it, enabled, live."""
    import bmesh

    bm = bmesh.new()
    bmesh.ops.create_grid(bm, x_segments=12, y_segments=12, size=1.0)
    box = bmesh.ops.create_cube(bm, size=0.6)
    bmesh.ops.translate(bm, vec=(0, 0, 0.3), verts=box["verts"])
    mesh = bpy.data.meshes.new("ground")
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new("ground", mesh)
    scene.collection.objects.link(obj)
    obj.hemishadow.enabled = True
    scene.hemishadow.live = True
    return obj


def radiance_of(obj):
    attr = obj.data.attributes[mesh_io.RADIANCE]
    out = np.empty(len(attr.data) * 4, np.float32)
    attr.data.foreach_get("color", out)
    return out.reshape(-1, 4)[:, :3]


def expected(obj, scene):
    """Radiance from the stored transfer and the lighting as it is now (computed here)."""
    transfer = engine_bridge._entries[obj.session_uid].transfer
    lighting = engine_bridge.scene_lighting(scene, 5)
    points = mesh_io.to_world(mesh_io.positions_of(obj.data), obj.matrix_world)
    lamp_light = lamps.lamp_irradiance(transfer, points, lamps.scene_lamps(scene))
    irradiance = hemishadow.shade(transfer, lighting) + lamp_light
    return np.asarray(obj.hemishadow.albedo) / math.pi * irradiance


def add_light(scene, kind, **settings):
    data = bpy.data.lights.new(kind.lower(), kind)
    for name, value in settings.items():
        setattr(data, name, value)
    obj = bpy.data.objects.new(kind.lower(), data)
    scene.collection.objects.link(obj)
    return obj


def check_frames(obj, scene, frames, monkeypatch):
    solves = count_solves(monkeypatch)
    seen = []
    for frame in frames:
        scene.frame_set(frame)
        shown = radiance_of(obj)
        np.testing.assert_allclose(shown, expected(obj, scene), rtol=1e-4, atol=1e-5 * shown.max())
        seen.append(shown)
    assert solves == []  # static object: re-shaded, never recomputed
    return seen


def test_keyframed_sun_rotation_and_strength_reshade(scene, monkeypatch):
    obj = ground(scene)
    sun = add_light(scene, "SUN", energy=2.0)
    sun.rotation_euler = (0, 0, 0)
    sun.keyframe_insert("rotation_euler", frame=1)
    sun.data.keyframe_insert("energy", frame=1)
    sun.rotation_euler = (math.radians(70), 0, 0)
    sun.data.energy = 5.0
    sun.keyframe_insert("rotation_euler", frame=5)
    sun.data.keyframe_insert("energy", frame=5)
    scene.frame_set(1)
    first, middle, last = check_frames(obj, scene, [1, 3, 5], monkeypatch)
    assert np.abs(last - first).max() > 0.2 * first.max()


def test_moving_point_lamp_reshades(scene, monkeypatch):
    obj = ground(scene)
    point = add_light(scene, "POINT", energy=40.0)
    point.location = (-1, 0, 1)
    point.keyframe_insert("location", frame=1)
    point.location = (1, 0, 1)
    point.keyframe_insert("location", frame=5)
    scene.frame_set(1)
    first, last = check_frames(obj, scene, [1, 5], monkeypatch)
    left = mesh_io.positions_of(obj.data)[:, 0] < -0.5
    assert first[left, 0].mean() > 3 * last[left, 0].mean()


def test_keyframed_world_strength_reshades(scene, monkeypatch):
    obj = ground(scene)
    scene.hemishadow.lighting_source = "WORLD"
    scene.world = bpy.data.worlds.new("sky")
    strength = scene.world.node_tree.nodes["Background"].inputs["Strength"]
    strength.default_value = 1.0
    strength.keyframe_insert("default_value", frame=1)
    strength.default_value = 3.0
    strength.keyframe_insert("default_value", frame=5)
    scene.frame_set(1)
    first, last = check_frames(obj, scene, [1, 5], monkeypatch)
    np.testing.assert_allclose(last, 3 * first, rtol=1e-4)


def test_hiding_a_sun_reshades(scene, monkeypatch):
    obj = ground(scene)
    sun = add_light(scene, "SUN", energy=3.0)
    scene.frame_set(1)
    lit = radiance_of(obj).copy()
    solves = count_solves(monkeypatch)
    sun.hide_viewport = True
    bpy.context.view_layer.update()  # depsgraph_update_post: the lighting changed
    assert radiance_of(obj).max() < 1e-6 < lit.max()
    assert solves == []


def test_animation_render_reshades_every_frame(scene, tmp_path):
    obj = ground(scene)
    sun = add_light(scene, "SUN", energy=1.0)
    sun.data.keyframe_insert("energy", frame=1)
    sun.data.energy = 4.0
    sun.data.keyframe_insert("energy", frame=2)
    scene.frame_set(1)
    scene.frame_end = 2
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.render.resolution_x = scene.render.resolution_y = 8
    scene.render.filepath = str(tmp_path / "frame_")
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    camera.location = (0, 0, 5)
    scene.collection.objects.link(camera)
    scene.camera = camera
    seen = {}

    def record(render_scene, *_):  # after the frame rendered: what it rendered
        seen[render_scene.frame_current] = radiance_of(obj).max()

    bpy.app.handlers.render_post.append(record)
    try:
        bpy.ops.render.render(animation=True)
    finally:
        bpy.app.handlers.render_post.remove(record)
    assert seen[1] > 0.1 and seen[2] == pytest.approx(4 * seen[1], rel=1e-4)
