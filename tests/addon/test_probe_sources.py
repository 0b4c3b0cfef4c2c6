"""The light sources of a probe bake from Blender (issue 12): point, spot and area lamps as
the lightmap bake reads them, and the bounce light of surfaces with baked lightmaps taken
from those lightmaps (addon/probe_lightmaps.py) instead of computed again."""

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import hemishadow  # noqa: E402


def dark_scene(addon):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.world.clear_cache()
    scene = bpy.context.scene
    scene.world = bpy.data.worlds.new("World")
    if bpy.app.version < (5, 0):  # 5.x always uses nodes (use_nodes deprecated)
        scene.world.use_nodes = True
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    return scene


def test_point_spot_and_area_lamps_light_the_probes(addon):
    """A point lamp (red) and a spot above a floor, an area lamp facing a probe: each probe's
    sides as the inverse square law of the lamp's intensity (Blender's power x colour), the
    spot's cone and the area lamp's cosine included (1 %)."""
    scene = dark_scene(addon)
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    bpy.ops.object.light_add(type="POINT", location=(0.0, 0.0, 2.0))
    point = bpy.context.active_object.data
    point.energy, point.color, point.shadow_soft_size = 200.0, (1.0, 0.5, 0.25), 0.0
    bpy.ops.object.light_add(type="SPOT", location=(3.0, 0.0, 2.0))  # points down (-Z), 45 degree cone
    spot = bpy.context.active_object.data
    spot.energy, spot.spot_size, spot.spot_blend, spot.shadow_soft_size = 100.0, math.radians(45), 0.0, 0.0
    bpy.ops.object.light_add(type="AREA", location=(-3.0, 0.0, 1.0), rotation=(0.0, math.radians(-90), 0.0))
    area = bpy.context.active_object.data  # faces +X (its local -Z)
    area.energy, area.size = 50.0, 0.05
    points = np.array([[0.5, 0.3, 1.0], [3.0, 0.0, 0.5], [-1.0, 0.0, 1.0]])
    result, _ = addon.probes.bake_probes(scene, points=points, bounces=0, store=False)

    def delta(intensity, lamp, p):
        to = np.asarray(lamp) - p
        cosines = np.maximum(hemishadow.probes.AXES @ (to / np.linalg.norm(to)), 0)
        return np.outer(cosines, intensity) / (to @ to) / math.pi

    def area_light(p):  # a small Lambertian emitter: P / pi W/sr along its normal (+X), times the cosine
        to = p - np.array([-3.0, 0.0, 1.0])
        return delta(np.full(3, 50.0 / math.pi * to[0] / np.linalg.norm(to)), (-3, 0, 1), p)

    red = 200.0 * np.array([1.0, 0.5, 0.25]) / (4 * math.pi)
    spot_i = np.full(3, 100.0 / (4 * math.pi))
    expected = [delta(red, (0, 0, 2), p) + area_light(p) for p in points]
    expected[1] += delta(spot_i, (3, 0, 2), points[1])  # the others are outside the spot's cone
    for k in range(3):
        err = np.abs(result["cube"][k] - expected[k]).max() / expected[k].max()
        assert err < 0.01, (k, err, result["cube"][k], expected[k])


def lit_wall(addon):
    """A 4 m floor and a 2 m wall at x = 1 facing -X, 12 x 12 grids with the unit square as
    their `lightmap` UVs, lit by a sun from the -X side 45 degrees up; no World."""
    scene = dark_scene(addon)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=12, y_subdivisions=12, size=4.0)
    floor = bpy.context.active_object
    floor.name = "Floor"
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=12, y_subdivisions=12, size=2.0, location=(1.0, 0.0, 1.0),
                                    rotation=(0.0, math.radians(-90), 0.0))
    wall = bpy.context.active_object
    wall.name = "Wall"
    for obj in (floor, wall):
        obj.data.uv_layers.new(name="lightmap")
    bpy.ops.object.light_add(type="SUN", rotation=(0.0, math.radians(-45), 0.0))
    bpy.context.active_object.data.energy = 3.0
    bpy.context.view_layer.update()
    return scene, floor, wall


PROBES = np.array([[0.7, 0.0, 0.8], [0.4, 0.5, 0.4], [0.8, -0.6, 1.4]])  # 0.2 to 0.6 m from the wall


def bounce_of(addon, scene):
    """The bounce part of the probes' sides (1 bounce minus direct only), and the result."""
    direct, _ = addon.probes.bake_probes(scene, points=PROBES, bounces=0, store=False)
    lit, _ = addon.probes.bake_probes(scene, points=PROBES, bounces=1, store=False)
    return lit["cube"] - direct["cube"], lit


