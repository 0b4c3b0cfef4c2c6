"""Shadow casters (issue 10, Blender side): a collection of objects shadowing a receiver on top
of its self-shadowing, kept as one hemishadow.Scene (addon/casters.py), live and baked.

The reference is the engine's own Scene, built here from the same geometry without the add-on:
a plane's vertices under a cube must get the Scene's ambient occlusion.
"""

import sys
import threading

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import bmesh  # noqa: E402
import hemishadow  # noqa: E402

from conftest import ROOT  # noqa: E402

sys.path.insert(0, str(ROOT))
from addon import cache, casters, engine_bridge, jobs, mesh_io  # noqa: E402
from addon.operators import bake  # noqa: E402
from layers import attribute  # noqa: E402
from spies import count_solves  # noqa: E402


# -- helpers -------------------------------------------------------------------------------

def ground(scene, name="Ground", segments=20, size=2.0):
    """An enabled subdivided plane of 2 x `size` m at z = 0 (normals up)."""
    bm = bmesh.new()
    bmesh.ops.create_grid(bm, x_segments=segments, y_segments=segments, size=size)
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    obj.hemishadow.enabled = True
    return obj


def cube(scene, name="Cube", location=(0.0, 0.0, 0.6), size=0.8, mesh=None):
    if mesh is None:
        bm = bmesh.new()
        bmesh.ops.create_cube(bm, size=size)
        mesh = bpy.data.meshes.new(name)
        bm.to_mesh(mesh)
        bm.free()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    scene.collection.objects.link(obj)
    return obj


def casters_collection(scene, objects, name="Shadow casters", default=True):
    collection = bpy.data.collections.new(name)
    scene.collection.children.link(collection)
    for obj in objects:
        collection.objects.link(obj)
    if default:
        scene.hemishadow.casters = collection
    return collection


def world_vertices(obj):
    co = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", co)
    return mesh_io.to_world(co.reshape(-1, 3), obj.matrix_world)


def live_ao(scene, obj):
    """AO of `obj` after a forced live computation of the scene."""
    engine_bridge.compute_now(scene, bpy.context.evaluated_depsgraph_get())
    return attribute(obj, mesh_io.AO)


def caster_scene(obj, scene):
    """The CasterScene the add-on shadows `obj` with this frame."""
    use = casters.for_object(obj, scene, bpy.context.evaluated_depsgraph_get())
    assert use is not None
    use.release()
    return use.caster_scene


def under(points, center=(0.0, 0.0), half=0.4):
    return (np.abs(points[:, 0] - center[0]) < half) & (np.abs(points[:, 1] - center[1]) < half)


class SceneCalls:
    """Counts the hemishadow.Scene calls that change a scene (a spy)."""

    def __init__(self, monkeypatch):
        self.calls = []
        for name in ("add_mesh", "add_instance", "set_vertices", "set_matrix"):
            original = getattr(hemishadow.Scene, name)

            def spy(self_, *args, _name=name, _original=original, **kwargs):
                self.calls.append(_name)
                return _original(self_, *args, **kwargs)

            monkeypatch.setattr(hemishadow.Scene, name, spy)

    def of(self, name):
        return self.calls.count(name)


# -- shadowing -----------------------------------------------------------------------------

@pytest.mark.parametrize("rotation, scale", [((0, 0, 0), (1, 1, 1)), ((0, 0, 0.5), (1, 1, 1)),
                                             ((0.2, 0, 2.0), (-1, 1, 1))], ids=["world", "turned", "mirrored"])
def test_a_cube_darkens_the_plane_under_it_as_the_scene_does(scene, rotation, scale):
    """The receiver's frame (turned, mirrored, moved) is placed among the casters exactly."""
    plane, box = ground(scene), cube(scene, location=(0.3, 0.2, 0.6))
    plane.rotation_euler, plane.scale, plane.location = rotation, scale, (0.3, 0.2, 0.0)
    box.rotation_euler = rotation
    bpy.context.view_layer.update()
    alone = live_ao(scene, plane)
    assert np.abs(alone - 1.0).max() < 1e-4, "a flat plane has no self-shadowing"
    casters_collection(scene, [plane, box])
    shadowed = live_ao(scene, plane)

    points = world_vertices(plane)
    reference = hemishadow.Scene()
    for obj in (plane, box):
        co = np.empty(len(obj.data.vertices) * 3, np.float32)
        obj.data.vertices.foreach_get("co", co)
        reference.add_instance(reference.add_mesh(co.reshape(-1, 3), mesh_io.triangles_of(obj.data)),
                               np.array(obj.matrix_world))
    up = np.asarray(plane.matrix_world.to_3x3() @ __import__("mathutils").Vector((0, 0, 1)))
    expected = reference.ambient_occlusion(points, np.tile(up, (len(points), 1)))
    below = np.linalg.norm(points[:, :2] - (0.3, 0.2), axis=1) < 0.25
    assert (alone[below] - shadowed[below]).min() > 0.2, "every vertex under the cube is darkened"
    # Both rasterize 32x32 hemispheres, each in its own tangent frame: 0.015 apart at most.
    assert np.abs(shadowed - expected).max() < 0.02 and np.abs(shadowed - expected).mean() < 0.005
    assert "shadowed by 'Shadow casters'" in plane.hemishadow.status


