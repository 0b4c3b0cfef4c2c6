"""addon/probes.py, its operators and `--command hemishadow probes` (issue 12), on scenes
built with bpy: a floor and a wall under a white World of strength 1."""

import json

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import hemishadow.probes as hp  # noqa: E402


@pytest.fixture
def room(addon):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.world.clear_cache()
    scene = bpy.context.scene
    scene.world = bpy.data.worlds.new("World")
    if bpy.app.version < (5, 0):  # 5.x always uses nodes (use_nodes deprecated)
        scene.world.use_nodes = True
    background = scene.world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (1, 1, 1, 1)
    background.inputs["Strength"].default_value = 1.0
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    bpy.context.active_object.name = "Floor"
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(2.0, 0.0, 1.0))
    wall = bpy.context.active_object
    wall.name, wall.scale = "Wall", (0.2, 4.0, 2.0)
    bpy.ops.object.add(type="LIGHT_PROBE")
    volume = bpy.context.active_object
    if volume.data.type != "VOLUME":
        volume.data = bpy.data.lightprobes.new("Volume", "VOLUME")
    volume.name = "Volume"
    volume.location, volume.scale = (0.0, 0.0, 1.5), (1.5, 1.0, 1.0)
    volume.rotation_euler = (0.0, 0.0, 0.2)
    volume.data.resolution_x, volume.data.resolution_y, volume.data.resolution_z = 3, 2, 2
    bpy.context.view_layer.update()
    return scene


def test_grid_is_where_blender_puts_the_samples(room, addon):
    volume = room.objects["Volume"]
    matrix, res = addon.probes.grid_of(volume)
    pts = hp.grid_points(matrix, res)
    mw = np.array(volume.matrix_world)
    local = np.array([[(i + 1) / 4 * 2 - 1, (j + 1) / 3 * 2 - 1, (k + 1) / 3 * 2 - 1]
                      for i in range(3) for j in range(2) for k in range(2)])
    assert np.allclose(pts, local @ mw[:3, :3].T + mw[:3, 3])


def test_command_line_bakes_a_volume(room, addon, tmp_path, capsys):
    out = tmp_path / "grid.npz"
    assert addon.cli.main(["probes", "--volume", "Volume", "--bounces", "0", "--out", str(out)]) == 0
    assert "12 probes" in capsys.readouterr().out
    data = hp.read_npz(out)
    assert data["cube"].shape == (12, 6, 3) and data["sh9"].shape == (12, 9, 3) and data["valid"].all()
    assert np.array_equal(data["grid_resolution"], [3, 2, 2])
    # white World of strength 1: 1.0 facing up under an open sky; the 2 m wall hides up to 8 % of it
    up = data["cube"][:, 4, 0]
    assert up.max() < 1 + 1e-4 and up.min() > 0.9 and (up > 0.999).sum() >= 3
    assert (data["cube"][:, 5] < 0.15).all()  # a black 8 m floor below (no bounce): sky only past its edge
    assert (data["cube"][:, 0, 0] < data["cube"][:, 1, 0]).all()  # +X faces the wall
    meta = json.loads((tmp_path / "grid.json").read_text())
    assert meta["count"] == 12 and np.allclose(meta["cube"], data["cube"])


def test_command_line_points_and_bad_input(room, addon, tmp_path, capsys):
    pts = tmp_path / "p.npy"
    np.save(pts, np.array([[0.0, 0.0, 1.0], [1.0, 0.5, 0.5]]))
    out = tmp_path / "p.npz"
    assert addon.cli.main(["probes", "--points", str(pts), "--out", str(out), "--bounces", "1"]) == 0
    assert hp.read_npz(out)["cube"].shape == (2, 6, 3)
    assert addon.cli.main(["probes", "--volume", "Nope", "--out", str(out)]) == 2
    assert "no Light Probe Volume or Empty named 'Nope'" in capsys.readouterr().err
    for obj in [o for o in room.objects if o.type == "MESH"]:
        bpy.data.objects.remove(obj)
    assert addon.cli.main(["probes", "--volume", "Volume", "--out", str(out)]) == 1
    assert "no visible, renderable mesh" in capsys.readouterr().err


def test_operator_stores_and_previews(room, addon, tmp_path):
    volume = room.objects["Volume"]
    bpy.context.view_layer.objects.active = volume
    assert bpy.ops.hemishadow.bake_probes(bounces=0, filepath=str(tmp_path / "v.npz")) == {"FINISHED"}
    kept = addon.probes.stored(volume)
    assert kept["cube"].shape == (12, 6, 3) and np.allclose(kept["cube"], hp.read_npz(tmp_path / "v.npz")["cube"])
    assert bpy.ops.hemishadow.probe_preview() == {"FINISHED"}
    preview = bpy.data.objects["hemishadow_probes_Volume"]
    colours = np.empty(len(preview.data.loops) * 4, np.float32)
    preview.data.color_attributes["hemishadow_probe"].data.foreach_get("color", colours)
    assert colours.reshape(-1, 4)[:, :3].max() > 0.9 and preview.hide_render
    assert bpy.ops.hemishadow.probe_preview() == {"FINISHED"}  # a toggle
    assert "hemishadow_probes_Volume" not in bpy.data.objects
    # the preview is not baked as a blocker, and objects with hemishadow enabled are left out
    names = {s.name for s in addon.probes.scene_geometry(room)[1]}
    assert names == {"Floor", "Wall"}
    room.objects["Wall"].hemishadow.enabled = True
    assert {s.name for s in addon.probes.scene_geometry(room)[1]} == {"Floor"}


def test_lighting_at_a_point_from_the_stored_grid(room, addon, tmp_path):
    """What a live object would take: SH9 at a point, between the stored probes; its
    irradiance facing up is the interpolated +Z side."""
    volume = room.objects["Volume"]
    addon.probes.bake_probes(room, volume, bounces=0, out=str(tmp_path / "v.npz"))
    _, _, world = addon.probes.scene_geometry(room)
    point = np.array(volume.matrix_world.translation)
    sh9 = addon.probes.lighting_at(volume, point, blockers=world)
    data = addon.probes.stored(volume)
    assert sh9.shape == (9, 3)
    expected = hp.evaluate(data, point[None], np.array([[0.0, 0.0, 1.0]]))["cube"][0, 4]
    assert np.allclose(hp.sh_to_cube(sh9)[4], expected, rtol=0.05)
    with pytest.raises(ValueError, match="no baked probes"):
        addon.probes.lighting_at(room.objects["Floor"], point)


def test_empty_far_from_geometry_zero_resolution_and_cancel(room, addon, tmp_path, capsys):
    bpy.ops.object.empty_add(location=(0.0, 0.0, 30.0))
    empty = bpy.context.active_object
    empty.name = "Sky"
    out = tmp_path / "e.npz"
    assert addon.cli.main(["probes", "--volume", "Sky", "--resolution", "2", "2", "1", "--out", str(out)]) == 0
    assert "no geometry inside the volume" in capsys.readouterr().out
    assert hp.read_npz(out)["cube"].shape == (4, 6, 3)
    assert addon.cli.main(["probes", "--volume", "Sky", "--resolution", "0", "2", "2", "--out", str(out)]) == 2
    assert "--resolution must be at least 1" in capsys.readouterr().err
    import hemishadow

    cancelled = tmp_path / "c.npz"
    with pytest.raises(hemishadow.Cancelled):
        addon.probes.bake_probes(room, room.objects["Volume"], out=str(cancelled), progress=lambda f: False)
    assert not cancelled.exists() and addon.probes.stored(room.objects["Volume"]) is None
