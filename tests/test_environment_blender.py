"""The engine's equirectangular mapping is Blender's: checked with a Cycles render.

The environment is a known SH expansion written to an EXR file with the pixel directions of
`test_sh.equirect_directions`. `test_sh` checks that the engine projects that image back onto
its coefficients (so engine mapping == that formula); here Cycles renders the same file
through the World's Environment Texture node along chosen directions, and the radiance it
shows must be the expansion evaluated there (so Blender's mapping == that formula).
"""

import numpy as np
import pytest

import hemishadow
from hemishadow.environment import write_exr
from test_sh import equirect_directions

bpy = pytest.importorskip("bpy")
from mathutils import Vector  # noqa: E402  (comes with bpy)


def probe_camera(scene):
    """Sets `scene` up to show, in a 2x2 EXR, the radiance along one direction: Cycles on
    the CPU, no filter, no view transform, and a camera of about one degree."""
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 4
    scene.cycles.use_denoising = False
    scene.cycles.filter_width = 0.01
    scene.render.resolution_x = scene.render.resolution_y = 2
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "OPEN_EXR"
    camera = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    camera.data.lens = 2000.0  # a ~1 degree field of view: one direction
    scene.collection.objects.link(camera)
    scene.camera = camera
    camera.rotation_mode = "QUATERNION"
    return camera


def radiance_along(scene, camera, direction, tmp_path):
    """The mean radiance Cycles renders with `camera` looking along `direction`."""
    camera.rotation_quaternion = Vector(direction).to_track_quat("-Z", "Y")
    out = tmp_path / "render.exr"
    scene.render.filepath = str(out)
    bpy.ops.render.render(write_still=True)
    return hemishadow.environment.read_exr(out).reshape(-1, 3).mean(axis=0)


def render_radiance(exr_path, direction, rotation=None, tmp_path=None):
    """Radiance Cycles shows along `direction` with `exr_path` as the World's environment."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    camera = probe_camera(scene)
    world = bpy.data.worlds.new("env")
    scene.world = world
    if bpy.app.version < (5, 0):  # 5.x always uses nodes (use_nodes deprecated)
        world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    env = nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(exr_path))
    background = nodes["Background"]
    links.new(env.outputs["Color"], background.inputs["Color"])
    if rotation is not None:
        coords = nodes.new("ShaderNodeTexCoord")
        mapping = nodes.new("ShaderNodeMapping")
        mapping.inputs["Rotation"].default_value = rotation
        links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
        links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    return radiance_along(scene, camera, direction, tmp_path)


DIRECTIONS = [(1, 0, 0), (0, 1, 0), (-1, 0, 0), (0, -1, 0), (0.3, -0.5, 0.8), (-0.6, 0.2, -0.7)]


@pytest.fixture(scope="module")
def environment(tmp_path_factory):
    rng = np.random.default_rng(6)
    truth = rng.normal(size=(9, 3)) * 0.3
    truth[0] = 4.0  # keep the radiance positive
    h, w = 256, 512
    image = (hemishadow.sh_basis(equirect_directions(h, w).reshape(-1, 3), 3) @ truth).reshape(h, w, 3)
    path = tmp_path_factory.mktemp("env") / "env.exr"
    write_exr(path, {"": image})
    return path, truth


@pytest.mark.parametrize("direction", DIRECTIONS)
def test_cycles_shows_the_expansion_along_each_direction(environment, direction, tmp_path):
    path, truth = environment
    d = np.array(direction, float) / np.linalg.norm(direction)
    shown = render_radiance(path, d, tmp_path=tmp_path)
    expected = hemishadow.sh_basis([d], 3)[0] @ truth
    assert shown == pytest.approx(expected, abs=0.02)


def test_mapping_node_rotation_matches_project_environment(environment, tmp_path):
    path, _ = environment
    rotation = (0.3, -0.2, 1.1)
    light = hemishadow.project_environment(path, 3, rotation=rotation)
    for direction in DIRECTIONS[:3]:
        d = np.array(direction, float)
        shown = render_radiance(path, d, rotation=rotation, tmp_path=tmp_path)
        expected = hemishadow.sh_basis([d], 3)[0] @ light
        assert shown == pytest.approx(expected, abs=0.03)
