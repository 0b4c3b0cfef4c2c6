"""Probes against Cycles: at each probe, an equirectangular panorama of the incident radiance
rendered by Cycles (camera rotated (90, 0, -90) degrees: the centre column looks along +X,
the top row along +Z; docs and DESIGN.md), integrated into the six cube sides; per-probe
relative error of the sides (relative to the probe's mean side), and the times.

Scene: an 8 m floor, a 1 m box and a 0.2 m wall (subdivided: bounce light is carried per
vertex), white World of strength 1, a sun of strength 3. The sun's direct light reaches a
probe as a delta that a panorama cannot show (Cycles' camera does not see sun lamps): it is
left out of both sides of the comparison (ours minus `capture.sun`); in the bounce case it
still lights the surfaces. Direct only (--bounces 0): every surface black in both.

--sweep 1@32,1,4,16: Cycles at those samples per pixel (@ panorama width, else --width; no
adaptive sampling) and ours against a Cycles reference at --samples (--ref-width wide); the
camera samples (spp x pixels: the panorama's integral averages them all) and time per probe
at which Cycles' error equals ours, and the speed-up, per probe of a --many probe bake and
all-in for the seven probes in a fresh process. Times: wall and process CPU seconds (all threads).

--lamp point / area: the sun is replaced by a point lamp (300 W, 10 cm radius) or a 1 m
square area lamp (300 W, facing down), the World is black, and the lamp is visible to
Cycles' camera (`visible_camera`), so that the panorama integrates it: both sides compare
the lamp's light whole. A probe the box shadows from the lamp entirely is measured against
the scene's mean side instead of its own (its own is zero).

    PYTHONPATH=native/python .venv/bin/python bench/probes_cycles.py [--bounces 0|N] [--samples 256]
        [--width 256] [--lamp sun|point|area] [--sweep 1@32,1,4 [--ref-width 256] [--many 1024]]
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
from lightmap_cycles import subdivide  # noqa: E402  (this folder)
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
    if material.node_tree is None:  # Blender < 5.0 (5.x deprecates use_nodes: always on)
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
    subdivide(objects, cuts)
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


def panorama_sides(scene, point, width, samples, bounces, folder, adaptive=True):
    """Cube sides (6, 3) of a Cycles panorama at `point`, and the render's wall and process
    CPU seconds (all of Cycles' threads)."""
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
    scene.cycles.use_adaptive_sampling = adaptive  # off in --sweep: the sample count sets the time
    # our N bounces: the probe sees surfaces lit by N - 1 bounces; Cycles' diffuse bounces count
    # the bounces after the camera ray's hit, so N - 1 of them
    scene.cycles.diffuse_bounces = max(bounces - 1, 0)
    scene.cycles.max_bounces = max(bounces, 1)
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = width, width // 2, 100
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.view_settings.view_transform = "Standard"
    scene.render.filepath = str(pathlib.Path(folder) / "pano.exr")
    t0, c0 = time.perf_counter(), time.process_time()
    bpy.ops.render.render(write_still=True)
    seconds = time.perf_counter() - t0, time.process_time() - c0
    image = read_exr(scene.render.filepath).astype(np.float64)   # (H, W, 3), top row first
    h, w = image.shape[:2]
    lon = np.pi - 2 * np.pi * (np.arange(w) + 0.5) / w            # centre column +X, left quarter +Y
    lat = np.pi / 2 - np.pi * (np.arange(h) + 0.5) / h            # top row +Z
    lon, lat = np.meshgrid(lon, lat)
    d = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], -1).reshape(-1, 3)
    omega = (np.cos(lat) * (2 * np.pi / w) * (np.pi / h)).reshape(-1)
    weights = np.maximum(d @ hp.AXES.T, 0) * omega[:, None] / np.pi   # (HW, 6)
    return weights.T @ image.reshape(-1, 3), seconds


def probe_errors(cubes, refs):
    """(P, 6) relative errors, |ours - Cycles| per side (mean over RGB) / the probe's mean side,
    and which probes the lamp does not reach (measured against the scene's mean probe)."""
    refs = np.asarray(refs)
    means = refs.mean(axis=(1, 2))
    scale = means.mean()
    shadowed = means < 0.02 * scale  # the lamp hidden: its own mean is (about) zero
    return np.abs(cubes - refs).mean(-1) / np.where(shadowed, scale, means)[:, None], shadowed


