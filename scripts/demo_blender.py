"""The Blender demo: cloth falling onto Suzanne over a floor, lit by a Blender HDRI, shadowed
live (each by itself and by the others), through the installed extension.

    .venv/bin/python scripts/build_extension.py --if-stale   # dist/hemishadow-0.1.0-linux_x64.zip
    .venv/bin/python scripts/demo_blender.py                  # or: make demo (does both)

Like Figure 1 of Kautz et al. 2004: a cloth simulation (a subdivided plane of 1,444 vertices
with a Cloth modifier) drops onto an obstacle (Suzanne, smooth, with a Subdivision Surface
modifier: hemishadow computes on its 507 original vertices and the modifier interpolates),
over a subdivided floor. Cloth, Suzanne and the floor are the scene's "Shadow casters"
collection: the cloth darkens Suzanne's head, and both darken the floor.
The script
0. installs the extension zip into the project's `bpy` module the way a user does
   (`bpy.ops.extensions.package_install_files`, enabled on install) into a project-local user
   folder (out/blender_user, recreated every run: BLENDER_USER_RESOURCES is set before `bpy`
   is imported, so a real user's Blender configuration is never touched), and checks that the
   add-on is enabled and that the engine `hemishadow` is imported from the extension's
   wheels, not from this environment;
1. builds the scene and bakes the cloth simulation's point cache;
2. lights it with the World's Environment Texture = Blender's "forest" HDRI;
3. enables hemishadow on the three objects, makes them the scene's shadow casters
   (`scene.hemishadow.casters`; `--no-casters`: self-shadowing only), adds the one-click material
   (`bpy.ops.hemishadow.add_material`), turns Live on (`bpy.ops.hemishadow.live_toggle`);
4. steps the frames with `scene.frame_set` (the live handlers compute every frame) and prints
   per-frame times: engine (transfer + shading) and Blender I/O (reading the evaluated mesh,
   writing the attributes), and frame_set as a whole;
5. bakes the range into hemishadow caches (//hemishadow_cache/*.npz, see docs/baking.md);
6. renders a few frames with Cycles (CPU) to PNG (the handlers copy the cached values) and
   saves the .blend.

The add-on runs as Blender runs an installed extension: the package
`bl_ext.user_default.hemishadow`, found in `sys.modules` once enabled.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import pathlib
import shutil
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
ZIP = ROOT / "dist" / "hemishadow-0.1.0-linux_x64.zip"
MODULE = "bl_ext.user_default.hemishadow"   # the add-on's package once installed in user_default


def demo_parser(doc, out_name, out_help="output folder"):
    """The options every demo shares: the zip to install, the output folder (out/`out_name`),
    Blender's user folder for the run, and --source."""
    parser = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    parser.add_argument("zip", nargs="?", default=str(ZIP),
                        help=f"the extension zip to install (default {ZIP.relative_to(ROOT)})")
    parser.add_argument("--out", default=str(ROOT / "out" / out_name), help=out_help)
    parser.add_argument("--user-resources", default=str(ROOT / "out" / "blender_user"),
                        help="Blender's user folder for this run, deleted and recreated (default out/blender_user)")
    parser.add_argument("--source", action="store_true",
                        help="register the add-on of this checkout with the environment's engine instead of "
                             "installing the zip (to measure changes before they are packaged)")
    return parser


def parse_args(argv=None):
    parser = demo_parser(__doc__, "demo", "output folder (PNG frames, demo.blend)")
    parser.add_argument("--frames", type=int, default=40, help="frames to simulate and shade (default 40)")
    parser.add_argument("--render", type=int, nargs="*", default=None,
                        help="frames to render (default: 4 spread over the range)")
    parser.add_argument("--no-render", action="store_true", help="render nothing (a quick check)")
    parser.add_argument("--resolution", type=int, nargs=2, default=(480, 360), metavar=("X", "Y"))
    parser.add_argument("--samples", type=int, default=16, help="Cycles samples (default 16)")
    parser.add_argument("--grid", type=int, default=38, help="cloth vertices per side (default 38: 1,444)")
    parser.add_argument("--hdri", default="forest", help="one of Blender's built-in HDRIs (default forest)")
    parser.add_argument("--no-casters", action="store_true",
                        help="self-shadowing only: no 'Shadow casters' collection (to compare the per-frame times)")
    return parser.parse_args(argv)


# -- installing the extension ------------------------------------------------------------------

