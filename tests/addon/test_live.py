"""The add-on's live path with the `bpy` module: registration, frame changes on the shared
characters, modifiers, odd objects, files, undo and a Cycles render of the outputs.

The add-on is registered from source (`addon/` as the package `addon`); installing the
built extension is tested beside this file by the packaging tests.
"""

import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import hemishadow  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DATA = os.path.join(os.path.dirname(ROOT), "shared", "data")
sys.path.insert(0, ROOT)
import addon  # noqa: E402
from addon import engine_bridge, mesh_io  # noqa: E402
from spies import count_solves  # noqa: E402
import layers  # noqa: E402
from layers import attribute  # noqa: E402


# -- helpers -------------------------------------------------------------------------------

def import_character(name):
    bpy.ops.import_scene.gltf(filepath=os.path.join(DATA, name))
    meshes = [o for o in bpy.context.scene.objects if o.type == "MESH" and o.find_armature()]
    for obj in meshes:
        obj.hemishadow.enabled = True
        obj.hemishadow.write_sh = True
    return meshes


def sh_layers(obj):
    return layers.sh_layers(obj, mesh_io.SH_PREFIX)


def expected_transfer(obj, count=None):
    """The engine's transfer on the evaluated mesh, read here independently of the add-on:
    a fresh solver built on the rest pose, both in the object's frame (its world matrix
    without the rotation: the polar decomposition), the result turned by that rotation."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(depsgraph)
    count = count or len(obj.data.vertices)
    matrix = np.array(evaluated.matrix_world, np.float64)
    u, scales, vt = np.linalg.svd(matrix[:3, :3])
    rotation = u @ vt
    turned = np.abs(rotation - np.eye(3)).max() >= 1e-6
    if not turned:
        shape, offset = matrix[:3, :3], matrix[:3, 3]
    elif np.ptp(scales) <= 1e-6 * scales.max():
        shape, offset = np.float32(scales.mean()) * np.eye(3), np.zeros(3)
    else:
        shape, offset = rotation.T @ matrix[:3, :3], np.zeros(3)
    shape, offset = shape.astype(np.float32), offset.astype(np.float32)
    co = np.empty(len(evaluated.data.vertices) * 3, np.float32)
    evaluated.data.vertices.foreach_get("co", co)
    frame = co.reshape(-1, 3)[:count] @ shape.T + offset
    tris = np.empty(len(obj.data.loop_triangles) * 3, np.int64)
    obj.data.loop_triangles.foreach_get("vertices", tris)
    rest = np.empty(count * 3, np.float32)
    obj.data.vertices.foreach_get("co", rest)
    rest = rest.reshape(-1, 3) @ shape.T + offset
    transfer = hemishadow.TransferSolver(rest, tris.reshape(-1, 3), bands=5).solve(frame)
    return hemishadow.rotate_sh(transfer.T, rotation).T if turned else transfer


def expected_radiance(obj, scene, transfer):
    return hemishadow.shade(transfer, engine_bridge.scene_lighting(scene, 5), np.asarray(obj.hemishadow.albedo))


def grid_with_box(name="ground"):
    """One mesh: a 2 m subdivided ground plane with a 0.6 m box standing on its middle."""
    import bmesh

    bm = bmesh.new()
    bmesh.ops.create_grid(bm, x_segments=24, y_segments=24, size=1.0)
    box = bmesh.ops.create_cube(bm, size=0.6)
    bmesh.ops.translate(bm, vec=(0, 0, 0.3), verts=box["verts"])
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    obj.hemishadow.enabled = True
    return obj


# -- registration -------------------------------------------------------------------------

def test_register_unregister_twice():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    for _ in range(2):
        addon.register()
        assert hasattr(bpy.types.Object, "hemishadow") and hasattr(bpy.types.Scene, "hemishadow")
        assert hasattr(bpy.ops.hemishadow, "compute") and "HEMISHADOW_PT_actions" in dir(bpy.types)
        assert addon.handlers.on_frame_change in bpy.app.handlers.frame_change_post
        addon.unregister()
        assert not hasattr(bpy.types.Object, "hemishadow")
        assert "HEMISHADOW_PT_actions" not in dir(bpy.types)
        assert addon.handlers.on_frame_change not in bpy.app.handlers.frame_change_post


# -- characters ---------------------------------------------------------------------------

@pytest.mark.parametrize("name, frames", [("cesium_man.glb", (5, 20)), ("fox.glb", (10, 40))])
def test_character_frames_match_engine(scene, name, frames):
    (obj,) = import_character(name)
    scene.hemishadow.live = True
    radiance = []
    for frame in frames:
        scene.frame_set(frame)
        transfer = expected_transfer(obj)
        np.testing.assert_allclose(sh_layers(obj), transfer, atol=1e-5)
        np.testing.assert_allclose(attribute(obj, mesh_io.RADIANCE), expected_radiance(obj, scene, transfer), atol=1e-5)
        np.testing.assert_allclose(attribute(obj, mesh_io.AO), hemishadow.ambient_occlusion(transfer), atol=1e-5)
        radiance.append(attribute(obj, mesh_io.RADIANCE))
    assert np.abs(radiance[0] - radiance[1]).max() > 0.02, "the pose changed, so must the shadows"
    assert obj.data.color_attributes.active_color_name == mesh_io.RADIANCE
    assert obj.data.color_attributes.default_color_name == mesh_io.RADIANCE


def test_split_vertices_are_welded(scene):
    """fox.glb is a triangle soup: copies of a position must get one value."""
    (obj,) = import_character("fox.glb")
    bpy.ops.hemishadow.compute()
    co = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", co)
    _, group = np.unique(co.reshape(-1, 3), axis=0, return_inverse=True)
    group = group.ravel()
    ao = attribute(obj, mesh_io.AO)
    low, high = np.full(group.max() + 1, np.inf), np.full(group.max() + 1, -np.inf)
    np.minimum.at(low, group, ao)
    np.maximum.at(high, group, ao)
    assert group.max() + 1 < len(ao) / 2 and (high - low).max() < 1e-6


def test_lighting_change_reshades_without_transfer(scene, monkeypatch):
    (obj,) = import_character("cesium_man.glb")
    scene.hemishadow.live = True
    scene.frame_set(3)
    before = attribute(obj, mesh_io.RADIANCE)
    solves = count_solves(monkeypatch)
    scene.hemishadow.intensity = 2.0
    obj.hemishadow.albedo = (0.4, 0.4, 0.4)
    np.testing.assert_allclose(attribute(obj, mesh_io.RADIANCE), before, rtol=1e-5, atol=1e-6)
    assert solves == []


def test_switching_live_on_shades_once(scene, monkeypatch):
    """Switching Live on computes under the lighting as it is: the update its writes cause
    shades nothing again, so the first computation's timings stay on show."""
    obj = grid_with_box()
    reshaded = []
    reshade = engine_bridge.reshade_object
    monkeypatch.setattr(engine_bridge, "reshade_object", lambda o, *a, **k: reshaded.append(o.name) or reshade(o, *a, **k))
    scene.hemishadow.live = True
    timing = engine_bridge.last_timings[obj.name]
    bpy.context.view_layer.update()
    scene.frame_set(scene.frame_current)
    assert reshaded == []
    assert engine_bridge.last_timings[obj.name] == timing
    scene.hemishadow.intensity = 2.0  # a real change of the lighting still shades again
    assert reshaded == [obj.name]