def test_an_object_in_its_own_casters_is_not_shadowed_twice(scene):
    bpy.ops.mesh.primitive_monkey_add(location=(0.3, -0.2, 0.1), rotation=(0.4, 0.2, 1.0))
    monkey = bpy.context.object
    monkey.hemishadow.enabled = True
    alone = live_ao(scene, monkey)
    assert alone.min() < 0.5, "Suzanne shadows herself"
    casters_collection(scene, [monkey])
    assert caster_scene(monkey, scene).scene.triangle_count > 0   # it is there, and excluded
    np.testing.assert_allclose(live_ao(scene, monkey), alone, atol=1e-5)


def test_each_object_takes_its_own_collection_before_the_default(scene):
    plane, box = ground(scene), cube(scene)
    casters_collection(scene, [box], name="Default")
    own = casters_collection(scene, [], name="Nothing here", default=False)
    plane.hemishadow.casters = own   # empty: self-shadowing only
    assert np.abs(live_ao(scene, plane) - 1.0).max() < 1e-4
    plane.hemishadow.casters = None
    assert live_ao(scene, plane).min() < 0.7


# -- moving and static casters -------------------------------------------------------------

def test_a_keyframed_caster_moves_the_shadow_and_a_static_one_costs_nothing(scene, monkeypatch):
    plane, box = ground(scene), cube(scene)
    casters_collection(scene, [plane, box])
    box.location = (-1.0, 0.0, 0.6)
    box.keyframe_insert("location", frame=1)
    box.location = (1.0, 0.0, 0.6)
    box.keyframe_insert("location", frame=10)
    scene.frame_set(1)
    scene.hemishadow.live = True
    first = attribute(plane, mesh_io.AO)
    calls = SceneCalls(monkeypatch)
    scene.frame_set(10)
    last = attribute(plane, mesh_io.AO)
    points = world_vertices(plane)
    left, right = under(points, (-1.0, 0.0)), under(points, (1.0, 0.0))
    assert first[left].max() < 0.8 and last[left].min() > 0.9
    assert last[right].max() < 0.8 and first[right].min() > 0.9
    assert calls.of("set_matrix") == 1 and calls.of("add_mesh") == 0, "moved, not rebuilt"

    box.animation_data_clear()   # now everything is static
    scene.frame_set(11)
    calls.calls.clear()
    solves = count_solves(monkeypatch)
    for frame in (12, 13, 14):
        scene.frame_set(frame)
    assert calls.calls == [] and solves == [], "static casters are neither refitted nor solved again"


def test_a_deforming_caster_is_refitted_not_rebuilt(scene, monkeypatch):
    plane, box = ground(scene), cube(scene)
    casters_collection(scene, [plane, box])
    box.shape_key_add(name="Basis")
    tall = box.shape_key_add(name="Tall")
    for point in tall.data:
        point.co.z += 1.0 if point.co.z > 0 else 0.0   # the top goes up
    tall.value = 0.0
    tall.keyframe_insert("value", frame=1)
    tall.value = 1.0
    tall.keyframe_insert("value", frame=5)
    scene.frame_set(1)
    scene.hemishadow.live = True
    before = attribute(plane, mesh_io.AO)
    calls = SceneCalls(monkeypatch)
    scene.frame_set(5)
    assert calls.of("set_vertices") == 1 and calls.of("add_mesh") == 0 and calls.of("set_matrix") == 0
    beside = under(world_vertices(plane), half=1.0) & ~under(world_vertices(plane), half=0.5)
    after = attribute(plane, mesh_io.AO)
    assert (after[beside] < before[beside] - 0.01).all(), "a taller box shadows more around it"


