"""The probe demo (issue 12): a character walks from the sun into the shade of a wall, lit live
by a baked probe grid, and keeps its own soft shadows.

    .venv/bin/python scripts/demo_probes.py            # `make demo-probes`
    .venv/bin/python scripts/demo_probes.py --source   # this checkout's add-on, no zip

Steps, through the add-on's operators as a user would click them:
1. installs the extension zip into a project-local user folder (as scripts/demo_blender.py);
2. builds the lightmap demo's room corner (scripts/demo_lightmaps.py: floor, two walls, a box,
   Blender's HDRI and a sun) and a Light Probe Volume over it; Bake Probes (2 bounces);
3. imports the shared Cesium Man (skinned, walking), enables it with the probe volume as its
   Probe Lighting and the add-on's one-click material, and moves it from the sunlit front of
   the room into the back wall's shadow;
4. with Live on, renders a frame in the sun and one in the shade with Cycles and writes
   out/demo_probes/side_by_side.png; prints the character's mean radiance in both.
"""

import math
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "scripts"))
import demo_blender  # noqa: E402  (installing the zip, render settings)
import demo_lightmaps  # noqa: E402  (the room corner, rendering, side by side)

CHARACTER = ROOT.parent / "shared" / "data" / "cesium_man.glb"
SUN, SHADE = (1, 24)  # frames: in the sun at the front, in the back wall's shadow


def parse_args(argv=None):
    parser = demo_blender.demo_parser(__doc__, "demo_probes")
    parser.add_argument("--hdri", default="forest", help="one of Blender's built-in HDRIs (default forest)")
    parser.add_argument("--bounces", type=int, default=2, help="diffuse bounces of the probes (default 2)")
    parser.add_argument("--resolution", type=int, nargs=2, default=(480, 360), metavar=("X", "Y"))
    parser.add_argument("--samples", type=int, default=16, help="Cycles samples (default 16)")
    parser.add_argument("--no-render", action="store_true", help="render nothing (a quick check)")
    return parser.parse_args(argv)


def add_volume(scene):
    """A Light Probe Volume over the room corner: 4 x 4 m, 2.5 m high, 6 x 6 x 3 probes."""
    import bpy

    bpy.ops.object.add(type="LIGHT_PROBE", location=(0.0, 0.0, 1.25))
    volume = bpy.context.object
    if volume.data.type != "VOLUME":
        volume.data = bpy.data.lightprobes.new("Probes", "VOLUME")
    volume.name = "Probes"
    volume.scale = (2.0, 2.0, 1.25)
    volume.data.resolution_x, volume.data.resolution_y, volume.data.resolution_z = 6, 6, 3
    bpy.context.view_layer.update()
    return volume


def add_character(scene, volume):
    """Cesium Man, enabled and lit by the probes, walking from the front into the shade."""
    import bpy

    bpy.ops.import_scene.gltf(filepath=str(CHARACTER))
    body = next(o for o in scene.objects if o.type == "MESH" and o.find_armature())
    root = body.find_armature()
    while root.parent is not None:  # the importer's Z_UP empty: its location is in world space
        root = root.parent
    root.rotation_euler.z = math.radians(135)  # facing the way it goes
    for frame, where in ((SUN, (1.2, -1.2, 0.0)), (SHADE, (-1.5, 1.3, 0.0))):
        root.location = where
        root.keyframe_insert("location", frame=frame)
    body.hemishadow.enabled = True
    body.hemishadow.probe_volume = volume
    bpy.context.view_layer.objects.active = body
    body.select_set(True)
    assert bpy.ops.hemishadow.add_material(mode="EMIT") == {"FINISHED"}
    scene.frame_start, scene.frame_end = SUN, SHADE
    return body


def main(argv=None):
    args = parse_args(argv)
    out = pathlib.Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    user, site = demo_blender.prepare_user_resources(args.user_resources)
    import bpy

    demo_blender.use_addon(args.source, args.zip, site)
    scene, _ = demo_lightmaps.build_scene(args.hdri)
    volume = add_volume(scene)
    bpy.context.view_layer.objects.active = volume
    t0 = time.perf_counter()
    assert bpy.ops.hemishadow.bake_probes(bounces=args.bounces, filepath=str(out / "probes.npz")) == {"FINISHED"}
    print(f"baked {volume.data.resolution_x * volume.data.resolution_y * volume.data.resolution_z} probes "
          f"({args.bounces} bounces) in {time.perf_counter() - t0:.1f} s -> {out / 'probes.npz'}")
    body = add_character(scene, volume)
    demo_blender.setup_render(scene, args.resolution, args.samples)
    scene.view_settings.exposure = -2.0
    scene.frame_set(SUN)
    scene.hemishadow.live = True
    frames = {}
    for frame in (SUN, SHADE):
        scene.frame_set(frame)
        radiance = np.empty(len(body.data.vertices) * 4, np.float32)
        body.data.attributes["hemishadow_radiance"].data.foreach_get("color", radiance)
        frames[frame] = radiance.reshape(-1, 4)[:, :3].mean(axis=0)
        print(f"frame {frame}: the character's mean radiance {np.round(frames[frame], 3).tolist()} "
              f"({body.hemishadow.status})")
        if not args.no_render:
            path = out / f"frame_{frame:03d}.png"
            print(f"  rendered {path} in {demo_lightmaps.render(scene, path, args.samples):.1f} s")
    if not args.no_render:
        demo_lightmaps.side_by_side(out / f"frame_{SUN:03d}.png", out / f"frame_{SHADE:03d}.png",
                                    out / "side_by_side.png")
        print(f"wrote {out / 'side_by_side.png'}")
    bpy.ops.wm.save_as_mainfile(filepath=str(out / "demo_probes.blend"))
    ratio = frames[SHADE].mean() / frames[SUN].mean()
    print(f"in the shade the character gets {ratio:.2f} x the light it gets in the sun")


if __name__ == "__main__":
    main()
