"""Relit panoramas against Cycles panoramic renders from the same viewpoint (issue 13).

A small diffuse scene (a floor, two boxes and a smooth sphere; Principled BSDFs with the
specular layer off, so Cycles renders them Lambertian), seen from ORIGIN. The panorama is
baked once from Blender (Cycles' primary visibility, `addon.panorama_bake`) and relit by the
engine; Cycles renders the same panorama (direct light only) under:
  - env:   an environment without a hard sun (a smooth sky, a broad warm lobe, a dark ground),
  - sun:   a sun lamp, hard (0.5 degree) and large-angle (60 degrees: about as soft as the SH of
           25 coefficients can represent a shadow),
  - point: a point lamp, hard (radius 0) and soft (radius 0.6 m).
Errors on 4 x 4 pixel blocks (averaging out Cycles' noise) whose 16 pixels see one object:
`block rel.` = mean over blocks of |ours - Cycles| / Cycles (RGB sums; the environment case,
target under 5 % with 25 coefficients); `norm. abs.` = mean |ours - Cycles| / mean Cycles
(lamps: blocks in full shadow have no relative error), for 9, 16 and 25 coefficients.

    PYTHONPATH=native/python .venv/bin/python bench/panorama_cycles.py [--size 256x128] [--samples 128]
        [--images docs/images]   # also writes PNG pictures of ours and Cycles' side by side
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import pathlib
import sys
import tempfile
import time

import bpy
import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import hemishadow.panorama as hp  # noqa: E402
from hemishadow.environment import read_exr, write_exr  # noqa: E402

ORIGIN = (0.0, 0.0, 1.2)
SUN = (0.55, -0.35, 0.76)          # towards the sun
POINT = (1.2, -1.0, 2.2)
COUNTS = (9, 16, 25)


def addon():
    """The registered add-on package (the installed extension, as the demo uses it), else this
    checkout's `addon`, registered here."""
    import importlib

    for name in bpy.context.preferences.addons.keys():
        if name.split(".")[-1] == "hemishadow":
            return importlib.import_module(name)
    import addon as package

    if not hasattr(bpy.types.Scene, "hemishadow_panorama"):
        package.register()
    return package


def sky(width=256, height=128):
    """An environment without a hard sun: radiance (H, W, 3), Blender's equirectangular layout."""
    d = hp.directions(width, height)
    z = d[..., 2:3]
    warm = np.array([1.0, -0.5, 0.6]) / np.linalg.norm([1.0, -0.5, 0.6])
    lobe = np.exp(6.0 * ((d * warm).sum(-1, keepdims=True) - 1.0))
    up = np.clip(z, 0, 1)
    ground = 0.5 + 0.5 * np.tanh(-8 * z)  # a smooth horizon: no step for the SH to ring on
    rgb = (1 - ground) * (np.array([0.35, 0.5, 0.8]) * (0.6 + 0.8 * up) + np.array([2.0, 1.4, 0.8]) * lobe) \
        + ground * np.array([0.12, 0.1, 0.08])
    return rgb.astype(np.float32)


def _material(name, rgb):
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # Blender < 5.0 (5.x deprecates use_nodes: always on)
        mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*rgb, 1.0)
    bsdf.inputs["Specular IOR Level"].default_value = 0.0  # Lambertian: the bake's model
    bsdf.inputs["Roughness"].default_value = 1.0
    return mat