def test_moving_a_caster_by_hand_recomputes_the_receiver(scene):
    plane, box = ground(scene), cube(scene)
    casters_collection(scene, [plane, box])
    scene.hemishadow.live = True
    before = attribute(plane, mesh_io.AO)
    box.location.x = 1.2   # a transform edit: depsgraph_update_post, not a frame change
    bpy.context.view_layer.update()
    below = under(world_vertices(plane))
    assert (attribute(plane, mesh_io.AO)[below] > before[below] + 0.2).all()


def test_a_scene_held_by_a_solve_is_not_changed_meanwhile(scene):
    """A worker may still solve with last frame's casters: the next frame updates another scene."""
    plane, box = ground(scene), cube(scene)
    casters_collection(scene, [plane, box])
    held = casters.for_object(plane, scene, bpy.context.evaluated_depsgraph_get())
    version = held.caster_scene.version
    box.location.x = 1.0
    moved = casters.for_object(plane, scene, bpy.context.evaluated_depsgraph_get())
    assert moved.caster_scene is not held.caster_scene and held.caster_scene.version == version
    held.release()
    moved.release()
    box.location.x = -1.0
    again = casters.for_object(plane, scene, bpy.context.evaluated_depsgraph_get())
    assert again.caster_scene is held.caster_scene and again.version > version, "free again: updated in place"


def test_a_worker_solves_with_the_casters_of_its_own_frame(scene, monkeypatch):
    """A heavy object solved in the worker (jobs.py) after the main thread moved on."""
    plane, box = ground(scene), cube(scene)
    casters_collection(scene, [plane, box])
    for frame, x in ((1, -1.0), (10, 1.0)):
        box.location.x = x
        box.keyframe_insert("location", frame=frame)
    monkeypatch.setattr(jobs, "HEAVY_VERTICES", 0)
    entered, gate, real = threading.Event(), threading.Event(), engine_bridge.solve_object

    def gated(request, progress=None):
        if threading.current_thread() is not threading.main_thread():
            entered.set()
            gate.wait(30)
        return real(request, progress)

    monkeypatch.setattr(engine_bridge, "solve_object", gated)
    try:
        scene.frame_set(1)
        jobs.update_scene(scene, bpy.context.evaluated_depsgraph_get(), [plane], interactive=True)
        assert entered.wait(30) and jobs.pending([plane])
        scene.frame_set(10)   # the main thread brings the casters to frame 10 meanwhile
        casters.for_object(plane, scene, bpy.context.evaluated_depsgraph_get()).release()
    finally:
        gate.set()
    jobs.finish_all()
    ao, points = attribute(plane, mesh_io.AO), world_vertices(plane)
    assert ao[under(points, (-1.0, 0.0))].max() < 0.8 and ao[under(points, (1.0, 0.0))].min() > 0.9


# -- instancing ----------------------------------------------------------------------------

def test_linked_duplicates_share_one_scene_mesh(scene):
    plane, box = ground(scene), cube(scene, location=(-1.0, -1.0, 0.6))
    copies = [cube(scene, f"Copy {i}", location, mesh=box.data) for i, location in
              enumerate([(1.0, -1.0, 0.6), (-1.0, 1.0, 0.6), (1.0, 1.0, 0.6)])]
    modified = cube(scene, "Modified", (0.0, 0.0, 0.6), mesh=box.data)
    modified.modifiers.new("Bevel", "BEVEL")   # geometry of its own
    casters_collection(scene, [plane, box, modified, *copies])
    found = caster_scene(plane, scene)
    assert found.scene._native.mesh_count == 3     # plane, the shared cube, the bevelled one
    assert found.scene._native.instance_count == 6
    ao, points = live_ao(scene, plane), world_vertices(plane)
    for x, y in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0), (0.0, 0.0)]:
        assert ao[under(points, (x, y), 0.3)].max() < 0.7


def test_a_collection_instance_casts_without_copies(scene):
    plane = ground(scene)
    source = bpy.data.collections.new("Props")   # not in the scene: drawn through instances only
    source.objects.link(cube(bpy.data.scenes.new("unused"), "Prop", (0.0, 0.0, 0.0)))
    instancers = []
    for i, x in enumerate((-1.0, 1.0)):
        empty = bpy.data.objects.new(f"Props {i}", None)
        empty.instance_type, empty.instance_collection = "COLLECTION", source
        empty.location = (x, 0.0, 0.6)
        scene.collection.objects.link(empty)
        instancers.append(empty)
    casters_collection(scene, [plane, *instancers])
    found = caster_scene(plane, scene)
    assert (found.scene._native.mesh_count, found.scene._native.instance_count) == (2, 3)
    ao, points = live_ao(scene, plane), world_vertices(plane)
    assert ao[under(points, (-1.0, 0.0), 0.3)].max() < 0.7 and ao[under(points, (1.0, 0.0), 0.3)].max() < 0.7
    assert ao[under(points, (0.0, 1.6), 0.3)].min() > 0.9


