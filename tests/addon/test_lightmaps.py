"""addon/lightmaps.py: lightmaps of Blender objects (issue 11), through the engine part.

The add-on module is imported from the repository without registering it (as test_world.py
does); the scene is built with bpy.
"""

import math
import pathlib
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import hemishadow.lightmap as lm  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from addon import lightmaps, world  # noqa: E402
from lightmap_scenes import plane, white_world  # noqa: E402


@pytest.fixture
def scene():
    return white_world(world)


def test_open_plane_under_a_white_world(scene, tmp_path):
    floor = plane()
    paths = lightmaps.bake_lightmaps(scene, [floor], resolution=16, bounces=0, out_dir=str(tmp_path))
    assert paths == {"Floor": str(tmp_path / "Floor.exr")}
    maps = lm.read_exr(paths["Floor"])
    assert np.abs(maps["flat"] - 1).max() < 2e-3  # the World's SH (25 coefficients) of a uniform sky
    for name in ("b0", "b1", "b2"):
        assert np.abs(maps[name] - (1 + 1 / math.sqrt(3)) / 2).max() < 2e-3
    image = bpy.data.images["hemishadow_Floor_flat"]
    assert tuple(image.size) == (16, 16) and image.is_float
    pixels = np.array(image.pixels).reshape(16, 16, 4)
    assert np.abs(pixels[..., :3] - 1).max() < 2e-3


def test_sun_and_a_blocker_cast_a_shadow(scene, tmp_path):
    floor = plane()
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 1.0))  # a blocker, not baked
    bpy.ops.object.light_add(type="SUN", rotation=(0, 0, 0))  # straight down
    sun = bpy.context.active_object
    sun.data.energy = math.pi
    sun.data.angle = 0.0
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    maps = lm.read_exr(lightmaps.bake_lightmaps(scene, [floor], resolution=16, bounces=0,
                                                out_dir=str(tmp_path))["Floor"])
    flat = maps["flat"][..., 0]
    # texel centres at +-(0.125 .. 1.875) m: the cube's shadow covers |x|, |y| < 0.5
    c = ((np.arange(16) + 0.5) / 16 - 0.5) * 4
    shadowed = (np.abs(c)[:, None] < 0.45) & (np.abs(c)[None, :] < 0.45)
    lit = (np.abs(c)[:, None] > 0.6) | (np.abs(c)[None, :] > 0.6)
    assert flat[shadowed].max() < 1e-3 and np.abs(flat[lit] - 1).max() < 1e-3


def test_missing_uv_map_names_the_object(scene):
    floor = plane(uv=None)
    with pytest.raises(ValueError, match="Floor: no UV map named 'lightmap'"):
        lightmaps.bake_lightmaps(scene, [floor], resolution=8, images=False)


def test_user_mesh_is_unchanged(scene, tmp_path):
    floor = plane()
    before = (len(floor.data.uv_layers), len(floor.data.vertices), [tuple(v.co) for v in floor.data.vertices])
    lightmaps.bake_lightmaps(scene, [floor], resolution=8, bounces=1, out_dir=str(tmp_path))
    assert (len(floor.data.uv_layers), len(floor.data.vertices), [tuple(v.co) for v in floor.data.vertices]) == before


def test_operator_bakes_the_selected_objects(scene, tmp_path):
    import addon

    addon.register()
    try:
        floor = plane()
        floor.select_set(True)
        bpy.context.view_layer.objects.active = floor
        assert bpy.ops.hemishadow.make_lightmap_uv() == {"FINISHED"}  # has one: left as it is
        assert [u.name for u in floor.data.uv_layers] == ["UVMap", "lightmap"]
        result = bpy.ops.hemishadow.bake_lightmaps(resolution=8, bounces=0, directory=str(tmp_path))
        assert result == {"FINISHED"}
        assert (tmp_path / "Floor.exr").is_file()
        assert np.abs(lm.read_exr(tmp_path / "Floor.exr")["flat"] - 1).max() < 2e-3
    finally:
        addon.unregister()


def test_command_line(scene, tmp_path, capsys):
    from addon import cli

    plane()
    plane("Bare", uv=None)
    assert cli.main(["lightmaps", "--objects", "Floor", "--resolution", "8", "--bounces", "0", "--basis", "sh",
                     "--out", str(tmp_path)]) == 0
    maps = lm.read_exr(tmp_path / "Floor.exr")
    assert set(maps) == {"flat", "sh0", "sh1", "sh2", "sh3", "ao", "coverage"}
    assert np.abs(maps["flat"] - 1).max() < 2e-3
    assert cli.main(["lightmaps", "--objects", "Nope", "--out", str(tmp_path)]) == 2
    assert cli.main(["lightmaps", "--objects", "Bare", "--out", str(tmp_path)]) == 1
    assert "Bare: no UV map named 'lightmap'" in capsys.readouterr().err
    assert cli.main(["lightmaps", "--resolution", "0", "--objects", "Floor", "--out", str(tmp_path)]) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Floor.exr"]  # nothing else written