def prepare_user_resources(folder):
    """Point Blender at an empty user folder; must run before `bpy` is imported."""
    if "bpy" in sys.modules:
        raise SystemExit("demo_blender: bpy is already imported; BLENDER_USER_RESOURCES would be ignored")
    folder = pathlib.Path(folder).resolve()
    if folder.exists():
        shutil.rmtree(folder)
    # Blender puts the extensions' wheel folder ahead of the other site-packages only when it
    # exists at start-up; created later (by the install), it goes to the end of sys.path,
    # behind this environment's own build of the engine. A user's Blender, with the
    # extension installed, starts with it present: create it first, as that start-up does.
    site = (folder / "extensions" / ".local" / "lib" /
            f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages")
    site.mkdir(parents=True)
    os.environ["BLENDER_USER_RESOURCES"] = str(folder)
    return folder, site


def install_extension(zip_path, site):
    """Install and enable the zip as a user does; the enabled add-on's module."""
    import addon_utils
    import bpy

    zip_path = pathlib.Path(zip_path).resolve()
    if not zip_path.is_file():
        raise SystemExit(f"demo_blender: no extension zip at {zip_path} "
                         f"(build it: .venv/bin/python scripts/build_extension.py)")
    t0 = time.perf_counter()
    bpy.ops.extensions.package_install_files(filepath=str(zip_path), repo="user_default", enable_on_install=True)
    # The operator's return value is no proof: check what Blender itself reports.
    loaded_default, loaded_state = addon_utils.check(MODULE)
    if not (loaded_default and loaded_state and MODULE in bpy.context.preferences.addons):
        raise SystemExit(f"demo_blender: {MODULE} is not enabled after installing {zip_path}")
    import hemishadow
    import hemishadow._native
    for module in (hemishadow, hemishadow._native):
        if not pathlib.Path(module.__file__).resolve().is_relative_to(site):
            raise SystemExit(f"demo_blender: {module.__name__} was imported from {module.__file__}, "
                             f"not from the extension's wheels in {site}")
    addon = sys.modules[MODULE]
    print(f"installed {zip_path.name} in {time.perf_counter() - t0:.1f} s: {MODULE} enabled "
          f"({pathlib.Path(addon.__file__).parent}), engine from {pathlib.Path(hemishadow.__file__).parent}")
    return addon


# -- the scene ---------------------------------------------------------------------------------

def use_addon(source, zip_path, site):
    """Registers this checkout's add-on with the environment's engine (`source`), or installs
    the extension zip as a user would."""
    if source:
        sys.path.insert(0, str(ROOT))
        import addon
        import hemishadow

        addon.register()
        print(f"add-on from {ROOT / 'addon'} (not installed), engine from {pathlib.Path(hemishadow.__file__).parent}")
    else:
        install_extension(zip_path, site)


def build_scene(grid: int, frames: int, hdri: str):
    import bpy
    from hemishadow.environment import builtin_hdris

    # An empty scene; read_factory_settings would also reset the preferences and so
    # disable the extension just installed.
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, frames
    scene.render.fps = 24

    # Floor: catches the cloth's edges; subdivided, so that its vertices can show the shadows.
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=40, y_subdivisions=40, size=8, location=(0, 0, 0))
    floor = bpy.context.object
    floor.name = "Floor"
    floor.modifiers.new("Collision", "COLLISION")

    # Obstacle: Suzanne looking up, smooth, subdivided last (hemishadow computes on the
    # original 507 vertices and the Subdivision Surface interpolates the attribute). Collision
    # comes first: the cloth collides with the 507-vertex cage, and Blender can leave the
    # subdivision till something needs it; after it, Collision would make Blender subdivide
    # again every time the shadows on Suzanne change (docs/blender.md, "Shadow casters").
    bpy.ops.mesh.primitive_monkey_add(size=1.5, location=(0, 0, 0.7), rotation=(-0.15, 0, 0.3))
    suzanne = bpy.context.object
    suzanne.name = "Suzanne"
    bpy.ops.object.shade_smooth()
    collision = suzanne.modifiers.new("Collision", "COLLISION").settings
    collision.thickness_outer = 0.03
    collision.cloth_friction = 30.0   # the cloth holds on to the head instead of sliding off
    suzanne.modifiers.new("Subdivision", "SUBSURF").levels = 1
    suzanne.modifiers["Subdivision"].render_levels = 2

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
    with quiet_stdout(), bpy.context.temp_override(scene=scene, active_object=cloth, object=cloth,
                                                   point_cache=cloth.modifiers["Cloth"].point_cache):
        bpy.ops.ptcache.bake(bake=True)   # prints "bake: frame N :: M" for every frame
    return time.perf_counter() - t0


