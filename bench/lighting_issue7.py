"""Issue 7, cases 4-6: before/after numbers of the add-on's lighting, for any checkout.

    .venv/bin/python bench/lighting_issue7.py [ROOT]     (ROOT: the checkout to measure, default this one)

Case 4: relative L2 error of the lighting SH of Worlds without an Environment Texture against
their exact expansion. Case 5: a white plane lit by one lamp (black World), computed by the
add-on (`engine_bridge.update_scene`) at the vertices, against a Cycles render whose pixel
centres they are: largest difference over the brightest pixel (a pixel averages what a vertex
samples, which shows at a spot's cone edge). Case 6: a static object under keyframed lighting: the radiance at frame 5
over frame 1, against what the lighting says.
"""

import math
import pathlib
import sys
import tempfile
import types

ROOT = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else pathlib.Path(__file__).resolve().parents[1]).resolve()
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402
import hemishadow  # noqa: E402
from hemishadow.environment import read_exr  # noqa: E402

import addon  # noqa: E402
from addon import engine_bridge, mesh_io, world  # noqa: E402
from test_sh import equirect_directions  # noqa: E402


def fresh_world():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    w = bpy.data.worlds.new("w")
    scene.world = w
    return scene, w.node_tree.nodes, w.node_tree.links


def case4():
    settings = types.SimpleNamespace(**dict(world.DEFAULTS, use_sun_lamps=False))
    out = {}
    scene, nodes, links = fresh_world()
    nodes["Background"].inputs["Color"].default_value = (0.2, 0.4, 0.6, 1)
    want = np.zeros((25, 3))
    want[0] = math.sqrt(4 * math.pi) * np.array([0.2, 0.4, 0.6])
    out["plain colour"] = (world.scene_lighting(scene, 5, settings), want)
    scene, nodes, links = fresh_world()
    coords, dot, add = nodes.new("ShaderNodeTexCoord"), nodes.new("ShaderNodeVectorMath"), nodes.new("ShaderNodeMath")
    dot.operation = "DOT_PRODUCT"
    dot.inputs[1].default_value = (0.3, -0.2, 0.6)
    add.inputs[1].default_value = 1.0
    links.new(coords.outputs["Generated"], dot.inputs[0])
    links.new(dot.outputs["Value"], add.inputs[0])
    links.new(add.outputs[0], nodes["Background"].inputs["Color"])
    d = equirect_directions(256, 512)
    gradient = np.repeat((1 + d @ np.array([0.3, -0.2, 0.6]))[..., None], 3, axis=2)
    out["gradient (nodes)"] = (world.scene_lighting(scene, 5, settings), hemishadow.project_environment(gradient, 5))
    scene, nodes, links = fresh_world()
    first, second = nodes["Background"], nodes.new("ShaderNodeBackground")
    first.inputs["Color"].default_value = (1, 0, 0, 1)
    second.inputs["Color"].default_value = (0, 0, 1, 1)
    second.inputs["Strength"].default_value = 2.0
    mix = nodes.new("ShaderNodeMixShader")
    mix.inputs["Fac"].default_value = 0.25
    links.new(first.outputs[0], mix.inputs[1])
    links.new(second.outputs[0], mix.inputs[2])
    links.new(mix.outputs[0], nodes["World Output"].inputs["Surface"])
    want = np.zeros((25, 3))
    want[0] = math.sqrt(4 * math.pi) * np.array([0.75, 0.0, 0.5])
    out["mix of two Backgrounds"] = (world.scene_lighting(scene, 5, settings), want)
    for name, (got, expected) in out.items():
        print(f"case 4, {name}: relative L2 error {np.linalg.norm(got - expected) / np.linalg.norm(expected):.4f}")


PIXELS, HALF = 64, 3.0

LAMPS = {
    "point": ("POINT", (0.3, -0.2, 1.0), (0, 0, 0), dict(energy=100.0, shadow_soft_size=0.1)),
    "spot": ("SPOT", (0.5, 0.0, 1.5), (0.3, 0.0, 0.0), dict(energy=300.0, spot_size=math.radians(60), spot_blend=0.4)),
    "area": ("AREA", (0.0, 0.4, 1.0), (0.4, 0.2, 0.0), dict(energy=100.0, shape="RECTANGLE", size=1.0, size_y=0.5)),
}


