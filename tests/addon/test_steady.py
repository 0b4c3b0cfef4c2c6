"""Subdivided objects whose stack cannot move them (addon/steady.py): their first evaluated
positions are kept instead of read again, because reading makes Blender subdivide them.

The reference is Blender's own evaluated mesh, read directly: after every change of what the
positions depend on (the mesh, the subdivision's settings, creases, the modifiers, shape
keys), each reader of the add-on must give exactly its first vertices.
"""

import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import hemishadow  # noqa: E402
import mathutils  # noqa: E402

from conftest import ROOT  # noqa: E402

sys.path.insert(0, str(ROOT))
from addon import engine_bridge, mesh_io, staleness, steady  # noqa: E402
from layers import attribute  # noqa: E402
from test_casters import casters_collection, ground, world_vertices  # noqa: E402


def collider(scene, location=(0.0, 0.0, 0.0)):
    """Suzanne with Collision above a Subdivision Surface (level 1, not on the limit surface, so
    that the level moves her first vertices): Blender evaluates her at every frame."""
    bpy.ops.mesh.primitive_monkey_add(location=location)
    monkey = bpy.context.object
    monkey.modifiers.new("Collision", "COLLISION")
    subdivision = monkey.modifiers.new("Subdivision", "SUBSURF")
    subdivision.levels, subdivision.use_limit_surface = 1, False
    return monkey


def count_reads(monkeypatch):
    """Names of the objects whose evaluated mesh steady.first_positions had to read."""
    reads, original = [], steady.first_positions

    def spy(obj, depsgraph, read):
        def counted():
            reads.append(obj.name)
            return read()

        return original(obj, depsgraph, counted)

    monkeypatch.setattr(steady, "first_positions", spy)
    return reads


def blender_first(obj):
    """Blender's first V evaluated positions, in world space."""
    obj_eval = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    return mesh_io.to_world(mesh_io.positions_of(obj_eval.data, len(obj.data.vertices)), obj_eval.matrix_world)


