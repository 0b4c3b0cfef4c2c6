"""The Blender demo: cloth falling onto Suzanne, lit by a Blender HDRI, self-shadowed live.

    .venv/bin/python scripts/demo_blender.py --out out/demo

Like Figure 1 of Kautz et al. 2004: a cloth simulation (a subdivided plane of 1,444 vertices
with a Cloth modifier) drops onto an obstacle (Suzanne, smooth, with a Subdivision Surface
modifier: hemishadow computes on its 507 original vertices and the modifier interpolates).
The script
1. builds the scene and bakes the cloth simulation's point cache;
2. lights it with the World's Environment Texture = Blender's "forest" HDRI;
3. enables hemishadow on both objects, adds the one-click material, turns Live on;
4. steps the frames with `scene.frame_set` (the live handlers compute every frame) and prints
   per-frame times: engine (transfer + shading) and Blender I/O (reading the evaluated mesh,
   writing the attributes), and frame_set as a whole;
5. bakes the range into hemishadow caches (//hemishadow_cache/*.npz, see docs/baking.md);
6. renders a few frames with Cycles (CPU) to PNG (the handlers copy the cached values) and
   saves the .blend.

The add-on is the repository's `addon/` package, imported as the package `hemishadow_addon`
and registered as Blender registers an enabled extension (`--addon` points at another copy,
for example the unpacked extension zip).
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="out/demo", help="output folder (PNG frames, demo.blend)")
    parser.add_argument("--frames", type=int, default=60, help="frames to simulate and shade (default 60)")
    parser.add_argument("--render", type=int, nargs="*", default=None,
                        help="frames to render (default: 4 spread over the range)")
    parser.add_argument("--resolution", type=int, nargs=2, default=(640, 480), metavar=("X", "Y"))
    parser.add_argument("--samples", type=int, default=16, help="Cycles samples (default 16)")
    parser.add_argument("--grid", type=int, default=38, help="cloth vertices per side (default 38: 1,444)")
    parser.add_argument("--hdri", default="forest", help="one of Blender's built-in HDRIs (default forest)")
    parser.add_argument("--addon", default=str(ROOT / "addon"), help="the add-on package folder (default: addon/)")
    return parser.parse_args(argv)


def load_addon(folder):
    """Register the add-on package in `folder` as `hemishadow_addon`, as an installed extension is."""
    import importlib.util

    import bpy

    name = "hemishadow_addon"
    if name in sys.modules:
        return sys.modules[name]
    folder = pathlib.Path(folder)
    spec = importlib.util.spec_from_file_location(name, folder / "__init__.py", submodule_search_locations=[str(folder)])
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    if not hasattr(bpy.types.Object, "hemishadow"):
        module.register()
    return module


# -- the scene ---------------------------------------------------------------------------------

def build_scene(grid: int, frames: int, hdri: str):
    import bpy
    from hemishadow.environment import builtin_hdris

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, frames
    scene.render.fps = 24

    # Floor: catches the cloth's edges.
    bpy.ops.mesh.primitive_plane_add(size=8, location=(0, 0, 0))
    floor = bpy.context.object
    floor.name = "Floor"
    floor.modifiers.new("Collision", "COLLISION")

    # Obstacle: Suzanne looking up, smooth, subdivided after (hemishadow computes on the
    # original 507 vertices and the Subdivision Surface interpolates the attribute).
    bpy.ops.mesh.primitive_monkey_add(size=1.5, location=(0, 0, 0.7), rotation=(-0.15, 0, 0.3))
    suzanne = bpy.context.object
    suzanne.name = "Suzanne"
    bpy.ops.object.shade_smooth()
    suzanne.modifiers.new("Subdivision", "SUBSURF").levels = 1
    suzanne.modifiers["Subdivision"].render_levels = 2
    collision = suzanne.modifiers.new("Collision", "COLLISION").settings
    collision.thickness_outer = 0.03
    collision.cloth_friction = 30.0   # the cloth holds on to the head instead of sliding off

    # Cloth: a grid of grid x grid vertices, 2 m wide, dropped over the back of the head.
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=grid - 1, y_subdivisions=grid - 1, size=2.0,
                                    location=(0.1, 0.25, 1.7), rotation=(0.1, 0.06, 0.3))
    cloth = bpy.context.object
    cloth.name = "Cloth"
    bpy.ops.object.shade_smooth()
    settings = cloth.modifiers.new("Cloth", "CLOTH").settings
    settings.quality = 6
    settings.mass = 0.3
    settings.tension_stiffness = settings.compression_stiffness = 10.0
    settings.bending_stiffness = 0.05
    cloth.modifiers["Cloth"].collision_settings.distance_min = 0.01
    cloth.modifiers["Cloth"].point_cache.frame_end = frames

    # World: Blender's HDRI through the Environment Texture node (what hemishadow reads).
    world = bpy.data.worlds.new("Forest")
    scene.world = world
    if world.node_tree is None:   # Blender < 5.0 makes worlds without nodes
        world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    environment = nodes.new("ShaderNodeTexEnvironment")
    environment.image = bpy.data.images.load(str(builtin_hdris()[hdri]))
    links.new(environment.outputs["Color"], nodes["Background"].inputs["Color"])

    # Camera looking down at the drape.
    bpy.ops.object.camera_add(location=(2.2, -3.9, 2.1))
    camera = bpy.context.object
    camera.data.lens = 50
    target = bpy.data.objects.new("Target", None)
    scene.collection.objects.link(target)
    target.location = (0.05, 0.1, 0.8)
    constraint = camera.constraints.new("TRACK_TO")
    constraint.target = target
    constraint.track_axis, constraint.up_axis = "TRACK_NEGATIVE_Z", "UP_Y"
    scene.camera = camera
    return scene, cloth, suzanne, floor


def bake_cloth(scene, cloth):
    """Simulate the cloth into its point cache (frames stepped in order)."""
    import bpy

    t0 = time.perf_counter()
    with bpy.context.temp_override(scene=scene, active_object=cloth, object=cloth,
                                   point_cache=cloth.modifiers["Cloth"].point_cache):
        bpy.ops.ptcache.bake(bake=True)
    return time.perf_counter() - t0


def setup_render(scene, resolution, samples):
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = True   # OpenImageDenoise ships with the bpy module
    scene.render.resolution_x, scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    scene.view_settings.view_transform = "AgX"
    scene.view_settings.look = "AgX - Medium High Contrast"
    scene.view_settings.exposure = -0.6


def demo_material(obj):
    """The add-on's one-click material (hemishadow.add_material, Emit Radiance) on `obj`."""
    import bpy

    with bpy.context.temp_override(object=obj, active_object=obj, selected_objects=[obj],
                                   selected_editable_objects=[obj]):
        bpy.ops.hemishadow.add_material(mode="EMIT")