def test_geometry_nodes_instances_cast_without_copies(scene):
    plane = ground(scene)
    prop = cube(bpy.data.scenes.new("unused"), "Prop", (0.0, 0.0, 0.0), size=0.6)
    scatter = cube(scene, "Scatter", (0.0, 0.0, 1.5), size=2.0)   # its 8 corners get a prop each
    tree = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    inputs, outputs = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
    on_points, info = tree.nodes.new("GeometryNodeInstanceOnPoints"), tree.nodes.new("GeometryNodeObjectInfo")
    info.inputs["Object"].default_value = prop
    info.inputs["As Instance"].default_value = True
    tree.links.new(inputs.outputs[0], on_points.inputs["Points"])
    tree.links.new(info.outputs["Geometry"], on_points.inputs["Instance"])
    tree.links.new(on_points.outputs[0], outputs.inputs[0])
    scatter.modifiers.new("Scatter", "NODES").node_group = tree
    casters_collection(scene, [plane, scatter])
    found = caster_scene(plane, scene)
    assert (found.scene._native.mesh_count, found.scene._native.instance_count) == (2, 9)
    assert found.notes == [], "the instancer's own (empty) mesh is no error"
    ao, points = live_ao(scene, plane), world_vertices(plane)
    for x in (-1.0, 1.0):
        for y in (-1.0, 1.0):
            assert ao[under(points, (x, y), 0.15)].max() < 0.8


# -- bad input -----------------------------------------------------------------------------

def test_casters_that_cannot_cast_are_named_not_raised(scene):
    plane, box = ground(scene), cube(scene)
    bpy.ops.curve.primitive_bezier_curve_add(location=(0.0, 1.0, 1.0))
    curve = bpy.context.object
    points_only = bpy.data.meshes.new("Points")
    points_only.from_pydata([(0, 0, 1), (1, 0, 1), (0, 1, 1)], [], [])
    loose = bpy.data.objects.new("Loose points", points_only)
    scene.collection.objects.link(loose)
    flat = cube(scene, "Flattened", (1.0, 1.0, 1.0))
    flat.scale = (1.0, 1.0, 0.0)   # a singular matrix: the engine refuses it
    casters_collection(scene, [plane, box, curve, loose, flat])
    scene.hemishadow.live = True   # computes in the handlers' way: nothing may escape
    scene.frame_set(2)
    status = plane.hemishadow.status
    assert "'BézierCurve' skipped: a curve object" in status, status
    assert "'Loose points' skipped: its mesh has no faces" in status, status
    assert "'Flattened' skipped" in status, status
    assert attribute(plane, mesh_io.AO)[under(world_vertices(plane))].max() < 0.8, "the cube still casts"


# -- the bake ------------------------------------------------------------------------------

@pytest.fixture
def baked(scene, tmp_path):
    """A plane under a keyframed cube, baked over frames 1..3 with the scene's casters."""
    plane, box = ground(scene), cube(scene)
    casters_collection(scene, [plane, box])
    for frame, x in ((1, -0.5), (3, 0.5)):
        box.location.x = x
        box.keyframe_insert("location", frame=frame)
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "casters.blend"))
    bake.bake_range(scene, [plane], 1, 3)
    return plane, box


def test_the_bake_uses_the_casters(scene, baked):
    plane, _ = baked
    cached = cache.load(plane)
    for frame in (1, 3):
        scene.frame_set(frame)
        np.testing.assert_allclose(cached.ao[frame - 1], live_ao(scene, plane), atol=1e-5)
    assert cached.ao[0][under(world_vertices(plane), (-0.5, 0.0), 0.3)].max() < 0.7
    assert cache.why_invalid(plane, scene, 2) is None