def used_first(obj):
    """What the live path and the cache check use, both in world space."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live, _, _ = mesh_io.read_evaluated(obj, depsgraph)
    return live, staleness.evaluated_positions(obj, depsgraph)


def _crease(obj, name, domain, count):
    attribute = obj.data.attributes.get(name) or obj.data.attributes.new(name, "FLOAT", domain)
    values = np.zeros(len(attribute.data), np.float32)
    values[:count] = 1.0
    attribute.data.foreach_set("value", values)
    obj.data.update()


def _move_vertex(obj):
    obj.data.vertices[0].co.z += 0.2
    obj.data.update()


def _shape_key(obj):
    obj.shape_key_add(name="Basis")
    key = obj.shape_key_add(name="Up")
    key.data[0].co.z += 0.2
    key.value = 1.0


def _animate_mesh(obj):
    obj.data.vertices[0].co.z += 0.2
    obj.data.vertices[0].keyframe_insert("co", frame=1)
    obj.data.update()


EDITS = {
    "a vertex moved": _move_vertex,
    "level 2": lambda obj: setattr(obj.modifiers["Subdivision"], "levels", 2),
    "on the limit surface": lambda obj: setattr(obj.modifiers["Subdivision"], "use_limit_surface", True),
    "simple subdivision": lambda obj: setattr(obj.modifiers["Subdivision"], "subdivision_type", "SIMPLE"),
    "edges creased": lambda obj: _crease(obj, "crease_edge", "EDGE", 200),
    "vertices creased": lambda obj: _crease(obj, "crease_vert", "POINT", 100),
    "subdivision off": lambda obj: setattr(obj.modifiers["Subdivision"], "show_viewport", False),
    "displaced after it": lambda obj: setattr(obj.modifiers.new("Displace", "DISPLACE"), "strength", 0.3),
    "a shape key": _shape_key,
    "keyframed vertices": _animate_mesh,
}


@pytest.mark.parametrize("edit", list(EDITS))
def test_every_change_of_what_the_positions_depend_on_is_read(scene, edit):
    monkey = collider(scene)
    before = blender_first(monkey)
    for positions in used_first(monkey):
        np.testing.assert_array_equal(positions, before)
    EDITS[edit](monkey)
    after = blender_first(monkey)
    assert np.abs(after - before).max() > 1e-3, "the edit moves the first vertices (else this tests nothing)"
    for positions in used_first(monkey):
        np.testing.assert_array_equal(positions, after)


def test_an_edit_blender_has_not_evaluated_yet_is_not_kept_once_it_has(scene):
    """`foreach_set` without `update()` leaves Blender's evaluated mesh as it was (Blender 4.2;
    5.x tags the mesh by itself): the add-on must then give what Blender shows, and after the
    update the new positions, not what it read while Blender lagged."""
    monkey = collider(scene)
    before = blender_first(monkey)
    co = np.empty(len(monkey.data.vertices) * 3, np.float32)
    monkey.data.vertices.foreach_get("co", co)
    co[2] += 0.2
    monkey.data.vertices.foreach_set("co", co)
    shown = blender_first(monkey)
    for positions in used_first(monkey):
        np.testing.assert_array_equal(positions, shown)
    monkey.data.update()
    after = blender_first(monkey)
    assert np.abs(after - before).max() > 1e-3
    for positions in used_first(monkey):
        np.testing.assert_array_equal(positions, after)


def test_a_subdivided_collider_is_read_once_while_a_caster_moves(scene, monkeypatch):
    """A static subdivided receiver shadowed by a moving cube, and a caster itself: Blender
    evaluates it every frame (Collision), the add-on reads it once and still shades it as a
    forced read of every frame does."""
    monkey = collider(scene, location=(0.0, 0.0, 0.5))
    monkey.hemishadow.enabled = True
    plane = ground(scene)
    bpy.ops.mesh.primitive_cube_add(size=0.4, location=(-1.0, 0.0, 1.4))
    block = bpy.context.object
    block.keyframe_insert("location", frame=1)
    block.location.x = 1.0
    block.keyframe_insert("location", frame=5)
    casters_collection(scene, [monkey, plane, block])
    reads = count_reads(monkeypatch)
    shading = []
    for frame in range(1, 6):
        scene.frame_set(frame)
        engine_bridge.compute_now(scene, bpy.context.evaluated_depsgraph_get())
        shading.append(attribute(monkey, mesh_io.AO))
    assert reads.count(monkey.name) == 1, reads
    assert np.abs(shading[0] - shading[-1]).max() > 0.02, "the cube's shadow moved over her"
    steady.forget()  # the reference: a fresh read of her evaluated mesh
    engine_bridge.forget()
    engine_bridge.compute_now(scene, bpy.context.evaluated_depsgraph_get())
    assert reads.count(monkey.name) == 2
    np.testing.assert_allclose(attribute(monkey, mesh_io.AO), shading[-1], atol=1e-6)


def test_a_subdivided_caster_follows_an_edit_of_its_mesh(scene):
    """The caster's scene takes the edited mesh: the plane's shadow is the engine's Scene of
    Blender's first evaluated vertices, before and after the monkey's mesh is moved."""
    plane = ground(scene, segments=16)
    monkey = collider(scene, location=(0.0, 0.0, 0.9))
    casters_collection(scene, [plane, monkey])
    shadows = []
    for shift in (0.0, 0.6):
        monkey.data.transform(mathutils.Matrix.Translation((shift, 0.0, 0.0)))
        monkey.data.update()
        engine_bridge.compute_now(scene, bpy.context.evaluated_depsgraph_get())
        shadows.append(attribute(plane, mesh_io.AO))
        reference = hemishadow.Scene()
        first = blender_first(monkey)
        reference.add_instance(reference.add_mesh(first, mesh_io.triangles_of(monkey.data)), np.eye(4))
        points = world_vertices(plane)
        expected = reference.ambient_occlusion(points, np.tile((0.0, 0.0, 1.0), (len(points), 1)))
        assert np.abs(shadows[-1] - expected).max() < 0.02 and np.abs(shadows[-1] - expected).mean() < 0.005
    assert np.abs(shadows[0] - shadows[1]).max() > 0.1, "the shadow moved with the mesh"


def test_nothing_is_kept_of_a_deleted_object(scene):
    monkey = collider(scene)
    uid = monkey.session_uid
    used_first(monkey)
    assert uid in steady._known
    bpy.data.objects.remove(monkey)
    engine_bridge.prune()
    assert uid not in steady._known
