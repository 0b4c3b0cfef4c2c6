"""Lightmaps against Cycles' Diffuse bake (Direct + Indirect, Color off): a floor with a box
on it under a uniform white World (strength 1) and a sun; the same UV map, resolution,
margin and diffuse bounces. Prints the mean and worst relative error of `flat` over covered
texels brighter than 1 % of the open-sky value, and both times.

    PYTHONPATH=native/python .venv/bin/python bench/lightmap_cycles.py [--resolution 32]
        [--samples 1024] [--bounces 0] [--no-sun] [--cuts N] [--map flat|b0|b1|b2]
        [--scene floor|room|corner] [--lamp none|point|spot|area] [--sweep 16,64,256] [--uniform]
        [--picture PNG] [--repeat 3]

--scene room: a closed 4 x 4 x 2.5 m room with a window in its +X wall, a table and a cabinet
(sky and sun come in through the window); corner: a ground with two walls meeting at a corner
and an overhang. The baked object is the floor (ground) in every scene. --lamp adds a point
(radius 0.1 m), spot (60 degrees, blend 0.3) or area (1 x 0.6 m) lamp under the ceiling
(over the corner). --sweep bakes with Cycles at those sample counts too and compares each
with the reference (--samples), to find Cycles' time at our error.

For a `b_i` map, the floor's material gets a Normal Map node (tangent space, the floor's
render UV map) fed the constant colour (b_i + 1) / 2, with bump-map correction off; only the
floor has it (a material of its own), so compare b_i with --bounces 0.
"""

import argparse
import math
import pathlib
import sys
import tempfile
import time

import bpy
import mathutils
import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from addon import lightmaps, world  # noqa: E402
import hemishadow.lightmap as lm  # noqa: E402


def _box(name, lo, hi, material):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=tuple((lo + hi) / 2))
    obj = bpy.context.active_object
    obj.name = name
    obj.scale = tuple(hi - lo)
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    obj.data.materials.append(material)
    return obj


def _room(material):
    """Walls 0.2 m thick around a 4 x 4 m floor, 2.5 m high; a 1.6 x 1 m window in the +X wall."""
    out = [_box("WallW", (-2.2, -2.2, 0), (-2, 2.2, 2.5), material), _box("WallS", (-2, -2.2, 0), (2, -2, 2.5), material),
           _box("WallN", (-2, 2, 0), (2, 2.2, 2.5), material), _box("Ceiling", (-2.2, -2.2, 2.5), (2.2, 2.2, 2.7), material),
           _box("WallE1", (2, -2.2, 0), (2.2, 2.2, 0.8), material), _box("WallE2", (2, -2.2, 1.8), (2.2, 2.2, 2.5), material),
           _box("WallE3", (2, -2.2, 0.8), (2.2, -0.8, 1.8), material), _box("WallE4", (2, 0.8, 0.8), (2.2, 2.2, 1.8), material),
           _box("TableTop", (-0.8, -0.5, 0.7), (0.4, 0.5, 0.75), material),
           _box("Cabinet", (-1.9, 0.8, 0), (-1.4, 1.9, 1.6), material)]
    for i, (x, y) in enumerate([(-0.75, -0.45), (0.35, -0.45), (-0.75, 0.45), (0.35, 0.45)]):
        out.append(_box(f"Leg{i}", (x - 0.03, y - 0.03, 0), (x + 0.03, y + 0.03, 0.7), material))
    return out


def _corner(material):
    """Two walls meeting at a corner and an overhang over the ground in front of one of them."""
    return [_box("WallA", (-2, 1, 0), (2, 1.2, 2), material), _box("WallB", (-2, -2, 0), (-1.8, 1, 2), material),
            _box("Overhang", (-2, -0.2, 2), (1, 1.2, 2.1), material)]