def test_the_cache_goes_stale_when_a_caster_moves_or_the_casters_change(scene, baked):
    plane, box = baked
    scene.frame_set(2)
    assert cache.why_invalid(plane, scene) is None
    action = box.animation_data.action
    if bpy.app.version < (4, 4):  # before layered actions, an Action holds its F-Curves
        fcurve = action.fcurves[0]
    else:
        fcurve = action.layers[0].strips[0].channelbags[0].fcurves[0]
    fcurve.keyframe_points[1].co.y = 0.8   # the cube ends elsewhere: frame 2 moves
    fcurve.update()
    scene.frame_set(2)
    reason = cache.why_invalid(plane, scene)
    assert reason is not None and "a shadow caster moved" in reason, reason
    fcurve.keyframe_points[1].co.y = 0.5
    fcurve.update()
    scene.frame_set(2)
    assert cache.why_invalid(plane, scene) is None
    scene.hemishadow.casters.objects.unlink(box)
    assert "shadow casters changed" in cache.why_invalid(plane, scene)
    scene.hemishadow.casters = None
    assert "shadow casters changed" in cache.why_invalid(plane, scene)


def test_a_render_subdividing_a_caster_more_still_uses_the_cache(scene, tmp_path):
    """Renders evaluate Subdivision at its render levels: the caster has more vertices than
    in the bake's viewport, its original ones in place. That is not a moved caster."""
    plane = ground(scene, segments=8)
    bpy.ops.mesh.primitive_monkey_add(location=(0.0, 0.0, 1.0))
    monkey = bpy.context.object
    subdivision = monkey.modifiers.new("Subdivision", "SUBSURF")
    subdivision.levels, subdivision.render_levels = 1, 2
    casters_collection(scene, [plane, monkey])
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "render.blend"))
    bake.bake_range(scene, [plane], 1, 2)
    scene.hemishadow.live = True
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.location = (0.0, -4.0, 2.0)
    scene.collection.objects.link(camera)
    scene.camera = camera
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 1
    scene.render.resolution_x = scene.render.resolution_y = 8
    scene.frame_start = scene.frame_end = 2
    scene.render.filepath = str(tmp_path / "frame_")
    engine_bridge.last_timings.clear()
    bpy.ops.render.render(animation=True)
    assert cache.stale_reason(plane) is None and plane.name not in engine_bridge.last_timings


def test_a_subdivided_caster_casts_its_original_faces_at_every_level(scene):
    """A caster that only deforms and subdivides casts with the surface it receives on: its
    original faces through the first evaluated vertices (the limit positions of the original
    ones), whatever its level; the shadow is the engine's Scene of that surface."""
    plane = ground(scene, segments=16)
    bpy.ops.mesh.primitive_monkey_add(location=(0.1, 0.0, 0.9))
    monkey = bpy.context.object
    monkey.modifiers.new("Bend", "SIMPLE_DEFORM").deform_method = "BEND"
    subdivision = monkey.modifiers.new("Subdivision", "SUBSURF")
    casters_collection(scene, [plane, monkey])
    shadows = {}
    for level in (1, 2):
        subdivision.levels = level
        depsgraph = bpy.context.evaluated_depsgraph_get()
        shown = monkey.evaluated_get(depsgraph).data
        assert len(shown.vertices) > len(monkey.data.vertices)
        known = caster_scene(plane, scene).meshes[("object", monkey.session_uid)]
        assert known.counts == (len(monkey.data.vertices), len(monkey.data.loop_triangles))
        shadows[level] = live_ao(scene, plane)
        first = mesh_io.positions_of(shown, len(monkey.data.vertices))
        reference = hemishadow.Scene()
        reference.add_instance(reference.add_mesh(first, mesh_io.triangles_of(monkey.data)), np.array(monkey.matrix_world))
        points = world_vertices(plane)
        expected = reference.ambient_occlusion(points, np.tile((0.0, 0.0, 1.0), (len(points), 1)))
        assert np.abs(shadows[level] - expected).max() < 0.02 and np.abs(shadows[level] - expected).mean() < 0.005
    assert shadows[1].min() < 0.6, "the monkey shadows the plane"
    assert np.abs(shadows[1] - shadows[2]).max() < 1e-3, "the same caster at both levels"


def test_a_mirrored_caster_casts_all_it_draws(scene):
    """Mirror adds vertices after the original ones without refining them: the caster is the
    evaluated mesh, both halves."""
    plane = ground(scene, segments=16)
    half = cube(scene, location=(0.0, 0.0, 0.6))
    half.data.transform(__import__("mathutils").Matrix.Translation((0.5, 0.0, 0.0)))
    half.modifiers.new("Mirror", "MIRROR")
    half.modifiers.new("Subdivision", "SUBSURF")
    casters_collection(scene, [plane, half])
    shown = half.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    known = caster_scene(plane, scene).meshes[("object", half.session_uid)]
    assert known.counts == (len(shown.vertices), len(shown.loop_triangles))
    ao = live_ao(scene, plane)
    points = world_vertices(plane)
    assert ao[np.linalg.norm(points[:, :2] - (-0.5, 0.0), axis=1) < 0.2].max() < 0.7, "the mirrored half casts"