def test_handlers_do_not_loop_and_follow_poses(scene, monkeypatch):
    (obj,) = import_character("cesium_man.glb")
    scene.hemishadow.live = True
    scene.frame_set(3)
    solves = count_solves(monkeypatch)
    bpy.context.view_layer.update()  # our own attribute writes are pending: nothing to compute
    scene.frame_set(3)
    assert solves == []
    armature = obj.find_armature()
    armature.pose.bones[2].rotation_quaternion = (0.7, 0.7, 0, 0)
    bpy.context.view_layer.update()  # a pose edit: depsgraph_update_post recomputes once
    assert solves == [1]
    np.testing.assert_allclose(sh_layers(obj), expected_transfer(obj), atol=1e-5)


def test_playback_leaves_no_thread_spinning(scene):
    """numpy's OpenBLAS runs large products on threads that then spin for about 0.1 s of CPU,
    taking the cores the next frame's solve needs (the demo's frame: 100 -> 70 ms). The live
    path keeps its products off them: once a frame is written, the process is idle."""
    import time

    (obj,) = import_character("cesium_man.glb")  # turned to Z up: its transfer is turned each frame
    for kind in ("SPOT", "POINT", "AREA"):  # lamps light each of its 3,315 vertices
        lamp = bpy.data.objects.new(kind, bpy.data.lights.new(kind, kind))
        lamp.location = (1.0, -2.0, 2.0)
        scene.collection.objects.link(lamp)
    scene.hemishadow.live = True
    scene.frame_set(2)
    time.sleep(0.5)  # threads woken by earlier tests go back to sleep
    for frame in (3, 4, 5):
        scene.frame_set(frame)
    start = time.process_time()
    time.sleep(0.3)
    assert time.process_time() - start < 0.03
    assert engine_bridge.last_timings[obj.name][0] == len(obj.data.vertices)