def build(folder):
    """The scene (world: the sky written to `folder`), without lamps."""
    bpy.ops.wm.read_homefile(use_empty=True)  # not factory settings: they would disable an installed add-on
    package = addon()
    package.world.clear_cache()
    scene = bpy.context.scene
    for name, location, scale, rgb in (("Floor", (0, 0, -0.05), (10, 10, 0.1), (0.6, 0.6, 0.6)),
                                       ("RedBox", (2.2, 0.9, 0.5), (1, 1, 1), (0.8, 0.2, 0.15)),
                                       ("Pillar", (-1.2, 1.8, 1.0), (0.6, 0.6, 2.0), (0.2, 0.7, 0.3))):
        bpy.ops.mesh.primitive_cube_add(size=1.0, location=location)
        obj = bpy.context.active_object
        obj.name, obj.scale = name, scale
        obj.data.materials.append(_material(name, rgb))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.7, location=(1.0, -2.0, 0.7), segments=48, ring_count=24)
    sphere = bpy.context.active_object
    sphere.name = "Sphere"
    bpy.ops.object.shade_smooth()
    sphere.data.materials.append(_material("Sphere", (0.2, 0.35, 0.85)))
    path = str(pathlib.Path(folder) / "sky.exr")
    write_exr(path, {"": sky()})
    world = bpy.data.worlds.new("Sky")
    if world.node_tree is None:  # Blender < 5.0
        world.use_nodes = True
    nodes = world.node_tree.nodes
    texture = nodes.new("ShaderNodeTexEnvironment")
    texture.image = bpy.data.images.load(path)
    world.node_tree.links.new(texture.outputs["Color"], nodes["Background"].inputs["Color"])
    scene.world = world
    bpy.context.view_layer.update()
    return scene


def set_world_strength(scene, strength):
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = strength


def add_sun(scene, angle_degrees, strength=3.0):
    from mathutils import Vector

    bpy.ops.object.light_add(type="SUN")
    sun = bpy.context.active_object
    sun.rotation_euler = Vector(SUN).to_track_quat("Z", "Y").to_euler()
    sun.data.energy, sun.data.angle = strength, math.radians(angle_degrees)
    bpy.context.view_layer.update()
    return sun


def add_point(scene, radius, power=300.0):
    bpy.ops.object.light_add(type="POINT", location=POINT)
    lamp = bpy.context.active_object
    lamp.data.energy, lamp.data.shadow_soft_size = power, radius
    bpy.context.view_layer.update()
    return lamp


def cycles(scene, size, samples, folder):
    """Cycles' panorama at ORIGIN (direct light only), (H, W, 3) linear, and its seconds."""
    ph = addon().panorama_hits

    path = str(pathlib.Path(folder) / "cycles.exr")
    r, c, f = scene.render, scene.cycles, scene.render.image_settings
    settings = [(r, "engine", "CYCLES"), (r, "resolution_x", size[0]), (r, "resolution_y", size[1]),
                (r, "resolution_percentage", 100), (r, "use_compositing", False), (r, "filepath", path),
                (c, "samples", samples), (c, "use_denoising", False), (c, "use_adaptive_sampling", False),
                (c, "diffuse_bounces", 0), (c, "max_bounces", 1), (c, "device", "CPU"),
                (f, "media_type", "IMAGE"), (f, "file_format", "OPEN_EXR"), (f, "color_depth", "32"),
                (scene.view_settings, "view_transform", "Standard")]
    with ph.temporary_camera(scene, np.array(ORIGIN), np.eye(3)) as camera, \
            ph.overrides([(scene, "camera", camera)] + settings):
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        seconds = time.perf_counter() - t0
    return read_exr(path).astype(np.float64), seconds


