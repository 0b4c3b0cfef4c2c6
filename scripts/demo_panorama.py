"""The panorama demo (issue 13): bake a relightable panorama of a small scene once, then relight
it under several lights without the scene, beside Cycles' renders of the same lights.

    .venv/bin/python scripts/demo_panorama.py            # `make demo-panorama`
    .venv/bin/python scripts/demo_panorama.py --source   # this checkout's add-on, no zip

Steps, through the add-on's operators as a user would click them:
1. installs the extension zip into a project-local user folder (as scripts/demo_blender.py);
2. builds bench/panorama_cycles.py's scene (a floor, two boxes, a smooth sphere; a smooth sky
   as the World) and bakes a panorama from a point above the floor (Panorama panel: Point,
   16 coefficients): out/demo_panorama/panorama.exr and panorama/panorama.json (8-bit maps);
3. relights it (Live Relight's settings, Save Relit Image) under the sky, two suns and a point
   lamp: out/demo_panorama/relit_<light>.png; unless --no-render, Cycles renders the same
   panorama under the same lights (direct light, as the bake) and
   out/demo_panorama/vs_cycles_<light>.png shows ours above, Cycles below.
"""

import pathlib
import shutil
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "scripts"))
sys.path.insert(0, str(ROOT / "bench"))
import demo_blender  # noqa: E402  (installing the zip)

LIGHTS = {  # name: (panel light setting, what Cycles gets)
    "sky": "sky",
    "sun_high": ((0.55, -0.35, 0.76), 3.0),
    "sun_low": ((-0.8, 0.45, 0.4), 4.0),
    "point": ((1.2, -1.0, 2.2), 300.0),
}


def parse_args(argv=None):
    parser = demo_blender.demo_parser(__doc__, "demo_panorama")
    parser.add_argument("--size", type=int, nargs=2, default=(512, 256), metavar=("W", "H"))
    parser.add_argument("--samples", type=int, default=64, help="Cycles samples (default 64)")
    parser.add_argument("--no-render", action="store_true", help="no Cycles renders (a quick check)")
    return parser.parse_args(argv)


def light(scene, name, bench):
    """Sets the panel's lights to `name` (lamps in the scene, or the World); returns the lamps
    added, for Cycles and for removal."""
    import bpy

    settings = scene.hemishadow_panorama
    bench.set_world_strength(scene, 1.0 if name == "sky" else 0.0)
    settings.use_world, settings.lights = name == "sky", "LAMPS"
    if name.startswith("sun"):
        direction, strength = LIGHTS[name]
        bench.SUN = direction
        return [bench.add_sun(scene, 0.5, strength)]
    if name == "point":
        position, power = LIGHTS[name]
        bench.POINT = position
        return [bench.add_point(scene, 0.0, power)]
    bpy.context.view_layer.update()
    return []


def main(argv=None):
    args = parse_args(argv)
    out = pathlib.Path(args.out)
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    _, site = demo_blender.prepare_user_resources(args.user_resources)
    import bpy  # after the user folder is set: bpy reads it when imported

    demo_blender.use_addon(args.source, args.zip, site)
    import hemishadow.panorama as hp
    import numpy as np
    import panorama_cycles as bench

    scene = bench.build(out)
    settings = scene.hemishadow_panorama
    settings.source, settings.point = "POINT", bench.ORIGIN
    settings.width, settings.height, settings.coefficients = args.size[0], args.size[1], "16"
    settings.filepath = str(out / "panorama.exr")
    t0 = time.perf_counter()
    assert bpy.ops.hemishadow.bake_panorama() == {"FINISHED"}, "the bake failed (see above)"
    print(f"baked {args.size[0]} x {args.size[1]} x 16 in {time.perf_counter() - t0:.1f} s -> {settings.baked}")
    pano = hp.Panorama.load(settings.baked)
    for name in LIGHTS:
        lamps = light(scene, name, bench)
        path = out / f"relit_{name}.png"
        assert bpy.ops.hemishadow.save_relit_panorama(filepath=str(path)) == {"FINISHED"}
        t0 = time.perf_counter()
        ours = hp.relight(pano, bench.addon().panorama_live.lights(scene))
        print(f"{name}: relit in {1e3 * (time.perf_counter() - t0):.1f} ms -> {path}")
        if not args.no_render:
            ref, seconds = bench.cycles(scene, args.size, args.samples, out)
            ids = np.where(pano.mask, 0, -1)
            rel, nabs = bench.errors(ours, ref, ids)
            print(f"{name}: Cycles {args.samples} spp in {seconds:.0f} s; 4x4 blocks: mean relative error "
                  f"{100 * rel:.1f} %, normalized mean absolute error {100 * nabs:.1f} %")
            bench.write_pictures(out, {name: (ours, ref)})
            (out / f"panorama_vs_cycles_{name}.png").rename(out / f"vs_cycles_{name}.png")
        for lamp in lamps:
            bpy.data.objects.remove(lamp)
    (out / "cycles.exr").unlink(missing_ok=True)


if __name__ == "__main__":
    main()