def test_engine_error_stays_in_status(scene, monkeypatch):
    (obj,) = import_character("cesium_man.glb")

    def fail(*args, **kwargs):
        raise RuntimeError("engine exploded")

    monkeypatch.setattr(hemishadow.TransferSolver, "solve", fail)
    scene.hemishadow.live = True
    scene.frame_set(7)  # must not raise
    assert "engine exploded" in obj.hemishadow.status
    with pytest.raises(RuntimeError, match="engine exploded"):
        bpy.ops.hemishadow.compute()


def test_an_engine_that_cannot_be_imported_is_named_in_the_status(scene, monkeypatch):
    """A broken install (a wheel for another platform, a missing dependency): Live and the
    frames it computes say so in the object's status instead of raising from a handler."""
    obj = grid_with_box()
    engine_bridge.forget()  # no solver kept from an earlier test
    monkeypatch.setitem(sys.modules, "hemishadow", None)  # `import hemishadow` raises ImportError
    scene.hemishadow.live = True
    scene.frame_set(scene.frame_current + 1)  # must not raise
    assert "the hemishadow engine could not be loaded" in obj.hemishadow.status, obj.hemishadow.status
    assert obj.hemishadow.status.startswith(f"{obj.name}: ")
    assert mesh_io.RADIANCE not in obj.data.attributes


def test_phong_uses_camera(scene):
    (obj,) = import_character("cesium_man.glb")
    obj.hemishadow.brdf = "PHONG"
    with pytest.raises(RuntimeError, match="active camera"):
        bpy.ops.hemishadow.compute()
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(camera)
    scene.camera = camera
    camera.location = (0, -4, 1)
    bpy.ops.hemishadow.compute()
    assert sh_layers(obj).shape == (len(obj.data.vertices), 25)


# -- modifiers and odd objects ------------------------------------------------------------

def test_subdivision_after_armature(scene):
    (obj,) = import_character("cesium_man.glb")
    count = len(obj.data.vertices)
    obj.modifiers.new("Subdivision", "SUBSURF").levels = 1
    scene.hemishadow.live = True
    values = []
    for frame in (5, 20):
        scene.frame_set(frame)
        assert len(attribute(obj, mesh_io.RADIANCE)) == count, obj.hemishadow.status
        np.testing.assert_allclose(sh_layers(obj), expected_transfer(obj, count), atol=1e-5)
        evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
        subdivided = attribute(obj, mesh_io.RADIANCE, evaluated)
        assert len(subdivided) > 4 * count  # the modifier interpolated the attribute
        values.append(subdivided)
    assert np.abs(values[0] - values[1]).max() > 0.02
    assert len(obj.data.vertices) == count and not obj.data.is_editmode


