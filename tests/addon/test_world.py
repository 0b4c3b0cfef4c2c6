"""addon/world.py: the lighting SH of a scene (World, built-in HDRIs, uniform sky, sun lamps).

world.py is imported from the repository's `addon` package without registering it, with
settings passed as a plain namespace, so these tests need neither the installed extension nor
its properties.
"""

import math
import pathlib
import sys
import types

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import hemishadow  # noqa: E402
from hemishadow.environment import builtin_hdris, read_exr, write_exr  # noqa: E402
from mathutils import Vector  # noqa: E402  (comes with bpy)

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from addon import world  # noqa: E402

FOREST = builtin_hdris()["forest"]


def settings(**overrides):
    values = dict(world.DEFAULTS, use_sun_lamps=False)
    values.update(overrides)
    return types.SimpleNamespace(**values)


@pytest.fixture
def scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    world.clear_cache()
    return bpy.context.scene


def environment_world(scene, image, rotation=None, strength=1.0, mapping_type="POINT", reroute=False):
    """World: [Texture Coordinate -> Mapping ->] Environment Texture -> Background."""
    w = bpy.data.worlds.new("env")
    scene.world = w
    if bpy.app.version < (5, 0):  # before 5.0 a new World has no node tree until asked
        w.use_nodes = True
    nodes, links = w.node_tree.nodes, w.node_tree.links
    env = nodes.new("ShaderNodeTexEnvironment")
    env.image = image
    background = nodes["Background"]
    background.inputs["Strength"].default_value = strength
    if reroute:
        middle = nodes.new("NodeReroute")
        links.new(env.outputs["Color"], middle.inputs[0])
        links.new(middle.outputs[0], background.inputs["Color"])
    else:
        links.new(env.outputs["Color"], background.inputs["Color"])
    if rotation is not None:
        coords = nodes.new("ShaderNodeTexCoord")
        mapping = nodes.new("ShaderNodeMapping")
        mapping.vector_type = mapping_type
        mapping.inputs["Rotation"].default_value = rotation
        links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
        links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    return w