def test_command_line_samples_adaptively_unless_uniform(scene, tmp_path, monkeypatch):
    from addon import cli

    plane()
    seen = []
    engine_bake = lm.bake
    monkeypatch.setattr(lm, "bake", lambda *a, **k: seen.append(k["adaptive"]) or engine_bake(*a, **k))
    for extra in ([], ["--uniform"]):
        assert cli.main(["lightmaps", "--objects", "Floor", "--resolution", "8", "--bounces", "0", "--samples", "9",
                         "--out", str(tmp_path), *extra]) == 0
    assert seen == [True, False]


def test_lightmap_node_group_combines_like_source(scene, tmp_path):
    """A plane emitting the group's output, rendered by Cycles from above: w_i =
    saturate(dot(n, b_i))^2, sum w_i map_i / sum w_i, for a tilted normal-map colour."""
    from addon import lightmap_nodes

    floor = plane(size=2.0)
    mat = bpy.data.materials.new("Show")
    floor.data.materials.append(mat)
    if mat.node_tree is None:  # Blender before 5.0
        mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    group = tree.nodes.new("ShaderNodeGroup")
    group.node_tree = lightmap_nodes.lightmap_group()
    n = np.array([0.3, -0.2, 0.9])
    n /= np.linalg.norm(n)
    group.inputs["Normal Color"].default_value = (*((n + 1) / 2), 1.0)
    colours = [(0.9, 0.1, 0.1), (0.1, 0.8, 0.2), (0.2, 0.3, 0.7)]
    for i, c in enumerate(colours):
        group.inputs[f"b{i}"].default_value = (*c, 1.0)
    emission = tree.nodes.new("ShaderNodeEmission")
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(group.outputs["Lightmap"], emission.inputs["Color"])
    tree.links.new(emission.outputs[0], out.inputs["Surface"])
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    bpy.ops.object.camera_add(location=(0, 0, 3))
    scene.camera = bpy.context.active_object
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 1
    scene.render.resolution_x = scene.render.resolution_y = 8
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = str(tmp_path / "show.exr")
    bpy.ops.render.render(write_still=True)
    from hemishadow.environment import read_exr

    pixel = read_exr(tmp_path / "show.exr")[4, 4]
    w = np.maximum(lm.HL2 @ n, 0) ** 2
    expected = (w[:, None] * np.array(colours)).sum(0) / w.sum()
    # Cycles' film adds about 1 % here (a grey 0.5 plane comes out 0.497..0.500); unsquared
    # weights (0.527, 0.284, 0.324) or another basis order would be 10 % off or more
    assert np.abs(pixel - expected).max() < 0.015, (pixel, expected)


@pytest.mark.parametrize("method", ["LIGHTMAP", "SMART"])
def test_make_lightmap_uv_adds_a_new_map_only(scene, method):
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    cube = bpy.context.active_object
    mesh = cube.data
    before = np.empty(len(mesh.loops) * 2, np.float32)
    mesh.uv_layers["UVMap"].uv.foreach_get("vector", before)
    assert lightmaps.make_lightmap_uv(cube, method=method) == "lightmap"
    assert [u.name for u in mesh.uv_layers] == ["UVMap", "lightmap"]
    assert mesh.uv_layers.active.name == "UVMap" and mesh.uv_layers["UVMap"].active_render
    after = np.empty_like(before)
    mesh.uv_layers["UVMap"].uv.foreach_get("vector", after)
    assert np.array_equal(before, after)
    new = np.empty_like(before)
    mesh.uv_layers["lightmap"].uv.foreach_get("vector", new)
    assert new.min() >= 0 and new.max() <= 1 and np.ptp(new) > 0.5
    with pytest.raises(ValueError, match="exists already"):
        lightmaps.make_lightmap_uv(cube, method=method)
    # and it bakes: islands that do not overlap; with no folder (unsaved .blend) the images are packed
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        maps = lightmaps.bake_lightmaps(scene, [cube], resolution=32, bounces=0)
    assert maps == {"Cube": None}
    image = bpy.data.images["hemishadow_Cube_flat"]
    assert image.packed_file is not None and image.is_float
