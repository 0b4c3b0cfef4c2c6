"""`python -m hemishadow farm bake|lightmaps|probes|panorama FILE.blend --scheduler ADDRESS | --local N
[the subcommand's own options]`: the farm options are parsed here; every other option goes to
the workers, which parse it with the add-on's own parser (`blender -b FILE --command hemishadow
SUBCOMMAND --help` lists them), so the farm takes exactly the headless commands' options.

Exit codes: 0 done, 1 failed (nothing written; also a bad option of the subcommand, which the
workers parse), 2 a bad farm option, 130 cancelled with Ctrl-C (nothing written).
"""

from __future__ import annotations

import argparse
import sys

KINDS = ("bake", "lightmaps", "probes", "panorama")


def parser():
    p = argparse.ArgumentParser(
        prog="python -m hemishadow farm", formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Run a hemishadow bake on a Dask cluster: the same outputs as "
                    "`blender -b FILE --command hemishadow SUBCOMMAND ...` (docs/farm.md).",
        epilog="Other options are the subcommand's own (see `blender -b FILE --command hemishadow SUBCOMMAND "
               "--help`), e.g.\n  python -m hemishadow farm bake shot.blend --local 2 --start 1 --end 240\n"
               "  python -m hemishadow farm lightmaps level.blend --scheduler tls://farm:8786 --objects Room")
    p.add_argument("what", choices=KINDS, metavar="{bake,lightmaps,probes,panorama}", help="the headless subcommand to run")
    p.add_argument("blend", metavar="FILE.blend", help="the saved .blend, as the workers see it (shared path) "
                                                       "unless --send-blend")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="address of a running Dask scheduler (default: tcp://127.0.0.1:8786, loopback)")
    where.add_argument("--local", type=int, metavar="N", help="start a local cluster of N worker processes instead")
    p.add_argument("--worker-mode", choices=("bpy", "subprocess"), default="bpy",
                   help="bpy: workers import bpy and run units in-process (default); subprocess: each unit "
                        "runs in `blender -b` (workers need no bpy, only a Blender with the extension)")
    p.add_argument("--blender", default="blender", metavar="PATH",
                   help="Blender executable on the workers for --worker-mode subprocess (default: blender)")
    p.add_argument("--addon", metavar="DIR",
                   help="checkout holding addon/ on the workers' paths (default: this checkout; 'none': the "
                        "extension installed in the workers' Blender)")
    p.add_argument("--send-blend", action="store_true",
                   help="send the .blend's bytes through the scheduler (no shared path; pack its images first)")
    p.add_argument("--frames-per-unit", type=int, metavar="N", help="bake: frames per work unit (default: auto)")
    p.add_argument("--probes-per-unit", type=int, metavar="N", help="probes: probes per work unit (default: auto)")
    p.add_argument("--cameras", nargs="+", metavar="NAME",
                   help="panorama: one panorama per camera (or Empty), each to //panoramas/<camera>.exr")
    p.add_argument("--timeout", type=float, default=10.0, metavar="S",
                   help="seconds to wait for the scheduler (default: 10)")
    return p


def main(argv) -> int:
    from . import client
    from .merge import MergeError
    from .worker import FarmError

    try:
        args, rest = parser().parse_known_args(list(argv))
    except SystemExit as stop:
        return int(stop.code or 0)
    if args.local is not None and args.local < 1:
        print("python -m hemishadow farm: error: --local needs at least 1 worker", file=sys.stderr)
        return 2
    addon = client.default_addon_dir() if args.addon is None else (None if args.addon == "none" else args.addon)
    try:
        job = client.Job(args.what, args.blend, rest, addon=addon, worker_mode=args.worker_mode,
                         blender=args.blender, send_blend=args.send_blend, frames_per_unit=args.frames_per_unit,
                         probes_per_unit=args.probes_per_unit, cameras=args.cameras)
        client.run_job(job, args.scheduler, args.local, args.timeout)
    except KeyboardInterrupt:
        print("hemishadow farm: cancelled (Ctrl-C): queued units removed, nothing written", file=sys.stderr)
        return 130
    except (FarmError, MergeError, OSError, ValueError) as error:
        print(f"hemishadow farm: error: {error}", file=sys.stderr)
        return 1
    return 0