def unoccluded_transfer(normal, bands):
    """Transfer vectors of a lone triangle facing `normal`: nothing blocks its vertices."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    u = np.cross(n, [1, 0, 0] if abs(n[0]) < 0.9 else [0, 1, 0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    vertices = np.array([u, v, -u - v], np.float32)
    return hemishadow.transfer(vertices, [[0, 1, 2]], np.tile(n, (3, 1)).astype(np.float32), bands=bands)


# ---------------------------------------------------------------------------------------
# World Environment Texture


def test_world_environment_matches_engine_projection(scene):
    environment_world(scene, bpy.data.images.load(str(FOREST)))
    source = world.lighting_source(scene, settings())
    assert source.kind == "WORLD" and source.path == str(FOREST)
    lighting = world.scene_lighting(scene, 5, settings())
    assert lighting.dtype == np.float32 and lighting.shape == (25, 3)
    np.testing.assert_allclose(lighting, hemishadow.project_environment(FOREST, 5), rtol=1e-5, atol=1e-6)


def test_mapping_rotation_rotates_the_result(scene):
    rotation = (0.3, -0.2, 1.1)
    environment_world(scene, bpy.data.images.load(str(FOREST)), rotation=rotation)
    lighting = world.scene_lighting(scene, 4, settings())
    expected = hemishadow.project_environment(FOREST, 4, rotation=rotation)
    np.testing.assert_allclose(lighting, expected, rtol=1e-5, atol=1e-6)
    assert not np.allclose(lighting, hemishadow.project_environment(FOREST, 4), atol=1e-2)
    # the same function turned: the rotated projection is the rotation of the projection
    turned = hemishadow.rotate_sh(hemishadow.project_environment(FOREST, 4), hemishadow.euler_to_matrix(rotation).T)
    np.testing.assert_allclose(lighting, turned, atol=2e-3 * np.abs(lighting).max())


def test_texture_mapping_rotates_the_other_way(scene):
    rotation = (0.0, 0.4, -0.9)
    environment_world(scene, bpy.data.images.load(str(FOREST)), rotation=rotation, mapping_type="TEXTURE")
    lighting = world.scene_lighting(scene, 3, settings())
    inverse = hemishadow.euler_to_matrix(rotation).T
    np.testing.assert_allclose(lighting, hemishadow.project_environment(FOREST, 3, rotation=inverse),
                               rtol=1e-5, atol=1e-6)


def test_background_strength_scales(scene):
    image = bpy.data.images.load(str(FOREST))
    environment_world(scene, image, strength=2.5, reroute=True)
    np.testing.assert_allclose(world.scene_lighting(scene, 3, settings()),
                               2.5 * hemishadow.project_environment(FOREST, 3), rtol=1e-5, atol=1e-6)


def test_strength_and_rotation_agree_with_cycles(scene, tmp_path):
    """End to end: Cycles shows the radiance the SH predict along a few directions.

    The environment is a known band-limited (9-coefficient) expansion, so its projection is
    exact and any mismatch is a mapping, rotation or strength error.
    """
    sys.path.insert(0, str(ROOT / "tests"))
    from test_environment_blender import probe_camera, radiance_along
    from test_sh import equirect_directions  # the mapping Cycles was checked against

    rng = np.random.default_rng(11)
    truth = rng.normal(size=(9, 3)) * 0.3
    truth[0] = 4.0
    h, w = 128, 256
    image = (hemishadow.sh_basis(equirect_directions(h, w).reshape(-1, 3), 3) @ truth).reshape(h, w, 3)
    path = tmp_path / "env.exr"
    write_exr(path, {"": image})
    environment_world(scene, bpy.data.images.load(str(path)), rotation=(0.5, 0.1, -0.8), strength=1.5)
    lighting = world.scene_lighting(scene, 3, settings())

    camera = probe_camera(scene)
    for direction in [(1, 0, 0), (-0.3, 0.5, 0.8)]:
        d = np.array(direction, float) / np.linalg.norm(direction)
        shown = radiance_along(scene, camera, d, tmp_path)
        expected = hemishadow.sh_basis([d], 3)[0] @ lighting
        assert shown == pytest.approx(expected, rel=0.01, abs=0.03), direction


# ---------------------------------------------------------------------------------------
# Images read through their pixels (packed, generated): rows run bottom-up in Blender


def test_packed_image_matches_its_file(scene):
    image = bpy.data.images.load(str(FOREST))
    image.pack()
    environment_world(scene, image)
    source = world.lighting_source(scene, settings())
    assert source.path is None  # read through image.pixels
    np.testing.assert_allclose(world.scene_lighting(scene, 5, settings()),
                               hemishadow.project_environment(FOREST, 5), rtol=1e-4, atol=1e-5)


def test_generated_image_rows_are_bottom_up(scene):
    h, w = 32, 64
    top_first = np.zeros((h, w, 4), np.float32)
    top_first[: h // 4, :, :3] = 1.0  # a bright sky cap in the image's top rows
    top_first[..., 3] = 1.0
    image = bpy.data.images.new("sky", w, h, float_buffer=True)
    image.pixels.foreach_set(top_first[::-1].ravel())  # Blender's buffer starts at the bottom row
    environment_world(scene, image)
    lighting = world.scene_lighting(scene, 3, settings())
    np.testing.assert_allclose(lighting, hemishadow.project_environment(top_first, 3), rtol=1e-5, atol=1e-6)
    assert lighting[2, 0] > 0.1  # Y_10 ~ z: the light comes from above


def test_byte_image_is_decoded_from_srgb(scene):
    image = bpy.data.images.new("grey", 256, 128)  # 8-bit, sRGB
    image.pixels.foreach_set(np.full(256 * 128 * 4, 0.5, np.float32))
    environment_world(scene, image)
    lighting = world.scene_lighting(scene, 3, settings())
    stored = round(0.5 * 255) / 255  # what an 8-bit buffer keeps
    linear = ((stored + 0.055) / 1.055) ** 2.4
    np.testing.assert_allclose(lighting[0], linear * math.sqrt(4 * math.pi), rtol=2e-3)
    np.testing.assert_allclose(lighting[1:], 0, atol=1e-4)


# ---------------------------------------------------------------------------------------
# Fallbacks and scene settings


def test_no_world_falls_back_to_the_builtin_hdri_and_says_so(scene):
    scene.world = None
    chosen = settings(hdri="city")
    source = world.lighting_source(scene, chosen)
    assert source.kind == "BUILTIN" and "no World" in source.label
    np.testing.assert_allclose(world.scene_lighting(scene, 3, chosen),
                               hemishadow.project_environment(builtin_hdris()["city"], 3), rtol=1e-5, atol=1e-6)
    assert any("no World" in m for m in world.notes(scene))  # for the status bar and reports


def test_builtin_source_ignores_the_world(scene):
    environment_world(scene, bpy.data.images.load(str(FOREST)))
    chosen = settings(lighting_source="BUILTIN", hdri="studio")
    np.testing.assert_allclose(world.scene_lighting(scene, 3, chosen),
                               hemishadow.project_environment(builtin_hdris()["studio"], 3), rtol=1e-5, atol=1e-6)


def test_uniform_sky_lights_an_open_surface_with_pi_times_its_radiance(scene):
    color = (0.2, 0.5, 1.0)
    lighting = world.scene_lighting(scene, 5, settings(lighting_source="UNIFORM", uniform_color=color, intensity=2.0))
    assert np.count_nonzero(lighting[1:]) == 0
    irradiance = hemishadow.shade(unoccluded_transfer((0.3, -0.4, 0.8), 5), lighting)
    np.testing.assert_allclose(irradiance, np.tile(2.0 * math.pi * np.array(color), (3, 1)), rtol=0.01)


def test_intensity_and_rotation_about_z(scene):
    environment_world(scene, bpy.data.images.load(str(FOREST)))
    base = world.scene_lighting(scene, 4, settings())
    turned = world.scene_lighting(scene, 4, settings(intensity=3.0, rotation=math.pi / 2))
    np.testing.assert_allclose(turned, 3.0 * hemishadow.rotate_sh(base, hemishadow.rotation_matrix((0, 0, 1), math.pi / 2)),
                               rtol=1e-4, atol=1e-4)
    # counter-clockwise seen from above: what arrived from +X now arrives from +Y
    x, y = hemishadow.sh_basis([[1, 0, 0.2], [0, 1, 0.2]], 4)
    np.testing.assert_allclose(y @ turned, 3.0 * (x @ base), rtol=1e-3)


def test_projection_is_cached(scene, monkeypatch):
    environment_world(scene, bpy.data.images.load(str(FOREST)), rotation=(0, 0, 0.3))
    calls = []
    project = hemishadow.project_environment
    monkeypatch.setattr(hemishadow, "project_environment", lambda *a, **k: calls.append(a) or project(*a, **k))
    first = world.scene_lighting(scene, 5, settings())
    again = world.scene_lighting(scene, 5, settings(intensity=2.0, rotation=0.4))
    assert len(calls) == 1
    np.testing.assert_allclose(again, 2 * hemishadow.rotate_sh(first, hemishadow.rotation_matrix((0, 0, 1), 0.4)),
                               rtol=1e-4, atol=1e-4)
    world.scene_lighting(scene, 3, settings())  # another band count: projected again
    scene.world.node_tree.nodes["Mapping"].inputs["Rotation"].default_value[2] = 0.5
    world.scene_lighting(scene, 5, settings())  # another Mapping rotation: projected again
    assert len(calls) == 3


# ---------------------------------------------------------------------------------------
# Sun lamps


def sun(scene, direction, strength, angle, color=(1, 1, 1)):
    """A sun lamp shining from `direction` (its -Z axis points the other way)."""
    data = bpy.data.lights.new("sun", "SUN")
    data.energy = strength
    data.angle = angle
    data.color = color
    obj = bpy.data.objects.new("sun", data)
    scene.collection.objects.link(obj)
    obj.rotation_mode = "QUATERNION"
    obj.rotation_quaternion = Vector(direction).to_track_quat("Z", "Y")
    bpy.context.view_layer.update()
    return obj


# Band-limited clamped cosine at 0 degrees, sum_l (2l+1)/(4pi) A_l: what truncation leaves of E.
FACING_FACTOR = {3: 1.0625, 4: 1.0625, 5: 0.96875}


@pytest.mark.parametrize("angle_degrees", [0.0, 0.526, 2.0, 10.0])
def test_sun_irradiance_on_a_surface_facing_it(scene, angle_degrees):
    direction = np.array([0.4, -0.3, 0.7])
    strength = 3.0
    sun(scene, direction, strength, math.radians(angle_degrees), color=(1.0, 0.5, 0.25))
    lighting = world.scene_lighting(scene, 5, settings(lighting_source="UNIFORM", uniform_color=(0, 0, 0),
                                                      use_sun_lamps=True))
    irradiance = hemishadow.shade(unoccluded_transfer(direction, 5), lighting)
    expected = strength * np.array([1.0, 0.5, 0.25])
    np.testing.assert_allclose(irradiance, np.tile(expected, (3, 1)), rtol=0.04)  # within a few %
    # and exactly what the truncated series predicts (transfer integration error only)
    np.testing.assert_allclose(irradiance, np.tile(expected * FACING_FACTOR[5], (3, 1)), rtol=0.01)


@pytest.mark.parametrize("bands", [3, 4, 5])
def test_sun_lobe_truncation_factor(bands):
    lighting = world.sun_lobe([0, 0, 1], np.full(3, 2.0), 0.0, bands)
    irradiance = hemishadow.shade(unoccluded_transfer([0, 0, 1], bands), lighting.astype(np.float32))
    np.testing.assert_allclose(irradiance[:, 0], 2.0 * FACING_FACTOR[bands], rtol=0.01)


@pytest.mark.parametrize("angle_degrees", [5.0, 40.0, 120.0, 180.0])
def test_sun_lobe_is_the_projection_of_a_uniform_cap(angle_degrees):
    """The closed form against Monte-Carlo-free quadrature over the cap itself."""
    direction = np.array([-0.2, 0.6, 0.5])
    direction /= np.linalg.norm(direction)
    half = math.radians(angle_degrees) / 2
    # a fine grid over the cap around +Z (equal-area in cos t), turned to `direction`
    k, m = 400, 360
    cos_t = 1 - (1 - math.cos(half)) * (np.arange(k) + 0.5) / k
    phi = 2 * math.pi * (np.arange(m) + 0.5) / m
    sin_t = np.sqrt(1 - cos_t**2)
    local = np.stack(np.broadcast_arrays(sin_t[:, None] * np.cos(phi), sin_t[:, None] * np.sin(phi),
                                         cos_t[:, None]), axis=-1).reshape(-1, 3)
    z = direction
    x = np.cross(z, [1, 0, 0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    directions = local @ np.stack([x, y, z])
    area = 2 * math.pi * (1 - math.cos(half))
    radiance = 1.0 / (math.pi * math.sin(half) ** 2)  # E = 1
    expected = radiance * area * hemishadow.sh_basis(directions, 5).astype(np.float64).mean(axis=0)
    np.testing.assert_allclose(world.sun_lobe(direction, 1.0, math.radians(angle_degrees), 5)[:, 0], expected,
                               atol=2e-4 * np.abs(expected).max())


def test_sun_lamps_follow_their_settings(scene):
    default = sun(scene, (0, 0, 1), 2.0, 0.0)
    default.rotation_quaternion = (1, 0, 0, 0)  # Blender's default: shining straight down
    hidden = sun(scene, (1, 0, 0), 5.0, 0.0)
    hidden.hide_render = True
    bpy.context.view_layer.update()
    dark = dict(lighting_source="UNIFORM", uniform_color=(0, 0, 0))
    lighting = world.scene_lighting(scene, 3, settings(use_sun_lamps=True, intensity=7.0, rotation=1.0, **dark))
    np.testing.assert_allclose(lighting, world.sun_lobe([0, 0, 1], 2.0 * np.ones(3), 0.0, 3), rtol=1e-5, atol=1e-6)
    assert lighting[2, 0] > 0  # from above
    assert not world.scene_lighting(scene, 3, settings(use_sun_lamps=False, **dark)).any()


def test_sun_strength_is_the_irradiance_cycles_shows(scene, tmp_path):
    """A white diffuse plane (normal +Z) under a sun 30 degrees off its normal, black world:
    Cycles shows radiance E cos(30) / pi, and the sun's SH lobe predicts the same irradiance."""
    scene.world = bpy.data.worlds.new("black")
    if bpy.app.version < (5, 0):
        scene.world.use_nodes = True
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 16
    scene.cycles.use_denoising = False
    scene.render.resolution_x = scene.render.resolution_y = 4
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "OPEN_EXR"
    mesh = bpy.data.meshes.new("plane")
    mesh.from_pydata([(-5, -5, 0), (5, -5, 0), (5, 5, 0), (-5, 5, 0)], [], [(0, 1, 2, 3)])
    plane = bpy.data.objects.new("plane", mesh)
    scene.collection.objects.link(plane)
    material = bpy.data.materials.new("white")
    if bpy.app.version < (5, 0):
        material.use_nodes = True
    diffuse = material.node_tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (1, 1, 1, 1)
    material.node_tree.links.new(diffuse.outputs[0], material.node_tree.nodes["Material Output"].inputs["Surface"])
    mesh.materials.append(material)
    camera = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    camera.location = (0, 0, 5)
    camera.data.lens = 500.0
    scene.collection.objects.link(camera)
    scene.camera = camera
    direction = np.array([math.sin(math.radians(30)), 0.0, math.cos(math.radians(30))])
    strength = 3.0
    sun(scene, direction, strength, math.radians(10.0))
    scene.render.filepath = str(tmp_path / "sun.exr")
    bpy.ops.render.render(write_still=True)
    shown = read_exr(tmp_path / "sun.exr").reshape(-1, 3).mean(axis=0) * math.pi  # irradiance
    assert shown == pytest.approx(np.full(3, strength * math.cos(math.radians(30))), rel=0.01)

    lighting = world.scene_lighting(scene, 5, settings(lighting_source="UNIFORM", uniform_color=(0, 0, 0),
                                                      use_sun_lamps=True))
    predicted = hemishadow.shade(unoccluded_transfer([0, 0, 1], 5), lighting)
    np.testing.assert_allclose(predicted, np.tile(shown, (3, 1)), rtol=0.03)