def timed_bake(scene, points, bounces):
    """Our probes at `points` (the sun's delta left out, as Cycles cannot see it), wall and CPU seconds."""
    t0, c0 = time.perf_counter(), time.process_time()
    ours, _ = probes.bake_probes(scene, points=points, bounces=bounces, store=False)
    seconds = time.perf_counter() - t0, time.process_time() - c0
    engine_scene = probes.scene_geometry(scene)[0]
    for sun in probes.lightmaps.suns_of(scene):
        ours["cube"] = ours["cube"] - capture.sun(engine_scene, ours["positions"].astype(np.float64), sun)[0]
    return ours, np.array(seconds)


def equal_error(ladder, errs, seconds, target):
    """Camera samples (spp x pixels) and seconds at which Cycles' error equals `target`: log-log
    interpolation between the ladder's rungs (sorted by samples), 1 / sqrt(N) and time ~ N past
    the last (Cycles is unbiased: its error is noise); the first rung if that is already as good."""
    if target >= errs[0]:
        return ladder[0], seconds[0]
    if target <= errs[-1]:
        n = ladder[-1] * (errs[-1] / target) ** 2
        return n, seconds[-1] * n / ladder[-1]
    k = np.nonzero(errs <= target)[0][0]
    t = (np.log(target) - np.log(errs[k - 1])) / (np.log(errs[k]) - np.log(errs[k - 1]))
    lerp = lambda v: np.exp(np.log(v[k - 1]) + t * (np.log(v[k]) - np.log(v[k - 1])))  # noqa: E731
    return lerp(ladder), lerp(seconds)