def test_bounce_from_baked_lightmaps_matches_the_computed_bounce(addon):
    """The same bounce light both ways: computed at the vertices, and read from the floor's
    and wall's lightmaps (baked direct only, 32 texels) at their vertices; worst side within
    5 % of the probe's brightest bounce side (3.3 % measured: texels against vertex samples
    where the wall's shadow edge crosses the floor). The lightmap path is the one taken: the
    notes say so, doubling the lightmaps doubles the bounce, and with the floor's lightmap
    gone and the wall's black, the floor is computed again and the wall sends nothing."""
    scene, floor, wall = lit_wall(addon)
    computed, plain = bounce_of(addon, scene)
    assert plain["lightmapped"] == [] and computed.max() > 0.05
    # One atlas (the default for several objects, read through hemishadow_lightmap), then
    # per-object maps (their own images, through `lightmap`): the newer bake is the one read.
    for layout in ("ATLAS", "OBJECT"):
        addon.lightmaps.bake_lightmaps(scene, [floor, wall], resolution=32, bounces=0, layout=layout)
        from_maps, lit = bounce_of(addon, scene)
        assert len(lit["lightmapped"]) == 2, layout
        assert any("bounce light from the baked lightmaps of 2 object" in n for n in lit["notes"])
        err = (np.abs(from_maps - computed).max(axis=(1, 2)) / computed.max(axis=(1, 2)))
        print(f"bounce, {layout} lightmaps against computed, per probe: {np.round(100 * err, 2).tolist()} %")
        assert err.max() < 0.05, (layout, err)
    for image in [i for i in bpy.data.images if i.name.startswith("hemishadow_atlas_")]:
        bpy.data.images.remove(image)  # from here on, the per-object maps alone

    for name in ("Wall", "Floor"):
        scale_image(f"hemishadow_{name}_flat", 2.0)
    doubled, _ = bounce_of(addon, scene)
    np.testing.assert_allclose(doubled, 2 * from_maps, rtol=1e-3, atol=1e-6)

    scale_image("hemishadow_Wall_flat", 0.0)  # a black wall: its lightmap, not the computed one
    bpy.data.images.remove(bpy.data.images["hemishadow_Floor_flat"])  # the floor: computed again
    mixed, lit = bounce_of(addon, scene)
    assert lit["lightmapped"] == [m for m in plain_ids(addon, scene, "Wall")]
    print("+X (facing the wall), -Z (facing the floor), mixed / computed:",
          (mixed[:, 0, 0] / computed[:, 0, 0]).round(3), (mixed[:, 5, 0] / computed[:, 5, 0]).round(3))
    assert (mixed[:, 0] < 0.5 * computed[:, 0]).all()
    assert (mixed[:, 5] > 0.4 * computed[:, 5]).all()  # the floor still lit (0.52 to 0.91)


def test_lightmaps_written_to_files_only_are_read_from_their_exr(addon, tmp_path):
    """Lightmaps baked without Blender images (files only, into the Lightmaps settings'
    folder): the probes read the EXR files' `flat` layers, the same bounce as computed."""
    scene, floor, wall = lit_wall(addon)
    computed, _ = bounce_of(addon, scene)
    scene.hemishadow_lightmaps.directory = str(tmp_path)
    addon.lightmaps.bake_lightmaps(scene, [floor, wall], resolution=32, bounces=0, out_dir=str(tmp_path),
                                   images=False, layout="OBJECT")  # an atlas's file names no object
    assert not [i for i in bpy.data.images if i.name.startswith("hemishadow_")]
    from_files, lit = bounce_of(addon, scene)
    assert len(lit["lightmapped"]) == 2
    err = np.abs(from_files - computed).max(axis=(1, 2)) / computed.max(axis=(1, 2))
    assert err.max() < 0.05, err


def scale_image(name, factor):
    image = bpy.data.images[name]
    pixels = np.empty(len(image.pixels), np.float32)
    image.pixels.foreach_get(pixels)
    pixels.reshape(-1, 4)[:, :3] *= factor
    image.pixels.foreach_set(pixels)


def plain_ids(addon, scene, name):
    """The engine mesh ids of the object `name` in the probe bake's scene."""
    _, surfaces, _ = addon.probes.scene_geometry(scene)
    return [s.mesh_id for s in surfaces if s.name == name]


def test_probe_lightmap_reading_follows_the_uv_and_image_rows(addon):
    """`baked.vertex_light` reads a map bilinearly at the corners' UVs, rows top to bottom,
    averaged per vertex."""
    flat = np.zeros((4, 4, 3), np.float32)
    flat[0, :, 0] = 1.0  # the top row: v near 1
    uv = np.array([[[0.5, 0.875], [0.5, 0.125], [0.125, 0.5]]])
    out = hemishadow.probes.baked.vertex_light(flat, uv, np.array([[0, 1, 2]]), 4)
    np.testing.assert_allclose(out[:, 0], [1.0, 0.0, 0.0, 0.0], atol=1e-6)
