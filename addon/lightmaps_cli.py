"""`blender -b FILE --command hemishadow lightmaps ...`: the lightmap bake from the command
line (issue 11). cli.py registers the subcommand; the work is lightmaps.bake_lightmaps."""

import sys
import time
import warnings

from . import lightmap_atlas, lightmaps


def add_parser(commands):
    p = commands.add_parser(
        "lightmaps", help="bake directional lightmaps of mesh objects to EXR files",
        description="Bake lightmaps (flat, HL2 basis or L1 SH, ao, coverage) of mesh objects to DIR/<object>.exr, "
                    "in the units of Cycles' Diffuse bake (irradiance / pi; docs/lightmaps.md).")
    p.add_argument("--objects", nargs="+", metavar="NAME", help="mesh objects to bake (default: the selected ones)")
    p.add_argument("--collection", metavar="NAME", help="bake the mesh objects of this collection")
    p.add_argument("--uv", metavar="NAME",
                   help="UV map placing the texels, used as it is: one DIR/<object>.exr per object (default: "
                        f"{lightmaps.DEFAULT_UV}; several objects without --uv share one atlas)")
    p.add_argument("--per-object", action="store_true",
                   help="one DIR/<object>.exr per object instead of the atlas (several objects)")
    p.add_argument("--atlas", default=lightmap_atlas.DEFAULT_ATLAS, metavar="NAME",
                   help="several objects (the default without --uv): one DIR/NAME.exr, the objects' islands "
                        f"(from {lightmaps.DEFAULT_UV!r}, else Lightmap Pack) packed at one texel density into "
                        f"the bake's own UV map {lightmap_atlas.ATLAS_UV!r} (default: %(default)s)")
    p.add_argument("--islands", default=lightmaps.DEFAULT_UV, metavar="NAME",
                   help="for an atlas: the UV map whose islands it packs (default: %(default)s)")
    size = p.add_mutually_exclusive_group()
    size.add_argument("--resolution", type=int, default=256, metavar="PX", help="texels per side (default: 256)")
    size.add_argument("--texel-density", type=float, metavar="PER_M",
                      help="texels per metre of surface instead of --resolution: per object, "
                           "density x sqrt(world area / lightmap UV area), a multiple of 4 in "
                           f"[{lightmaps.MIN_RESOLUTION}, {lightmaps.MAX_RESOLUTION}]")
    p.add_argument("--basis", choices=("hl2", "sh", "flat"), default="hl2",
                   help="hl2: flat, b0-b2, ao; sh: flat, sh0-sh3, ao; flat: flat, ao (default: hl2)")
    p.add_argument("--bounces", type=int, default=2, metavar="N", help="diffuse bounces, 0 = direct only (default: 2)")
    p.add_argument("--samples", type=int, default=4, metavar="N", help="supersamples per texel, in total (default: 4)")
    p.add_argument("--uniform", action="store_true",
                   help="all samples in every texel (default: adaptive, all samples only where a texel's light "
                        "departs from its neighbours', one at its centre elsewhere)")
    p.add_argument("--margin", type=int, default=2, metavar="PX", help="padding around islands (default: 2)")
    p.add_argument("--out", metavar="DIR", help="folder of the EXR files (default: //lightmaps beside the .blend)")
    p.add_argument("--scene", metavar="NAME", help="scene to use (default: the active scene)")
    return p


def objects(scene, args, usage_error):
    if args.collection:
        import bpy

        collection = bpy.data.collections.get(args.collection)
        if collection is None:
            raise usage_error(f"no collection named {args.collection!r}")
        found = [o for o in collection.all_objects if o.type == "MESH"]
    elif args.objects:
        found = []
        for name in args.objects:
            obj = scene.objects.get(name)
            if obj is None or obj.type != "MESH":
                meshes = ", ".join(o.name for o in scene.objects if o.type == "MESH") or "none"
                raise usage_error(f"no mesh object named {name!r} in scene {scene.name!r}; mesh objects: {meshes}")
            found.append(obj)
    else:
        found = [o for o in scene.objects if o.type == "MESH" and o.select_get()]
    if not found:
        raise usage_error("no mesh object to bake: name them with --objects or --collection")
    return found


def run(scene, found, args, progress):
    """Bakes; prints what was written. Raises hemishadow.Cancelled when progress says so."""
    if args.out is None and not __import__("bpy").data.filepath:
        raise ValueError("the .blend file has never been saved: give --out DIR")
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        layout = "OBJECT" if args.per_object or args.uv is not None else "ATLAS"
        written = lightmaps.bake_lightmaps(scene, found, uv_name=args.uv or args.islands,
                                           layout=layout, atlas_name=args.atlas, resolution=args.resolution,
                                           texel_density=args.texel_density, basis=args.basis, bounces=args.bounces,
                                           samples=args.samples, adaptive=not args.uniform, margin=args.margin,
                                           out_dir=args.out,
                                           progress=progress, images=False)
    for warning in caught:
        print(f"hemishadow: warning: {warning.message}", file=sys.stderr)
    for name, path in written.items():
        print(f"hemishadow: {name} -> {path}")
    skipped = lightmaps.unsupported_lamps(scene)
    if skipped:
        print(f"hemishadow: lamps not baked yet (point, spot, area): {', '.join(skipped)}")
    print(f"hemishadow: baked {len(written)} lightmap(s) in {time.perf_counter() - t0:.2f} s")