def test_topology_changing_modifier_is_reported(scene):
    obj = grid_with_box()
    obj.modifiers.new("Decimate", "DECIMATE").ratio = 0.5
    with pytest.raises(RuntimeError, match="Decimate"):
        bpy.ops.hemishadow.compute()
    assert "Decimate" in obj.hemishadow.status and mesh_io.RADIANCE not in obj.data.attributes


def test_mesh_without_faces(scene):
    mesh = bpy.data.meshes.new("points")
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1)], [])
    obj = bpy.data.objects.new("points", mesh)
    scene.collection.objects.link(obj)
    obj.hemishadow.enabled = True
    scene.hemishadow.live = True
    scene.frame_set(2)
    assert "no faces" in obj.hemishadow.status and mesh_io.RADIANCE not in mesh.attributes
    with pytest.raises(RuntimeError, match="no faces"):
        bpy.ops.hemishadow.compute()


def test_deleted_object(scene):
    (obj,) = import_character("cesium_man.glb")
    other = grid_with_box()
    scene.hemishadow.live = True
    scene.frame_set(2)
    uid = obj.session_uid
    assert engine_bridge.has_transfer(obj)
    bpy.data.objects.remove(obj)
    scene.frame_set(3)
    assert uid not in engine_bridge._entries
    assert mesh_io.RADIANCE in other.data.attributes


def test_edit_mode_is_skipped(scene):
    obj = grid_with_box()
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    scene.hemishadow.live = True
    scene.frame_set(4)
    assert "Edit Mode" in obj.hemishadow.status
    bpy.ops.object.mode_set(mode="OBJECT")
    scene.frame_set(5)
    assert mesh_io.RADIANCE in obj.data.attributes


def test_clear_removes_only_hemishadow_attributes(scene):
    (obj,) = import_character("cesium_man.glb")
    bpy.ops.hemishadow.compute()
    before = {a.name for a in obj.data.attributes if not a.name.startswith("hemishadow_")}
    bpy.ops.hemishadow.clear()
    after = {a.name for a in obj.data.attributes}
    assert after == before
    bpy.ops.hemishadow.compute()  # computes and writes again after a clear
    assert mesh_io.RADIANCE in obj.data.attributes


# -- files and undo -----------------------------------------------------------------------