@contextlib.contextmanager
def quiet_stdout():
    """Send what Blender's C code prints to stdout (file descriptor 1) to /dev/null."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


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


def shadow_casters(scene, objects):
    """A "Shadow casters" collection holding `objects` (linked, not moved), the scene's default."""
    import bpy

    collection = bpy.data.collections.new("Shadow casters")
    scene.collection.children.link(collection)
    for obj in objects:
        collection.objects.link(obj)
    scene.hemishadow.casters = collection
    return collection


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
    # Outputs of an earlier run: a bake cache there would be used instead of computing live.
    shutil.rmtree(out / "hemishadow_cache", ignore_errors=True)
    if not args.no_render:
        for old in out.glob("frame_*.png"):
            old.unlink()
    user, site = prepare_user_resources(args.user_resources)

    import bpy

    module = "addon" if args.source else MODULE
    use_addon(args.source, args.zip, site)
    engine_bridge = sys.modules[module + ".engine_bridge"]
    bake = sys.modules[module + ".operators.bake"]

    scene, cloth, suzanne, floor = build_scene(args.grid, args.frames, args.hdri)
    blend = out / "demo.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))   # a home for the caches (//)
    print(f"scene: cloth {len(cloth.data.vertices)} vertices, Suzanne {len(suzanne.data.vertices)} vertices, "
          f"frames {scene.frame_start}..{scene.frame_end}, lighting: Blender's '{args.hdri}' HDRI")
    print(f"cloth simulation baked in {bake_cloth(scene, cloth):.1f} s")

    objects = [cloth, suzanne, floor]
    for obj, albedo in ((cloth, (0.80, 0.30, 0.22)), (suzanne, (0.80, 0.72, 0.55)), (floor, (0.42, 0.40, 0.37))):
        obj.hemishadow.enabled = True
        obj.hemishadow.albedo = albedo
        demo_material(obj)
    scene.hemishadow.lighting_source = "WORLD"
    if not args.no_casters:
        shadow_casters(scene, objects)

    print("live shadowing (scene.frame_set, handlers on), shadow casters: "
          + ("none (self-shadowing only)" if args.no_casters else "cloth, Suzanne and floor") + ":")
    scene.frame_set(scene.frame_start)
    engine_bridge.last_timings.clear()
    bpy.ops.hemishadow.live_toggle()   # switched on: computes the enabled objects at once
    if not scene.hemishadow.live:
        raise SystemExit("demo_blender: hemishadow.live_toggle did not switch Live on")
    unshaded = [o for o in objects if o.hemishadow.enabled and o.name not in engine_bridge.last_timings]
    if unshaded:  # the add-on reported why (console, status): stop rather than time nothing
        raise SystemExit("demo_blender: Live computed nothing for " + "; ".join(
            f"{o.name} ({o.hemishadow.status or 'no status'})" for o in unshaded))
    print(f"Live on at frame {scene.frame_start}, first computation: " + ", ".join(
        f"{name} {t[0]} vertices, engine {t[2] * 1e3:.1f} ms, Blender I/O {t[1] * 1e3:.1f} ms"
        for name, t in engine_bridge.last_timings.items()))
    rows = run_live(scene, objects, args.frames, engine_bridge)
    print_timings(rows, objects)
    for obj in objects:
        names = sorted(a.name for a in obj.data.attributes if a.name.startswith("hemishadow_"))
        print(f"attributes of {obj.name}: {', '.join(names) or 'none'}")

    # Bake the same range, so the renders (and playback) copy from the cache.
    result = bake.bake_range(scene, objects, scene.frame_start, scene.frame_end)
    print(f"baked frames {scene.frame_start}..{scene.frame_end}: engine {result.engine_seconds:.2f} s, "
          f"Blender {result.blender_seconds:.2f} s -> " + ", ".join(result.saved.values()))

    setup_render(scene, args.resolution, args.samples)
    if args.no_render:
        frames = []
    elif args.render is not None:
        frames = args.render
    else:
        frames = sorted({scene.frame_start + round(i * (args.frames - 1) / 3) for i in range(4)})
    for frame in frames:
        scene.frame_set(frame)
        scene.render.filepath = str(out / f"frame_{frame:03d}.png")
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        print(f"rendered {scene.render.filepath} ({time.perf_counter() - t0:.1f} s, Cycles CPU, "
              f"{args.samples} samples, {args.resolution[0]}x{args.resolution[1]})")
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    print(f"saved {blend}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