def lit_plane(kind, location, rotation, settings):
    """A plane whose vertices are the pixel centres of a 64 x 64 orthographic camera."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()
    scene = bpy.context.scene
    scene.world = bpy.data.worlds.new("black")
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.hemishadow.lighting_source = "UNIFORM"
    scene.hemishadow.uniform_color = (0, 0, 0)
    c = (np.arange(PIXELS) + 0.5) / PIXELS * 2 * HALF - HALF
    x, y = np.meshgrid(c, c[::-1])
    verts = np.stack([x, y, np.zeros_like(x)], -1).reshape(-1, 3)
    index = np.arange(PIXELS * PIXELS).reshape(PIXELS, PIXELS)
    faces = np.stack([index[1:, :-1], index[1:, 1:], index[:-1, 1:], index[:-1, :-1]], -1).reshape(-1, 4)
    mesh = bpy.data.meshes.new("plane")
    mesh.from_pydata(verts.tolist(), [], faces.tolist())
    plane = bpy.data.objects.new("plane", mesh)
    scene.collection.objects.link(plane)
    plane.hemishadow.enabled = True
    plane.hemishadow.albedo = (1, 1, 1)
    data = bpy.data.lights.new(kind.lower(), kind)
    for name, value in settings.items():
        setattr(data, name, value)
    lamp = bpy.data.objects.new(kind.lower(), data)
    lamp.location, lamp.rotation_euler = location, rotation
    scene.collection.objects.link(lamp)
    bpy.context.view_layer.update()
    return scene, plane


def cycles_render(scene, plane):
    scene.render.engine = "CYCLES"
    scene.cycles.device, scene.cycles.samples = "CPU", 16
    scene.cycles.use_denoising = scene.cycles.use_adaptive_sampling = False
    scene.cycles.pixel_filter_type, scene.cycles.filter_width = "BOX", 1.0
    scene.render.resolution_x = scene.render.resolution_y = PIXELS
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "OPEN_EXR"
    material = bpy.data.materials.new("white")
    diffuse = material.node_tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (1, 1, 1, 1)
    material.node_tree.links.new(diffuse.outputs[0], material.node_tree.nodes["Material Output"].inputs["Surface"])
    plane.data.materials.append(material)
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    camera.data.type, camera.data.ortho_scale = "ORTHO", 2 * HALF
    camera.location = (0, 0, 5)
    scene.collection.objects.link(camera)
    scene.camera = camera
    path = pathlib.Path(tempfile.mkdtemp()) / "plane.exr"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    return read_exr(path)[..., 0].ravel()


def radiance(obj):
    attr = obj.data.attributes[mesh_io.RADIANCE]
    out = np.empty(len(attr.data) * 4, np.float32)
    attr.data.foreach_get("color", out)
    return out.reshape(-1, 4)[:, 0]


def case5():
    for name, (kind, location, rotation, settings) in LAMPS.items():
        scene, plane = lit_plane(kind, location, rotation, settings)
        engine_bridge.update_scene(scene, bpy.context.evaluated_depsgraph_get(), force=True)
        computed = radiance(plane)
        shown = cycles_render(scene, plane)
        print(f"case 5, {name} lamp: largest |add-on - Cycles| / brightest pixel "
              f"{np.abs(computed - shown).max() / shown.max():.3f}")
        addon.unregister()


def case6():
    for name in ("World strength 1 -> 3", "sun strength 2 -> 5"):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        addon.register()
        scene = bpy.context.scene
        scene.hemishadow.lighting_source = "UNIFORM" if name.startswith("sun") else "WORLD"
        scene.hemishadow.uniform_color = (0, 0, 0)
        if name.startswith("World"):
            scene.world = bpy.data.worlds.new("sky")
            value, keys = scene.world.node_tree.nodes["Background"].inputs["Strength"], (1.0, 3.0)
            path = "default_value"
        else:
            scene.world = None
            sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
            scene.collection.objects.link(sun)
            value, keys, path = sun.data, (2.0, 5.0), "energy"
        for frame, key in zip((1, 5), keys):
            setattr(value, path, key)
            value.keyframe_insert(path, frame=frame)
        mesh = bpy.data.meshes.new("ground")
        mesh.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [], [(0, 1, 2, 3)])
        ground = bpy.data.objects.new("ground", mesh)
        scene.collection.objects.link(ground)
        ground.hemishadow.enabled = True
        scene.frame_set(1)
        scene.hemishadow.live = True
        scene.frame_set(1)
        first = radiance(ground).mean()
        scene.frame_set(5)
        print(f"case 6, keyframed {name}: radiance frame 5 / frame 1 = {radiance(ground).mean() / first:.3f} "
              f"(lighting says {keys[1] / keys[0]:.3f})")
        addon.unregister()


if __name__ == "__main__":
    print(f"measuring {ROOT}")
    case4()
    case5()
    case6()