def test_save_and_reload(scene, tmp_path):
    (obj,) = import_character("cesium_man.glb")
    obj.hemishadow.bands = "16"
    scene.hemishadow.live = True
    scene.hemishadow.intensity = 1.5
    scene.frame_set(9)
    radiance, name = attribute(obj, mesh_io.RADIANCE), obj.name
    path = str(tmp_path / "saved.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    obj, scene = bpy.data.objects[name], bpy.context.scene
    assert obj.hemishadow.enabled and obj.hemishadow.bands == "16"
    assert scene.hemishadow.live and scene.hemishadow.intensity == 1.5
    np.testing.assert_array_equal(attribute(obj, mesh_io.RADIANCE), radiance)
    assert sh_layers(obj).shape[1] == 16


def test_undo_after_compute(scene):
    """`ed.undo` works headless once two undo steps exist (checked with bpy 5.0.1)."""
    obj = grid_with_box()
    bpy.ops.ed.undo_push(message="before")
    bpy.ops.hemishadow.compute()
    bpy.ops.ed.undo_push(message="compute")
    assert mesh_io.RADIANCE in obj.data.attributes
    bpy.ops.ed.undo()
    obj = bpy.data.objects["ground"]
    assert mesh_io.RADIANCE not in obj.data.attributes and obj.hemishadow.enabled
    bpy.context.scene.hemishadow.live = True  # the live path writes again after the undo
    assert mesh_io.RADIANCE in obj.data.attributes


# -- rendering ----------------------------------------------------------------------------

def camera_pixel(scene, camera, point):
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    ndc = world_to_camera_view(scene, camera, Vector(point))
    size = scene.render.resolution_x
    return int(ndc.y * size), int(ndc.x * size)  # row from the bottom, column


def render_ground_with_box(scene, path, engine):
    """Compute the ground-with-box mesh, give it the Emit material, render it from above
    into a linear EXR; returns (image rows from the bottom, positions, radiance, camera)."""
    from hemishadow.environment import read_exr

    obj = grid_with_box()
    bpy.ops.hemishadow.compute()
    bpy.context.view_layer.objects.active = obj
    bpy.ops.hemishadow.add_material(mode="EMIT")
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    camera.data.type, camera.data.ortho_scale = "ORTHO", 2.0
    camera.location = (0, 0, 5)
    scene.collection.objects.link(camera)
    scene.camera = camera
    render = scene.render
    render.engine, render.resolution_x, render.resolution_y, render.resolution_percentage = engine, 64, 64, 100
    scene.cycles.device, scene.cycles.samples, scene.cycles.use_denoising = "CPU", 4, False
    scene.view_settings.view_transform = "Standard"
    render.image_settings.file_format = "OPEN_EXR"
    render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    co = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", co)
    return read_exr(path)[::-1], co.reshape(-1, 3), attribute(obj, mesh_io.RADIANCE), camera


def check_shadow_in_render(scene, path, engine):
    image, co, radiance, camera = render_ground_with_box(scene, path, engine)
    # Ground vertices just outside the box (in its shadow), and one ring in from a corner.
    on_ground = np.abs(co[:, 2]) < 1e-6
    ring = np.maximum(np.abs(co[:, 0]), np.abs(co[:, 1]))
    shadowed = np.flatnonzero(on_ground & (ring > 0.35) & (ring < 0.45))
    dark = shadowed[np.argmin(radiance[shadowed, 0])]
    bright = np.argmin(np.linalg.norm(co - (0.9, 0.9, 0), axis=1))
    values = {}
    for name, vertex in (("dark", dark), ("bright", bright)):
        row, col = camera_pixel(scene, camera, co[vertex])
        values[name] = image[row, col, 0]
        np.testing.assert_allclose(values[name], radiance[vertex, 0], rtol=0.15, err_msg=name)
    assert values["dark"] < 0.8 * values["bright"]


def test_cycles_render_shows_radiance(scene, tmp_path):
    check_shadow_in_render(scene, tmp_path / "cycles.exr", "CYCLES")


def test_eevee_render_shows_radiance(scene, tmp_path):
    """EEVEE through Mesa's software OpenGL: slow (about 25 s, shader compilation), but real."""
    engines = {e.identifier for e in scene.render.bl_rna.properties["engine"].enum_items}
    check_shadow_in_render(scene, tmp_path / "eevee.exr", "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in engines
                           else "BLENDER_EEVEE")


def test_multiply_material_keeps_base_color_texture(scene):
    (obj,) = import_character("cesium_man.glb")
    material = obj.material_slots[0].material
    bsdf = next(n for n in material.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    texture = bsdf.inputs["Base Color"].links[0].from_node
    bpy.context.view_layer.objects.active = obj
    bpy.ops.hemishadow.add_material(mode="MULTIPLY")
    group = next(n for n in material.node_tree.nodes if n.bl_idname == "ShaderNodeGroup")
    assert group.inputs["Base Color"].links[0].from_node == texture
    output = next(n for n in material.node_tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    assert output.inputs["Surface"].links[0].from_node == group