def blocks(image, object_id, size=4):
    """Block means (B, 3) of the 4 x 4 blocks whose pixels all see one object, and their mask."""
    h, w = object_id.shape
    ids = object_id[:h - h % size, :w - w % size].reshape(h // size, size, w // size, size)
    same = (ids >= 0).all(axis=(1, 3)) & (ids == ids[:, :1, :, :1]).all(axis=(1, 3))
    img = image[:h - h % size, :w - w % size].reshape(h // size, size, w // size, size, 3).mean(axis=(1, 3))
    return img[same], same


def errors(ours, ref, object_id):
    """(mean block relative error, normalized mean absolute error) of RGB sums on 4 x 4 blocks."""
    a, _ = blocks(ours, object_id)
    b, _ = blocks(ref, object_id)
    a, b = a.sum(axis=1), b.sum(axis=1)
    lit = b > 1e-3 * b.mean()
    return float((np.abs(a - b)[lit] / b[lit]).mean()), float(np.abs(a - b).mean() / b.mean())


def bake(scene, size):
    """{coefficients: Panorama} from one Cycles primary-visibility render."""
    panorama_bake = addon().panorama_bake
    prepared = panorama_bake.prepare(scene, at=ORIGIN, size=size, coefficients=25)
    return {k: panorama_bake.compute(dataclasses.replace(prepared, bands=int(round(math.sqrt(k)))))
            for k in COUNTS}, prepared.hits.object_id


def environment_case(size, samples, folder):
    """(errors per coefficient count, ours (25), Cycles, object ids) under the sky."""
    lightmaps = addon().lightmaps
    scene = build(folder)
    panoramas, ids = bake(scene, size)
    sh = lightmaps.lighting_of(scene)
    ref, seconds = cycles(scene, size, samples, folder)
    out = {k: errors(hp.relight(p, [hp.Environment(sh)]), ref, ids) for k, p in panoramas.items()}
    return out, hp.relight(panoramas[25], [hp.Environment(sh)]), ref, ids, seconds


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="256x128", help="panorama size WxH (default 256x128)")
    parser.add_argument("--samples", type=int, default=128, help="Cycles samples per pixel (default 128)")
    parser.add_argument("--images", metavar="DIR", help="write PNG comparisons (ours above, Cycles below) there")
    args = parser.parse_args(argv)
    size = tuple(int(v) for v in args.size.split("x"))
    pictures = {}
    with tempfile.TemporaryDirectory() as folder:
        env, ours, ref, ids, seconds = environment_case(size, args.samples, folder)
        pictures["env"] = (ours, ref)
        print(f"environment (no hard sun), Cycles {args.samples} spp {size[0]}x{size[1]} in {seconds:.0f} s")
        _table(env)
        scene = bpy.context.scene
        set_world_strength(scene, 0.0)
        panoramas, ids = bake(scene, size)
        for label, make, light in (("sun 0.5 deg", lambda: add_sun(scene, 0.5), hp.Sun(SUN, 3.0)),
                                   ("sun 60 deg", lambda: add_sun(scene, 60.0), hp.Sun(SUN, 3.0)),
                                   ("point r=0", lambda: add_point(scene, 0.0), hp.Point(POINT, 300.0)),
                                   ("point r=0.6", lambda: add_point(scene, 0.6), hp.Point(POINT, 300.0))):
            lamp = make()
            ref, seconds = cycles(scene, size, max(args.samples // 2, 16), folder)
            bpy.data.objects.remove(lamp)
            print(f"{label}: Cycles {max(args.samples // 2, 16)} spp in {seconds:.0f} s")
            _table({k: errors(hp.relight(p, [light]), ref, ids) for k, p in panoramas.items()})
            pictures[label.split()[0] + ("_soft" if "60" in label or "0.6" in label else "")] = (
                hp.relight(panoramas[25], [light]), ref)
    if args.images:
        write_pictures(pathlib.Path(args.images), pictures)


def _table(rows):
    print("  coefficients  block rel.  norm. abs.")
    for k, (rel, nabs) in rows.items():
        print(f"  {k:12d}  {100 * rel:9.2f} %  {100 * nabs:9.2f} %")


def write_pictures(folder, pictures):
    """panorama_vs_cycles_<case>.png: ours above, Cycles below (sRGB, Standard view)."""
    from hemishadow.lightmap.encode import write_png
    from hemishadow.meshio import linear_to_srgb8

    folder.mkdir(parents=True, exist_ok=True)
    for name, (ours, ref) in pictures.items():
        both = np.concatenate([ours, ref], axis=0)
        rgba = np.concatenate([linear_to_srgb8(both), np.full(both.shape[:2] + (1,), 255, np.uint8)], axis=2)
        write_png(folder / f"panorama_vs_cycles_{name}.png", rgba)
        print(f"wrote {folder / f'panorama_vs_cycles_{name}.png'}")


if __name__ == "__main__":
    main()
