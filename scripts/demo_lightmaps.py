"""The lightmap demo (issue 11): a room corner with a box, lit by one of Blender's HDRIs and a
sun, baked to directional lightmaps headless through the installed add-on, then rendered by
Cycles twice: path traced (the reference) and from the lightmaps alone (the add-on's
"Add to Materials": Emission = Base Color x the "Hemishadow Lightmap" group).

    .venv/bin/python scripts/demo_lightmaps.py            # `make demo-lightmaps`
    .venv/bin/python scripts/demo_lightmaps.py --source   # this checkout's add-on, no zip

Steps, all through the add-on's operators, as a user would click them:
1. installs the extension zip into a project-local user folder (as scripts/demo_blender.py);
2. builds the scene: floor 4 x 4 m, two walls 2.5 m high, a 1 m box turned 25 degrees, each
   with a material of its own; World = Blender's HDRI (Environment Texture), a sun;
3. Make Lightmap UVs (a NEW UV map `lightmap`), Bake Lightmaps (texel density, HL2 basis,
   2 bounces) into out/demo_lightmaps/lightmaps/<object>.exr;
4. renders out/demo_lightmaps/reference.png (Cycles, the scene's own materials and lights),
   then Add to Materials and out/demo_lightmaps/lightmapped.png (Cycles, lightmaps only),
   and out/demo_lightmaps/side_by_side.png (both), and saves demo_lightmaps.blend.
"""

import math
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "scripts"))
import demo_blender  # noqa: E402  (installing the zip, render settings)


def parse_args(argv=None):
    parser = demo_blender.demo_parser(__doc__, "demo_lightmaps")
    parser.add_argument("--hdri", default="forest", help="one of Blender's built-in HDRIs (default forest)")
    parser.add_argument("--density", type=float, default=20.0, help="lightmap texels per metre (default 20)")
    parser.add_argument("--bounces", type=int, default=2, help="diffuse bounces (default 2)")
    parser.add_argument("--resolution", type=int, nargs=2, default=(480, 360), metavar=("X", "Y"))
    parser.add_argument("--samples", type=int, default=32, help="Cycles samples of the reference (default 32)")
    return parser.parse_args(argv)


def material(name, colour):
    import bpy

    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # Blender < 5.0
        mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
    bsdf.inputs["Roughness"].default_value = 1.0
    bsdf.inputs["Specular IOR Level"].default_value = 0.0  # diffuse only, as the bake assumes
    return mat


def build_scene(hdri):
    import bpy
    from hemishadow.environment import builtin_hdris

    bpy.ops.wm.read_homefile(use_empty=True)  # (factory settings would disable the extension)
    scene = bpy.context.scene
    parts = []

    def add(obj, name, colour):
        obj.name = name
        obj.data.materials.append(material(name, colour))
        parts.append(obj)

    bpy.ops.mesh.primitive_plane_add(size=4.0)
    add(bpy.context.object, "Floor", (0.55, 0.50, 0.45))
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0, 2.0, 1.25), rotation=(math.pi / 2, 0, 0))
    bpy.context.object.scale = (4.0, 2.5, 1.0)
    add(bpy.context.object, "BackWall", (0.80, 0.78, 0.74))
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(-2.0, 0, 1.25), rotation=(math.pi / 2, 0, math.pi / 2))
    bpy.context.object.scale = (4.0, 2.5, 1.0)
    add(bpy.context.object, "SideWall", (0.70, 0.78, 0.85))
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(-0.4, 0.6, 0.5), rotation=(0, 0, math.radians(25)))
    add(bpy.context.object, "Box", (0.85, 0.40, 0.20))

    world = bpy.data.worlds.new(hdri.title())
    scene.world = world
    if world.node_tree is None:
        world.use_nodes = True
    nodes = world.node_tree.nodes
    environment = nodes.new("ShaderNodeTexEnvironment")
    environment.image = bpy.data.images.load(str(builtin_hdris()[hdri]))
    world.node_tree.links.new(environment.outputs["Color"], nodes["Background"].inputs["Color"])

    bpy.ops.object.light_add(type="SUN", rotation=(math.radians(53), 0, math.radians(108)))
    sun = bpy.context.object
    sun.data.energy, sun.data.angle = 6.0, math.radians(2.0)

    bpy.ops.object.camera_add(location=(3.4, -3.6, 2.6))
    camera = bpy.context.object
    camera.data.lens = 28
    target = bpy.data.objects.new("Target", None)
    scene.collection.objects.link(target)
    target.location = (-0.6, 0.6, 0.7)
    constraint = camera.constraints.new("TRACK_TO")
    constraint.target = target
    constraint.track_axis, constraint.up_axis = "TRACK_NEGATIVE_Z", "UP_Y"
    scene.camera = camera
    return scene, parts