def test_a_bending_quad_whose_diagonal_flips_is_refitted_not_rebuilt(scene, monkeypatch):
    """Blender splits a quad along the other diagonal once it bends concave (a cloth does this
    every few frames): same faces, so the caster is refitted, not rebuilt every frame."""
    plane = ground(scene)
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0.0, 0.0, 0.6))
    quad = bpy.context.object
    casters_collection(scene, [plane, quad])
    quad.shape_key_add(name="Basis")
    bent = quad.shape_key_add(name="Bent")
    corner = max(range(4), key=lambda i: bent.data[i].co.x - bent.data[i].co.y)  # the (+x, -y) corner
    bent.data[corner].co = (-0.3, 0.3, 0.0)  # into the opposite half: concave there
    for value, frame in ((0.0, 1), (1.0, 5)):
        bent.value = value
        bent.keyframe_insert("value", frame=frame)
    triangles = []
    for frame in (1, 5):
        scene.frame_set(frame)
        evaluated = quad.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
        triangles.append(mesh_io.triangles_of(evaluated).tolist())
    assert sorted(map(sorted, triangles[0])) != sorted(map(sorted, triangles[1])), "the diagonal flipped"
    scene.frame_set(1)
    scene.hemishadow.live = True
    calls = SceneCalls(monkeypatch)
    scene.frame_set(5)
    assert calls.of("set_vertices") == 1 and calls.of("add_mesh") == 0, "refitted, not rebuilt"


def test_a_walking_character_is_darkened_by_a_wall_it_passes(scene):
    """A real imported, skinned and animated character (Cesium Man) walks past a wall: on the
    frame it stands beside it, the side facing the wall darkens, and its AO is the engine's
    for its evaluated mesh with the wall as casters (computed here without the add-on)."""
    bpy.ops.import_scene.gltf(filepath=str(ROOT.parent / "shared" / "data" / "cesium_man.glb"))
    character = next(o for o in scene.objects if o.type == "MESH" and o.find_armature())
    character.hemishadow.enabled = True
    rig = character.find_armature()
    wall = cube(scene, name="Wall", location=(0.6, 0.0, 1.0), size=1.0)
    wall.scale = (0.1, 2.0, 2.0)
    casters_collection(scene, [wall, character])
    for frame, x in ((1, -3.0), (10, 0.0)):  # far from the wall, then beside it
        rig.location.x = x
        rig.keyframe_insert("location", index=0, frame=frame)
    scene.frame_set(1)
    far = live_ao(scene, character)
    scene.frame_set(10)
    near = live_ao(scene, character)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = character.evaluated_get(depsgraph)
    world = mesh_io.to_world(mesh_io.positions_of(evaluated.data, len(character.data.vertices)), evaluated.matrix_world)
    facing = world[:, 0] > np.percentile(world[:, 0], 80)  # the side towards the wall
    assert world[:, 0].max() < 0.55, "beside the wall, not through it"
    assert near[facing].mean() < far[facing].mean() - 0.05
    # The reference: the same evaluated mesh and wall through the engine alone.
    rest = mesh_io.to_world(mesh_io.positions_of(character.data), evaluated.matrix_world)
    solver = hemishadow.TransferSolver(rest, mesh_io.triangles_of(character.data), bands=1)
    walls = hemishadow.Scene()
    bm = bmesh.new()
    bm.from_mesh(wall.data)
    bmesh.ops.triangulate(bm, faces=bm.faces)
    verts = np.array([v.co[:] for v in bm.verts], np.float32)
    tris = np.array([[v.index for v in f.verts] for f in bm.faces], np.uint32)
    bm.free()
    walls.add_instance(walls.add_mesh(verts, tris), np.array(wall.matrix_world))
    expected = hemishadow.ambient_occlusion(solver.solve(world, casters=walls))
    print(f"AO near {near[facing].mean():.3f} far {far[facing].mean():.3f}; against the engine max {np.abs(near - expected).max():.4f} "
          f"mean {np.abs(near - expected).mean():.5f}")
    assert np.abs(near - expected).max() < 0.05 and np.abs(near - expected).mean() < 0.005
