"""`blender -b FILE --command hemishadow panorama [--camera NAME | --at X,Y,Z] [--size WxH]
[--coefficients 16] [--bounces N] [--out FILE.exr]`: a relightable panorama from the command
line (issue 13). cli.py registers the subcommand; the work is panorama_bake.bake_panorama."""

import time

import numpy as np

from . import panorama_bake


def add_parser(commands):
    p = commands.add_parser(
        "panorama", help="bake a relightable panorama (SH coefficients per pixel) to FILE.exr",
        description="Bake an equirectangular panorama whose every pixel stores the SH coefficients of its response "
                    "to light from each direction (docs/panoramas.md). Writes FILE.exr and the compact form "
                    "FILE/panorama.json with its 8-bit maps; relight them with `python -m hemishadow relight`.")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--camera", metavar="NAME", help="camera or Empty to bake from (default: the scene camera)")
    where.add_argument("--at", metavar="X,Y,Z", type=_point,
                       help="a point instead: centre column +X, left quarter +Y, top row +Z")
    p.add_argument("--size", metavar="WxH", type=_size, default=(1024, 512), help="pixels (default: 1024x512)")
    p.add_argument("--coefficients", type=int, choices=sorted(panorama_bake.BANDS), default=16,
                   help="SH coefficients per pixel (default: 16)")
    p.add_argument("--bounces", type=int, default=0, metavar="N",
                   help="bounce light under the scene's own lighting, stored apart (default: 0, none)")
    p.add_argument("--out", metavar="FILE.exr", help="output file (default: //panoramas/<camera>.exr)")
    p.add_argument("--scene", metavar="NAME", help="scene to use (default: the active scene)")
    return p


def _point(text):
    import argparse

    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 3 or not np.isfinite(values).all():
        raise argparse.ArgumentTypeError(f"expected X,Y,Z, got {text!r}")
    return values


def _size(text):
    import argparse

    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WxH such as 1024x512, got {text!r}") from None
    return w, h


def run(scene, args, usage_error, progress):
    """Bakes; prints what was written. Raises hemishadow.Cancelled when progress says so."""
    import bpy

    if args.bounces < 0:
        raise usage_error("--bounces must be 0 or more")
    try:
        panorama_bake.checked_size(args.size)
    except ValueError as error:
        raise usage_error(f"--size: {error}") from None
    if args.out is None and not bpy.data.filepath:
        raise ValueError("the .blend file has never been saved: give --out FILE.exr")
    if args.camera is not None and scene.objects.get(args.camera) is None:
        names = ", ".join(o.name for o in scene.objects if o.type in ("CAMERA", "EMPTY")) or "none"
        raise usage_error(f"no camera or Empty named {args.camera!r} in scene {scene.name!r}; there are: {names}")
    t0 = time.perf_counter()
    panorama, paths = panorama_bake.bake_panorama(
        scene, camera=args.camera, at=args.at, size=args.size, coefficients=args.coefficients,
        bounces=args.bounces, out=args.out, progress=progress)
    h, w = panorama.alpha.shape
    print(f"hemishadow: panorama {w} x {h}, {args.coefficients} coefficients, "
          f"{100 * float(panorama.alpha.mean()):.0f} % of pixels on a surface -> {paths[0]}, {paths[1]}")
    print(f"hemishadow: baked in {time.perf_counter() - t0:.2f} s")
