"""Lightmaps against Cycles' Diffuse bake (Direct + Indirect, Color off): a floor with a box
on it under a uniform white World (strength 1) and a sun; the same UV map, resolution,
margin and diffuse bounces. Prints the mean and worst relative error of `flat` over covered
texels brighter than 1 % of the open-sky value, and both times.

    PYTHONPATH=native/python .venv/bin/python bench/lightmap_cycles.py [--resolution 32]
        [--samples 1024] [--bounces 0] [--no-sun] [--cuts N] [--map flat|b0|b1|b2]

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
import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from addon import lightmaps, world  # noqa: E402
import hemishadow.lightmap as lm  # noqa: E402


def build(sun, cuts=0, basis_vector=None):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    world.clear_cache()
    scene = bpy.context.scene
    scene.world = bpy.data.worlds.new("World")
    bg = scene.world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (1, 1, 1, 1)
    bg.inputs["Strength"].default_value = 1.0
    material = bpy.data.materials.new("Diffuse")
    material.use_nodes = True
    bsdf = material.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1)
    bsdf.inputs["Roughness"].default_value = 1.0
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    floor = bpy.context.active_object
    floor.name = "Floor"
    floor.data.uv_layers.new(name="lightmap")
    floor.data.materials.append(_basis_material(material, basis_vector) if basis_vector is not None else material)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.3, 0.2, 0.5))
    cube = bpy.context.active_object
    cube.data.materials.append(material)
    if cuts:  # bounce light is carried per vertex: finer meshes carry it better
        for obj in (floor, cube):
            bpy.ops.object.select_all(action="DESELECT")
            obj.select_set(True)
            bpy.context.view_layer.objects.active = obj
            bpy.ops.object.mode_set(mode="EDIT")
            bpy.ops.mesh.select_all(action="SELECT")
            bpy.ops.mesh.subdivide(number_cuts=cuts)
            bpy.ops.object.mode_set(mode="OBJECT")
    if sun:
        bpy.ops.object.light_add(type="SUN", rotation=(math.radians(40), 0, math.radians(30)))
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


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, default=32)
    parser.add_argument("--samples", type=int, default=1024, help="Cycles samples")
    parser.add_argument("--bounces", type=int, default=0)
    parser.add_argument("--no-sun", action="store_true")
    parser.add_argument("--cuts", type=int, default=0, help="subdivide the floor and the box (edge cuts)")
    parser.add_argument("--map", choices=("flat", "b0", "b1", "b2"), default="flat")
    args = parser.parse_args(argv)
    vector = None if args.map == "flat" else lm.HL2[int(args.map[1])]
    scene, floor, material = build(not args.no_sun, args.cuts, vector)
    with tempfile.TemporaryDirectory() as folder:
        t0 = time.perf_counter()
        ours = lm.read_exr(lightmaps.bake_lightmaps(scene, [floor], resolution=args.resolution,
                                                    basis="flat" if args.map == "flat" else "hl2",
                                                    bounces=args.bounces, samples=4, margin=2, out_dir=folder,
                                                    images=False)["Floor"])
        ours_seconds = time.perf_counter() - t0
    reference, cycles_seconds = cycles_bake(scene, floor, material, args.resolution, args.samples, args.bounces, 2)
    covered = ours["coverage"] > 0
    bright = reference[..., 0] > 0.01
    # Texels under the box: Cycles bakes their centres' point inside the box (black); ours fills
    # them from valid neighbours (and averages only the valid part of rim texels). Excluded with
    # a one-texel border, as texels next to a texel darker than 1 %.
    padded = np.pad(bright, 1, constant_values=True)
    clear = np.ones_like(bright)
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            clear &= padded[dy:dy + bright.shape[0], dx:dx + bright.shape[1]]
    relative = np.abs(ours[args.map] - reference).mean(-1) / np.maximum(reference.mean(-1), 1e-6)
    print(f"{args.map} vs Cycles ({args.samples} samples, {args.bounces} bounces, sun={not args.no_sun}, "
          f"cuts={args.cuts}); "
          f"ours {ours_seconds:.2f} s, Cycles {cycles_seconds:.2f} s")
    for label, keep in (("covered, > 1 %", covered & bright), ("away from the box's footprint", covered & clear)):
        error = relative[keep]
        print(f"  {label}: mean {100 * error.mean():.2f} %, median {100 * np.median(error):.2f} %, "
              f"worst {100 * error.max():.1f} % over {keep.sum()} texels")
    return relative


if __name__ == "__main__":
    main()
