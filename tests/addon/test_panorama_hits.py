"""addon/panorama_hits.py (issue 13): primary visibility of a panorama from Cycles' data passes,
against the engine's own `primary_hits` of the same scene, pixel for pixel away from
silhouette edges; the mapping (centre column +X, left quarter +Y, top row +Z); nothing left
behind."""

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import hemishadow.panorama as hp  # noqa: E402

SIZE = (96, 48)


def _material(name, rgb):
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0):  # 5.x always uses nodes (use_nodes deprecated)
        mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*rgb, 1.0)
    return mat


def _box(name, location, scale, rgb):
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=location)
    obj = bpy.context.active_object
    obj.name, obj.scale = name, scale
    obj.data.materials.append(_material(name, rgb))
    return obj


@pytest.fixture
def boxes(addon):
    """Flat-shaded boxes on a floor, one on each axis seen from (0, 0, 1)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    _box("Floor", (0, 0, -0.05), (12, 12, 0.1), (0.5, 0.5, 0.5))
    _box("AlongX", (3, 0, 1), (1, 2, 2), (0.8, 0.1, 0.1))
    _box("AlongY", (0, 3, 1), (2, 1, 2), (0.1, 0.8, 0.1))
    _box("Above", (0, 0, 4), (2, 2, 0.5), (0.1, 0.1, 0.8))
    bpy.context.view_layer.update()
    return scene


@pytest.fixture
def panorama_hits(addon):
    from addon import panorama_hits

    return panorama_hits


def _edges(object_id):
    """Pixels with a differently-labelled neighbour (3 x 3, wrapping around in longitude)."""
    edge = np.zeros(object_id.shape, bool)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            shifted = np.roll(object_id, dc, axis=1)
            shifted = np.roll(shifted, dr, axis=0)
            if dr == -1:
                shifted[-1] = object_id[-1]
            if dr == 1:
                shifted[0] = object_id[0]
            edge |= shifted != object_id
    return edge


def test_cycles_hits_match_the_engine_away_from_edges(boxes, panorama_hits):
    origin = np.array([0.0, 0.0, 1.0])
    hits, engine_scene, surfaces = panorama_hits.hits(boxes, origin, np.eye(3), SIZE)
    ref = hp.primary_hits(engine_scene, origin, size=SIZE)
    names = [s.name for s in surfaces]
    inner = ~(_edges(ref.object_id) | _edges(hits.object_id))
    assert inner.sum() > 0.6 * inner.size
    assert np.array_equal(hits.mask[inner], ref.mask[inner])
    assert np.array_equal(hits.object_id[inner], ref.object_id[inner])
    on = inner & ref.mask
    depth = np.linalg.norm(ref.position[on] - origin, axis=1)
    assert np.abs(hits.position[on] - ref.position[on]).max(axis=1).max() < 1e-3 * depth.max()
    assert (hits.shading_normal[on] * ref.shading_normal[on]).sum(axis=1).min() > 0.9999
    assert (hits.geometric_normal[on] * ref.geometric_normal[on]).sum(axis=1).min() > 0.9999
    # Blender's BVH, which gives the geometric normal where the engine's ray sees another object
    from addon import probes

    world = probes.scene_geometry(boxes, live=True)[2]
    bvh = panorama_hits.geometric_normals(world, origin, hits.position[on].astype(np.float64))
    assert (bvh * ref.geometric_normal[on]).sum(axis=1).min() > 0.9999
    # Diffuse Color gives the Principled BSDF's Base Color (metallic 0, no transmission)
    for i, name in enumerate(names):
        base = np.array(bpy.data.materials[name].node_tree.nodes["Principled BSDF"].inputs["Base Color"]
                        .default_value[:3])
        seen = hits.albedo[on & (hits.object_id == i)]
        assert len(seen) and np.abs(seen - base).max() < 1e-4, name


def test_mapping_centre_x_left_quarter_y_top_z(boxes, panorama_hits):
    hits, _, surfaces = panorama_hits.hits(boxes, np.array([0.0, 0.0, 1.0]), np.eye(3), SIZE)
    names = [s.name for s in surfaces]
    w, h = SIZE
    assert names[hits.object_id[h // 2, w // 2]] == "AlongX"
    assert names[hits.object_id[h // 2, w // 4]] == "AlongY"
    assert (hits.object_id[0] == names.index("Above")).all()
    assert (hits.object_id[-1] == names.index("Floor")).all()
    assert not hits.mask[h // 2, 3 * w // 4]  # -Y: open sky past the floor's edge at the horizon


def test_a_camera_gives_its_own_frame(boxes, panorama_hits):
    bpy.ops.object.camera_add(location=(0, 0, 1), rotation=(math.radians(90), 0, math.radians(0)))
    camera = bpy.context.active_object  # turned by +90 degrees about Z from the identity frame
    origin, rotation = panorama_hits.viewpoint(boxes, camera.name)
    assert np.allclose(origin, (0, 0, 1)) and np.allclose(rotation @ [1, 0, 0], [0, 1, 0], atol=1e-6)
    hits, _, surfaces = panorama_hits.hits(boxes, origin, rotation, SIZE)
    assert surfaces[hits.object_id[SIZE[1] // 2, SIZE[0] // 2]].name == "AlongY"


def _specular():
    return [m.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value for m in bpy.data.materials]


def test_nothing_is_left_behind(boxes, panorama_hits):
    scene = boxes
    before = (scene.render.engine, scene.render.resolution_x, scene.render.resolution_y,
              scene.render.image_settings.file_format, scene.camera, scene.cycles.samples,
              scene.cycles.filter_width, scene.view_layers[0].use_pass_position, len(bpy.data.objects),
              len(bpy.data.cameras), [o.pass_index for o in scene.objects], _specular())
    panorama_hits.hits(scene, np.array([0.0, 0.0, 1.0]), np.eye(3), SIZE)
    after = (scene.render.engine, scene.render.resolution_x, scene.render.resolution_y,
             scene.render.image_settings.file_format, scene.camera, scene.cycles.samples,
             scene.cycles.filter_width, scene.view_layers[0].use_pass_position, len(bpy.data.objects),
             len(bpy.data.cameras), [o.pass_index for o in scene.objects], _specular())
    assert before == after and before[-1] == [0.5] * 4


def test_viewpoint_inside_a_mesh_and_empty_scene(boxes, panorama_hits):
    with pytest.raises(ValueError, match="AlongX: the viewpoint .* is inside it"):
        panorama_hits.hits(boxes, np.array([3.0, 0.0, 1.0]), np.eye(3), SIZE)
    for obj in list(boxes.objects):
        bpy.data.objects.remove(obj)
    with pytest.raises(ValueError, match="no visible, renderable mesh to bake a panorama of"):
        panorama_hits.hits(boxes, np.array([0.0, 0.0, 1.0]), np.eye(3), SIZE)