def select(objects):
    import bpy

    bpy.ops.object.select_all(action="DESELECT")
    for obj in objects:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = objects[0]


def render(scene, path, samples):
    import bpy

    scene.cycles.samples = samples
    scene.render.filepath = str(path)
    t0 = time.perf_counter()
    with demo_blender.quiet_stdout():
        bpy.ops.render.render(write_still=True)
    return time.perf_counter() - t0


def side_by_side(left, right, path):
    import bpy

    images = [bpy.data.images.load(str(p)) for p in (left, right)]
    w, h = images[0].size
    pixels = [np.array(i.pixels[:], np.float32).reshape(h, w, 4) for i in images]
    gap = np.ones((h, 8, 4), np.float32)
    both = np.concatenate([pixels[0], gap, pixels[1]], axis=1)
    out = bpy.data.images.new("side_by_side", both.shape[1], h)
    out.pixels.foreach_set(both.ravel())
    out.filepath_raw, out.file_format = str(path), "PNG"
    out.save()


def main(argv=None):
    args = parse_args(argv)
    out = pathlib.Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    user, site = demo_blender.prepare_user_resources(args.user_resources)
    import bpy

    demo_blender.use_addon(args.source, args.zip, site)
    scene, parts = build_scene(args.hdri)
    bpy.ops.wm.save_as_mainfile(filepath=str(out / "demo_lightmaps.blend"))
    demo_blender.setup_render(scene, args.resolution, args.samples)
    scene.view_settings.exposure = -2.0

    select(parts)
    settings = scene.hemishadow_lightmaps
    settings.size_mode, settings.texel_density = "DENSITY", args.density
    settings.basis, settings.bounces, settings.samples = "hl2", args.bounces, 4
    settings.layout = "OBJECT"  # an image per object, as docs/lightmaps.md shows them
    settings.directory = str(out / "lightmaps")
    assert bpy.ops.hemishadow.make_lightmap_uv(method="SMART") == {"FINISHED"}
    t0 = time.perf_counter()
    assert bpy.ops.hemishadow.bake_lightmaps() == {"FINISHED"}
    baked = time.perf_counter() - t0
    sizes = {o.name: bpy.data.images[f"hemishadow_{o.name}_flat"].size[0] for o in parts}
    print(f"baked lightmaps ({', '.join(f'{k} {v}x{v}' for k, v in sizes.items())}; HL2 basis, "
          f"{args.bounces} bounces) in {baked:.1f} s -> {settings.directory}")

    reference = out / "reference.png"
    print(f"reference (Cycles, {args.samples} samples): {render(scene, reference, args.samples):.1f} s")
    assert bpy.ops.hemishadow.add_lightmap_nodes() == {"FINISHED"}
    lightmapped = out / "lightmapped.png"
    # the materials now only emit (lamps and World light nothing): a few samples suffice
    print(f"lightmapped (Cycles, emission only, 4 samples): {render(scene, lightmapped, 4):.1f} s")
    side_by_side(reference, lightmapped, out / "side_by_side.png")
    bpy.ops.wm.save_mainfile()
    print(f"wrote {reference}, {lightmapped}, {out / 'side_by_side.png'} and {out / 'demo_lightmaps.blend'}")


if __name__ == "__main__":
    main()
