"""`blender -b FILE --command hemishadow probes [--volume NAME | --points FILE.npy] [--bounces N]
[--out FILE.npz]`: the probe bake from the command line (issue 12). cli.py registers the
subcommand; the work is probes.bake_probes."""

import time

import numpy as np

from . import probes


def add_parser(commands):
    p = commands.add_parser(
        "probes", help="bake ambient cubes and SH9 on a probe grid to an .npz file",
        description="Bake ambient cubes (+X, -X, +Y, -Y, +Z, -Z; irradiance / pi) and SH9 of the incident radiance "
                    "at the samples of a Light Probe Volume (or an Empty's bounds) or at given points "
                    "(docs/probes.md). Writes FILE.npz and FILE.json.")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--volume", metavar="NAME", help="Light Probe Volume or Empty (default: the only volume)")
    where.add_argument("--points", metavar="FILE.npy", help="(P, 3) world positions instead of a grid")
    p.add_argument("--resolution", type=int, nargs=3, metavar=("X", "Y", "Z"),
                   help=f"samples of an Empty's grid (default: {' '.join(map(str, probes.EMPTY_RESOLUTION))})")
    p.add_argument("--bounces", type=int, default=2, metavar="N", help="diffuse bounces, 0 = direct only (default: 2)")
    p.add_argument("--out", metavar="FILE.npz", help="output file (default: //probes/<volume>.npz)")
    p.add_argument("--scene", metavar="NAME", help="scene to use (default: the active scene)")
    return p


def target(scene, args, usage_error):
    """(volume object or None, points or None) named by the command line."""
    if args.points:
        try:
            pts = np.load(args.points)
        except (OSError, ValueError) as error:
            raise usage_error(f"cannot read --points {args.points}: {error}") from None
        return None, pts
    volumes = [o for o in scene.objects if o.type == "LIGHT_PROBE" and o.data.type == "VOLUME"]
    if args.volume:
        obj = scene.objects.get(args.volume)
        if obj is None or not (obj in volumes or obj.type == "EMPTY"):
            names = ", ".join(o.name for o in volumes) or "none"
            raise usage_error(f"no Light Probe Volume or Empty named {args.volume!r} in scene {scene.name!r}; "
                              f"volumes: {names}")
        return obj, None
    if len(volumes) != 1:
        raise usage_error(f"scene {scene.name!r} has {len(volumes)} Light Probe Volumes: name one with --volume "
                          "or give --points")
    return volumes[0], None


def run(scene, args, usage_error, progress):
    """Bakes; prints what was written. Raises hemishadow.Cancelled when progress says so."""
    volume, pts = target(scene, args, usage_error)
    if args.bounces < 0:
        raise usage_error("--bounces must be 0 or more")
    if args.resolution is not None and min(args.resolution) < 1:
        raise usage_error(f"--resolution must be at least 1 on every axis, got {' '.join(map(str, args.resolution))}")
    if args.out is None and not __import__("bpy").data.filepath:
        raise ValueError("the .blend file has never been saved: give --out FILE.npz")
    t0 = time.perf_counter()
    result, path = probes.bake_probes(scene, volume, pts, bounces=args.bounces, resolution=args.resolution,
                                      out=args.out, progress=progress, store=False)
    p, bad, moved = len(result["positions"]), int((~result["valid"]).sum()), int(result["moved"].sum())
    print(f"hemishadow: {p} probes ({bad} invalid, left out; {moved} moved out of geometry) -> {path}")
    for note in result["notes"]:
        print(f"hemishadow: note: {note}")
    print(f"hemishadow: baked in {time.perf_counter() - t0:.2f} s")