def sweep(scene, args, rungs):
    """Cycles at the `rungs` (spp, width) and ours, each against a Cycles reference at
    args.samples; the samples and time at which Cycles' error equals ours; the speed-up."""
    p = len(POINTS)
    ours, fresh = timed_bake(scene, POINTS, args.bounces)      # a fresh process: one-off tables
    ours, warm = timed_bake(scene, POINTS, args.bounces)
    many = np.tile(POINTS, (args.many // p, 1))                 # a grid's worth: fixed costs spread
    big = timed_bake(scene, many, args.bounces)[1]
    per_probe = big / len(many)
    rungs = sorted(rungs, key=lambda r: r[0] * r[1] ** 2)
    with tempfile.TemporaryDirectory() as folder:
        def render(samples, width):
            out = [panorama_sides(scene, q, width, samples, args.bounces, folder, adaptive=False) for q in POINTS]
            return np.array([o[0] for o in out]), np.array([o[1] for o in out]).mean(0)
        refs, ref_seconds = render(args.samples, args.ref_width or args.width)
        rows = [render(*r) for r in rungs]
    ours_err = probe_errors(ours["cube"], refs)[0]
    print(f"{args.lamp}, {args.bounces} bounces, {args.cuts} cuts, {p} probes; reference {args.samples} spp, "
          f"{args.ref_width or args.width} px wide: {ref_seconds[0]:.1f} s wall, {ref_seconds[1]:.1f} s CPU per probe")
    print("| | mean error | worst error | wall s / probe | CPU s / probe |\n|---|---|---|---|---|")
    errs = []
    for (spp, width), (sides, seconds) in zip(rungs, rows):
        err = probe_errors(sides, refs)[0]
        errs.append((err.mean(), err.max()))
        print(f"| Cycles {spp} spp, {width} x {width // 2} px | {100 * err.mean():.2f} % | {100 * err.max():.1f} % | "
              f"{seconds[0]:.3f} | {seconds[1]:.3f} |")
    print(f"| ours (time: {len(many)} probes / {len(many)}) | {100 * ours_err.mean():.2f} % | "
          f"{100 * ours_err.max():.1f} % | {per_probe[0]:.4f} | {per_probe[1]:.4f} |")
    marginal = (big - warm) / (len(many) - p)
    print(f"ours, {p} probes: fresh process {fresh[0]:.2f} s wall, {fresh[1]:.2f} s CPU; again {warm[0]:.2f} s wall, "
          f"{warm[1]:.2f} s CPU (one-off tables of a fresh process: {fresh[0] - warm[0]:.2f} s wall, "
          f"{fresh[1] - warm[1]:.2f} s CPU); {len(many)} probes {big[0]:.2f} s wall, {big[1]:.2f} s CPU; "
          f"each probe past the fixed costs {1e3 * marginal[0]:.2f} ms wall, {1e3 * marginal[1]:.2f} ms CPU")
    samples = np.array([spp * w * (w // 2) for spp, w in rungs], float)
    errs = np.array(errs)
    for i, label in enumerate(("mean", "worst")):
        target = ours_err.mean() if i == 0 else ours_err.max()
        found = [equal_error(samples, errs[:, i], np.array([r[1][j] for r in rows]), target) for j in (0, 1)]
        n, cycles = found[0][0], np.array([f[1] for f in found])
        print(f"equal {label} error: Cycles at {n:.0f} camera samples per probe, {cycles[0]:.3f} s wall, "
              f"{cycles[1]:.3f} s CPU per probe; speed-up {cycles[0] / per_probe[0]:.1f}x wall, "
              f"{cycles[1] / per_probe[1]:.1f}x CPU ({len(many)} probes), {cycles[0] / marginal[0]:.0f}x wall past "
              f"the fixed costs, {cycles[0] * p / fresh[0]:.2f}x wall ({p} probes, fresh process)")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bounces", type=int, default=0)
    parser.add_argument("--samples", type=int, default=256, help="Cycles samples per pixel")
    parser.add_argument("--width", type=int, default=256, help="panorama width (height = width / 2)")
    parser.add_argument("--cuts", type=int, default=8, help="edge cuts subdividing each mesh (bounce light is "
                                                           "carried per vertex)")
    parser.add_argument("--lamp", choices=("sun", "point", "area"), default="sun",
                        help="the light besides the World (point, area: the World is black)")
    parser.add_argument("--sweep", default="", help="Cycles samples[@width] to time against ours at equal error, "
                                                      "e.g. 1@32,1@64,4,16 (--samples: the reference's)")
    parser.add_argument("--ref-width", type=int, default=0, help="--sweep: the reference's panorama width "
                                                                  "(default --width)")
    parser.add_argument("--many", type=int, default=1024, help="--sweep: probes of our timed grid-sized bake")
    args = parser.parse_args(argv)
    scene = build(0.8 if args.bounces else 0.0, args.cuts, args.lamp)
    if args.sweep:
        rungs = [(x + "@" + str(args.width)).split("@")[:2] for x in args.sweep.split(",")]
        return sweep(scene, args, [(int(spp), int(width)) for spp, width in rungs])
    ours, (ours_seconds, _) = timed_bake(scene, POINTS, args.bounces)
    cycles_seconds, refs = 0.0, []
    with tempfile.TemporaryDirectory() as folder:
        for k, p in enumerate(ours["positions"]):
            ref, seconds = panorama_sides(scene, p, args.width, args.samples, args.bounces, folder)
            cycles_seconds += seconds[0]
            refs.append(ref)
    errors, shadowed = probe_errors(ours["cube"], refs)
    for k, (p, ref, rel) in enumerate(zip(ours["positions"], refs, errors)):
        print(f"probe {k} at {np.round(p, 2).tolist()}: worst side {100 * rel.max():.1f} %"
              f"{' of the mean probe (shadowed)' if shadowed[k] else ''} "
              f"(ours {np.round(ours['cube'][k, :, 0], 3).tolist()}, Cycles {np.round(ref[:, 0], 3).tolist()})")
    print(f"{args.lamp}: {len(POINTS)} probes, {args.bounces} bounces, {args.cuts} cuts: "
          f"mean {100 * errors.mean():.2f} %, "
          f"worst {100 * errors.max():.1f} %; ours {ours_seconds:.2f} s "
          f"(one-off tables included), Cycles {cycles_seconds:.1f} s ({args.samples} spp, {args.width} px)")
    return errors


if __name__ == "__main__":
    main()
