"""Probes against Cycles: at each probe, an equirectangular panorama of the incident radiance
rendered by Cycles (camera rotated (90, 0, -90) degrees: the centre column looks along +X,
the top row along +Z; docs and DESIGN.md), integrated into the six cube sides; per-probe
relative error of the sides (relative to the probe's mean side), and the times.

Scene: an 8 m floor, a 1 m box and a 0.2 m wall (subdivided: bounce light is carried per
vertex), white World of strength 1, a sun of strength 3. The sun's direct light reaches a
probe as a delta that a panorama cannot show (Cycles' camera does not see sun lamps): it is
left out of both sides of the comparison (ours minus `capture.sun`); in the bounce case it
still lights the surfaces. Direct only (--bounces 0): every surface black in both.

--lamp point / area: the sun is replaced by a point lamp (300 W, 10 cm radius) or a 1 m
square area lamp (300 W, facing down), the World is black, and the lamp is visible to
Cycles' camera (`visible_camera`), so that the panorama integrates it: both sides compare
the lamp's light whole. A probe the box shadows from the lamp entirely is measured against
the scene's mean side instead of its own (its own is zero).

    PYTHONPATH=native/python .venv/bin/python bench/probes_cycles.py [--bounces 0|N] [--samples 256]
        [--width 256] [--lamp sun|point|area]
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
from addon import probes, world  # noqa: E402
import hemishadow.probes as hp  # noqa: E402
from hemishadow.environment import read_exr  # noqa: E402
from hemishadow.probes import capture  # noqa: E402

POINTS = np.array([[1.0, 0.2, 0.4], [0.3, 1.0, 0.3], [-1.0, -1.0, 1.5], [0.3, 0.2, 1.4], [2.0, 2.0, 0.2],
                   [-1.75, 0.5, 0.8], [-1.3, 0.0, 0.3]])


LAMPS = {"point": dict(type="POINT", location=(1.0, -1.2, 1.8), energy=300.0, shadow_soft_size=0.1),
         "area": dict(type="AREA", location=(0.5, -0.5, 2.5), energy=300.0, size=1.0)}


def build(albedo, cuts=8, lamp="sun"):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    world.clear_cache()
    scene = bpy.context.scene
    scene.world = bpy.data.worlds.new("World")
    bg = scene.world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (1, 1, 1, 1)
    bg.inputs["Strength"].default_value = 1.0 if lamp == "sun" else 0.0
    material = bpy.data.materials.new("Diffuse")
    material.use_nodes = True
    bsdf = material.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (albedo, albedo, albedo, 1)
    bsdf.inputs["Roughness"].default_value = 1.0
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    objects = []
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    objects.append(bpy.context.active_object)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.3, 0.2, 0.5))
    objects.append(bpy.context.active_object)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(-2.0, 0.0, 1.0))
    objects.append(bpy.context.active_object)
    objects[-1].scale = (0.2, 3.0, 2.0)
    for obj in objects:
        obj.data.materials.append(material)
        bpy.ops.object.select_all(action="DESELECT")
        obj.select_set(True)
        bpy.context.view_layer.objects.active = obj
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_all(action="SELECT")
        bpy.ops.mesh.subdivide(number_cuts=cuts)
        bpy.ops.object.mode_set(mode="OBJECT")
    if lamp == "sun":
        bpy.ops.object.light_add(type="SUN", rotation=(math.radians(40), 0, math.radians(30)))
        bpy.context.active_object.data.energy = 3.0
        bpy.context.active_object.data.angle = math.radians(1.0)
    else:
        settings = dict(LAMPS[lamp])
        bpy.ops.object.light_add(type=settings.pop("type"), location=settings.pop("location"))
        obj = bpy.context.active_object
        obj.visible_camera = True  # the panorama must see the lamp to integrate its light
        for key, value in settings.items():
            setattr(obj.data, key, value)
    bpy.context.view_layer.update()
    return scene


def panorama_sides(scene, point, width, samples, bounces, folder):
    """Cube sides (6, 3) of a Cycles panorama at `point`, and the render's seconds."""
    cam_data = bpy.data.cameras.get("Probe") or bpy.data.cameras.new("Probe")
    cam_data.type = "PANO"
    cam_data.panorama_type = "EQUIRECTANGULAR"
    cam = bpy.data.objects.get("Probe") or bpy.data.objects.new("Probe", cam_data)
    if cam.name not in scene.collection.objects:
        scene.collection.objects.link(cam)
    cam.location = point
    cam.rotation_euler = (math.radians(90), 0, math.radians(-90))
    scene.camera = cam
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    # our N bounces: the probe sees surfaces lit by N - 1 bounces; Cycles' diffuse bounces count
    # the bounces after the camera ray's hit, so N - 1 of them
    scene.cycles.diffuse_bounces = max(bounces - 1, 0)
    scene.cycles.max_bounces = max(bounces, 1)
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = width, width // 2, 100
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.view_settings.view_transform = "Standard"
    scene.render.filepath = str(pathlib.Path(folder) / "pano.exr")
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    seconds = time.perf_counter() - t0
    image = read_exr(scene.render.filepath).astype(np.float64)   # (H, W, 3), top row first
    h, w = image.shape[:2]
    lon = np.pi - 2 * np.pi * (np.arange(w) + 0.5) / w            # centre column +X, left quarter +Y
    lat = np.pi / 2 - np.pi * (np.arange(h) + 0.5) / h            # top row +Z
    lon, lat = np.meshgrid(lon, lat)
    d = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], -1).reshape(-1, 3)
    omega = (np.cos(lat) * (2 * np.pi / w) * (np.pi / h)).reshape(-1)
    weights = np.maximum(d @ hp.AXES.T, 0) * omega[:, None] / np.pi   # (HW, 6)
    return weights.T @ image.reshape(-1, 3), seconds


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bounces", type=int, default=0)
    parser.add_argument("--samples", type=int, default=256, help="Cycles samples per pixel")
    parser.add_argument("--width", type=int, default=256, help="panorama width (height = width / 2)")
    parser.add_argument("--cuts", type=int, default=8, help="edge cuts subdividing each mesh (bounce light is "
                                                           "carried per vertex)")
    parser.add_argument("--lamp", choices=("sun", "point", "area"), default="sun",
                        help="the light besides the World (point, area: the World is black)")
    args = parser.parse_args(argv)
    scene = build(0.8 if args.bounces else 0.0, args.cuts, args.lamp)
    t0 = time.perf_counter()
    ours, _ = probes.bake_probes(scene, points=POINTS, bounces=args.bounces, store=False)
    ours_seconds = time.perf_counter() - t0
    engine_scene = probes.scene_geometry(scene)[0]
    for sun in probes.lightmaps.suns_of(scene):
        ours["cube"] = ours["cube"] - capture.sun(engine_scene, ours["positions"].astype(np.float64), sun)[0]
    errors, cycles_seconds, refs = [], 0.0, []
    with tempfile.TemporaryDirectory() as folder:
        for k, p in enumerate(ours["positions"]):
            ref, seconds = panorama_sides(scene, p, args.width, args.samples, args.bounces, folder)
            cycles_seconds += seconds
            refs.append(ref)
    scale = np.mean([r.mean() for r in refs])
    for k, (p, ref) in enumerate(zip(ours["positions"], refs)):
        shadowed = ref.mean() < 0.02 * scale  # the lamp hidden: its own mean is (about) zero
        rel = np.abs(ours["cube"][k] - ref).mean(-1) / (scale if shadowed else ref.mean())
        errors.append(rel)
        print(f"probe {k} at {np.round(p, 2).tolist()}: worst side {100 * rel.max():.1f} %"
              f"{' of the mean probe (shadowed)' if shadowed else ''} "
              f"(ours {np.round(ours['cube'][k, :, 0], 3).tolist()}, Cycles {np.round(ref[:, 0], 3).tolist()})")
    errors = np.array(errors)
    print(f"{args.lamp}: {len(POINTS)} probes, {args.bounces} bounces, {args.cuts} cuts: "
          f"mean {100 * errors.mean():.2f} %, "
          f"worst {100 * errors.max():.1f} %; ours {ours_seconds:.2f} s "
          f"(one-off tables included), Cycles {cycles_seconds:.1f} s ({args.samples} spp, {args.width} px)")
    return errors


if __name__ == "__main__":
    main()