LAMPS = {  # (type, location, rotation in degrees, settings); rotation (0, 0, 0) points down
    "point": ("POINT", (0.3, -0.6, 2.2), (0, 0, 0), {"energy": 200.0, "shadow_soft_size": 0.1}),
    "spot": ("SPOT", (-0.3, 0.2, 2.3), (20, 0, 0), {"energy": 300.0, "shadow_soft_size": 0.05,
                                                   "spot_size": math.radians(60), "spot_blend": 0.3}),
    "area": ("AREA", (0.0, -0.5, 2.4), (0, 0, 30), {"energy": 150.0, "shape": "RECTANGLE", "size": 1.0, "size_y": 0.6}),
}


def _lamp(kind, corner):
    kind_, location, rotation, settings = LAMPS[kind]
    if corner:
        location = (location[0] - 0.5, location[1] + 0.3, 1.8)
    bpy.ops.object.light_add(type=kind_, location=location, rotation=tuple(math.radians(a) for a in rotation))
    for key, value in settings.items():
        setattr(bpy.context.active_object.data, key, value)


def subdivide(objects, cuts):
    """Every face of each object cut `cuts` times (Edit Mode's Subdivide)."""
    for obj in objects:
        bpy.ops.object.select_all(action="DESELECT")
        obj.select_set(True)
        bpy.context.view_layer.objects.active = obj
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_all(action="SELECT")
        bpy.ops.mesh.subdivide(number_cuts=cuts)
        bpy.ops.object.mode_set(mode="OBJECT")


def build(sun, cuts=0, basis_vector=None, scene_name="floor", lamp="none", sky=1.0):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    world.clear_cache()
    scene = bpy.context.scene
    scene.world = bpy.data.worlds.new("World")
    bg = scene.world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (1, 1, 1, 1)
    bg.inputs["Strength"].default_value = sky
    material = bpy.data.materials.new("Diffuse")
    if material.node_tree is None:  # Blender < 5.0 (5.x deprecates use_nodes: always on)
        material.use_nodes = True
    bsdf = material.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1)
    bsdf.inputs["Roughness"].default_value = 1.0
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    bpy.ops.mesh.primitive_plane_add(size=6.0 if scene_name == "corner" else 4.0)
    floor = bpy.context.active_object
    floor.name = "Floor"
    floor.data.uv_layers.new(name="lightmap")
    floor.data.materials.append(_basis_material(material, basis_vector) if basis_vector is not None else material)
    if scene_name == "floor":
        bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.3, 0.2, 0.5))
        others = [bpy.context.active_object]
        others[0].data.materials.append(material)
    else:
        others = _room(material) if scene_name == "room" else _corner(material)
    if lamp != "none":
        _lamp(lamp, scene_name == "corner")
    if cuts:  # bounce light is carried per vertex: finer meshes carry it better
        subdivide([floor] + others, cuts)
    if sun:
        rotation = (0, math.radians(55), math.radians(10)) if scene_name == "room" else (math.radians(40), 0, math.radians(30))
        bpy.ops.object.light_add(type="SUN", rotation=rotation)
        bpy.context.active_object.data.energy = 3.0
        bpy.context.active_object.data.angle = math.radians(1.0)
    return scene, floor, floor.data.materials[0]


def _basis_material(material, vector):
    """A copy of `material` whose shading normal is `vector` in the tangent frame."""
    mat = material.copy()
    mat.name = "Basis"
    mat.cycles.use_bump_map_correction = False  # on, even an open plane bakes 0.633, not 0.789
    nodes = mat.node_tree.nodes
    normal_map = nodes.new("ShaderNodeNormalMap")
    normal_map.space = "TANGENT"
    normal_map.uv_map = "UVMap"
    normal_map.inputs["Color"].default_value = (*((np.asarray(vector) + 1) / 2), 1.0)
    mat.node_tree.links.new(normal_map.outputs["Normal"], nodes["Principled BSDF"].inputs["Normal"])
    return mat