def floor_material(floor):
    import bpy

    material = bpy.data.materials.new("Floor")
    if material.node_tree is None:
        material.use_nodes = True
    principled = material.node_tree.nodes["Principled BSDF"]
    principled.inputs["Base Color"].default_value = (0.30, 0.29, 0.27, 1.0)
    principled.inputs["Roughness"].default_value = 0.9
    floor.data.materials.append(material)


# -- the run -----------------------------------------------------------------------------------

def run_live(scene, objects, frames, engine_bridge):
    """Step every frame with Live on; per frame: frame_set seconds and, per object, the live
    path's own split (vertices, Blender I/O, engine), or None when nothing moved (the live
    path then computes nothing: Suzanne is static)."""
    rows = []
    for frame in range(scene.frame_start, scene.frame_start + frames):
        engine_bridge.last_timings.clear()
        t0 = time.perf_counter()
        scene.frame_set(frame)
        total = time.perf_counter() - t0
        rows.append((frame, total, {o.name: engine_bridge.last_timings.get(o.name) for o in objects}))
    return rows


def print_timings(rows, objects):
    names = [o.name for o in objects]
    print("frame  frame_set ms  " + "  ".join(f"{n}: engine ms, I/O ms" for n in names))
    for frame, total, timings in rows:
        cells = []
        for n in names:
            t = timings[n]
            text = "unchanged" if t is None else f"{t[2] * 1e3:7.1f}, {t[1] * 1e3:5.1f}"
            cells.append(f"{text:>{len(n) + 20}}")
        print(f"{frame:>5}  {total * 1e3:>12.1f}  " + "  ".join(cells))
    print(f"medians over {len(rows)} frames (computed frames only):")
    for n in names:
        done = [r[2][n] for r in rows if r[2][n] is not None]
        if not done:
            print(f"  {n}: never moved, computed once when Live was switched on")
            continue
        engine = np.median([t[2] for t in done]) * 1e3
        io = np.median([t[1] for t in done]) * 1e3
        print(f"  {n}: {done[0][0]} vertices, computed on {len(done)} frames: engine {engine:.1f} ms, "
              f"Blender I/O {io:.1f} ms")
    print(f"  frame_set as a whole (cloth cache read, depsgraph, handlers): "
          f"{np.median([r[1] for r in rows]) * 1e3:.1f} ms")


def main(argv=None):
    args = parse_args(argv)
    out = pathlib.Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)

    import bpy

    addon = load_addon(args.addon)
    engine_bridge = sys.modules[addon.__name__ + ".engine_bridge"]
    bake = sys.modules[addon.__name__ + ".operators.bake"]

    scene, cloth, suzanne, floor = build_scene(args.grid, args.frames, args.hdri)
    blend = out / "demo.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))   # a home for the caches (//)
    print(f"scene: cloth {len(cloth.data.vertices)} vertices, Suzanne {len(suzanne.data.vertices)} vertices, "
          f"frames {scene.frame_start}..{scene.frame_end}, lighting: Blender's '{args.hdri}' HDRI")
    print(f"cloth simulation baked in {bake_cloth(scene, cloth):.1f} s")

    objects = [cloth, suzanne]
    for obj, albedo in ((cloth, (0.80, 0.30, 0.22)), (suzanne, (0.80, 0.72, 0.55))):
        obj.hemishadow.enabled = True
        obj.hemishadow.albedo = albedo
    scene.hemishadow.lighting_source = "WORLD"
    demo_material(cloth)
    demo_material(suzanne)
    floor_material(floor)

    print("live self-shadowing (scene.frame_set, handlers on):")
    scene.hemishadow.live = True
    rows = run_live(scene, objects, args.frames, engine_bridge)
    print_timings(rows, objects)

    # Bake the same range, so the renders (and playback) copy from the cache.
    result = bake.bake_range(scene, objects, scene.frame_start, scene.frame_end)
    print(f"baked frames {scene.frame_start}..{scene.frame_end}: engine {result.engine_seconds:.2f} s, "
          f"Blender {result.blender_seconds:.2f} s -> " + ", ".join(result.saved.values()))

    setup_render(scene, args.resolution, args.samples)
    frames = args.render if args.render is not None else [
        scene.frame_start + round(i * (args.frames - 1) / 3) for i in range(4)]
    for frame in frames:
        scene.frame_set(frame)
        scene.render.filepath = str(out / f"frame_{frame:03d}.png")
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        print(f"rendered {scene.render.filepath} ({time.perf_counter() - t0:.1f} s, Cycles CPU, "
              f"{args.samples} samples)")
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    print(f"saved {blend}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