def cycles_bake(scene, floor, material, resolution, samples, bounces, margin):
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_adaptive_sampling = False  # a sample count, not a noise threshold, sets the time
    scene.cycles.diffuse_bounces = bounces
    scene.cycles.max_bounces = max(bounces, 1)
    scene.render.bake.margin = margin
    image = bpy.data.images.new("cycles_flat", resolution, resolution, float_buffer=True, alpha=False)
    node = material.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = image
    material.node_tree.nodes.active = node
    bpy.ops.object.select_all(action="DESELECT")
    floor.select_set(True)
    bpy.context.view_layer.objects.active = floor
    t0 = time.perf_counter()
    bpy.ops.object.bake(type="DIFFUSE", pass_filter={"DIRECT", "INDIRECT"}, margin=margin, uv_layer="lightmap")
    seconds = time.perf_counter() - t0
    material.node_tree.nodes.remove(node)  # the other objects' shading stays as it was
    pixels = np.array(image.pixels).reshape(resolution, resolution, 4)[::-1, :, :3]
    return pixels.astype(np.float32), seconds


def footprints(floor, resolution):
    """Texels that an object standing on the floor covers, even in part. Cycles bakes each
    texel over its area, so a texel partly under a wall is darkened by the point inside it;
    ours averages the valid part only (receivers inside geometry never leak or darken)."""
    size = floor.dimensions.x
    out = np.zeros((resolution, resolution), bool)
    for obj in bpy.context.scene.objects:
        if obj.type != "MESH" or obj == floor:
            continue
        corners = np.array([obj.matrix_world @ mathutils.Vector(c) for c in obj.bound_box])
        if corners[:, 2].min() > 1e-3:
            continue
        (u0, v0), (u1, v1) = corners[:, :2].min(0) / size + 0.5, corners[:, :2].max(0) / size + 0.5
        cols = np.arange(resolution)
        c = (cols + 1 > u0 * resolution) & (cols < u1 * resolution)
        r = (resolution - cols > v0 * resolution) & (resolution - cols - 1 < v1 * resolution)  # row 0 at v = 1
        out |= r[:, None] & c[None, :]
    return out


def errors(ours, reference, covered, footprint=None):
    """Relative error per texel (mean over RGB) and the texels compared: covered and brighter
    than 1 % of the open-sky value; and those away from texels darker than that and from the
    footprints of objects standing on the floor (`footprints`)."""
    bright = reference[..., 0] > 0.01
    padded = np.pad(bright, 1, constant_values=True)
    clear = np.ones_like(bright)
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            clear &= padded[dy:dy + bright.shape[0], dx:dx + bright.shape[1]]
    if footprint is not None:
        clear &= ~footprint
    relative = np.abs(ours - reference).mean(-1) / np.maximum(reference.mean(-1), 1e-6)
    return relative, covered & bright, covered & clear


def picture(path, reference, ours, relative, covered):
    """Cycles' map and ours side by side at one exposure (the reference's 99th percentile is
    white, sRGB), then the relative error (black 0, white 10 % or more), each texel 4 px."""
    from hemishadow.lightmap.encode import write_png

    white = np.percentile(reference[covered], 99)
    srgb = lambda x: np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(np.maximum(x, 0.0031308), 1 / 2.4) - 0.055)
    shown = [srgb(np.clip(m / white, 0.0, 1.0)) for m in (reference, ours)]
    shown.append(np.repeat(np.clip(np.where(covered, relative, 0.0) / 0.10, 0.0, 1.0)[..., None], 3, axis=2))
    gap = np.ones((reference.shape[0], 2, 3))
    rgb = np.concatenate([shown[0], gap, shown[1], gap, shown[2]], axis=1).repeat(4, axis=0).repeat(4, axis=1)
    rgba = np.concatenate([rgb, np.ones(rgb.shape[:2] + (1,))], axis=2)
    write_png(path, (rgba * 255 + 0.5).astype(np.uint8))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, default=32)
    parser.add_argument("--samples", type=int, default=1024, help="Cycles samples of the reference")
    parser.add_argument("--bounces", type=int, default=0)
    parser.add_argument("--no-sun", action="store_true")
    parser.add_argument("--no-sky", action="store_true", help="World strength 0 (lamps only)")
    parser.add_argument("--cuts", type=int, default=0, help="subdivide every mesh (edge cuts)")
    parser.add_argument("--map", choices=("flat", "b0", "b1", "b2"), default="flat")
    parser.add_argument("--scene", choices=("floor", "room", "corner"), default="floor")
    parser.add_argument("--lamp", choices=("none",) + tuple(LAMPS), default="none")
    parser.add_argument("--ours-samples", type=int, default=4, help="our supersamples per texel")
    parser.add_argument("--uniform", action="store_true", help="ours with every sample in every texel (not adaptive)")
    parser.add_argument("--repeat", type=int, default=7,
                        help="bake ours this many times: the best after the first is timed (the first "
                             "builds one-off tables; Cycles' sweep runs after its reference, warm too); "
                             "bakes of a tenth of a second vary by half between runs, so six are timed")
    parser.add_argument("--sweep", default="", help="Cycles sample counts to time against ours, e.g. 16,64,256")
    parser.add_argument("--picture", default="", help="PNG: Cycles' map, ours, and the relative error (0-10 %%)")
    args = parser.parse_args(argv)
    vector = None if args.map == "flat" else lm.HL2[int(args.map[1])]
    scene, floor, material = build(not args.no_sun, args.cuts, vector, args.scene, args.lamp,
                                   0.0 if args.no_sky else 1.0)
    times = []
    with tempfile.TemporaryDirectory() as folder:
        for _ in range(max(args.repeat, 1)):
            t0 = time.perf_counter()
            ours = lm.read_exr(lightmaps.bake_lightmaps(scene, [floor], resolution=args.resolution,
                                                        basis="flat" if args.map == "flat" else "hl2",
                                                        bounces=args.bounces, samples=args.ours_samples,
                                                        adaptive=not args.uniform, margin=2, out_dir=folder,
                                                        images=False)["Floor"])
            times.append(time.perf_counter() - t0)
    # Cycles' sweep runs after its reference bake, warm; ours after the first, which builds
    # the engine's one-off tables (the plane table, about 0.15 s once per process)
    ours_seconds = min(times[1:]) if len(times) > 1 else times[0]
    reference, cycles_seconds = cycles_bake(scene, floor, material, args.resolution, args.samples, args.bounces, 2)
    covered = ours["coverage"] > 0
    footprint = footprints(floor, args.resolution)
    relative, bright, clear = errors(ours[args.map], reference, covered, footprint)
    print(f"{args.map} vs Cycles ({args.scene}, lamp {args.lamp}, {args.samples} samples, {args.bounces} bounces, "
          f"sun={not args.no_sun}, sky={not args.no_sky}, cuts={args.cuts}); ours {ours_seconds:.2f} s "
          f"(first bake in the process {times[0]:.2f} s), Cycles {cycles_seconds:.2f} s")
    for label, keep in (("covered, > 1 %", bright), ("away from footprints", clear)):
        error = relative[keep]
        print(f"  {label}: mean {100 * error.mean():.2f} %, median {100 * np.median(error):.2f} %, "
              f"worst {100 * error.max():.1f} % over {keep.sum()} texels")
    ours_error = relative[clear].mean()
    if args.picture:
        picture(args.picture, reference, ours[args.map], relative, covered)
    for samples in [int(x) for x in args.sweep.split(",") if x]:
        image, seconds = cycles_bake(scene, floor, material, args.resolution, samples, args.bounces, 2)
        rel = errors(image, reference, covered, footprint)[0][clear].mean()
        print(f"  Cycles {samples:5d} samples: {seconds:7.2f} s, mean error {100 * rel:.2f} % "
              f"({'<=' if rel <= ours_error else '>'} ours {100 * ours_error:.2f} %, ours {ours_seconds:.2f} s)")
    return relative


if __name__ == "__main__":
    main()
