"""Headless use: `blender --background FILE.blend --command hemishadow ...`.

Registered with `bpy.utils.register_cli_command("hemishadow", main)`; Blender calls
`main(argv)` with the arguments after the command id and exits with its return value:
0 on success, 1 when the work failed, 2 for a bad command line (as argparse does), 130 when
cancelled with Ctrl-C (nothing saved).

Progress goes to stderr as in the engine's own command line (`hemishadow.cli.ProgressBar`): a
bar redrawn in place on a terminal, a line per 10 % otherwise; `compute` shows the engine's
progress through the vertices, `bake` the frames (and the vertices within them).
"""

from __future__ import annotations

import argparse
import sys
import time

import bpy

__all__ = ["main", "register", "unregister"]

PROG = "blender --background FILE.blend --command hemishadow"


class UsageError(Exception):
    """A command line that cannot be run: exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise UsageError(f"{self.prog}: error: {message}")

    def exit(self, status=0, message=None):
        if message:
            (sys.stderr if status else sys.stdout).write(message)
        raise SystemExit(status)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, formatter_class=argparse.RawDescriptionHelpFormatter, description=(
        "Soft self-shadowing from environment lighting for the mesh objects of the open .blend file.\n"
        "Objects are named with --objects; by default, every object with hemishadow enabled."), epilog=(
        "examples:\n"
        "  ... compute --frame 12 --objects Cloth --save\n"
        "  ... bake --start 1 --end 120               (caches in //hemishadow_cache/)\n"
        "  ... bake --pack                            (caches inside the .blend, saved)\n"
        "  ... bake --help\n"
        "progress goes to stderr; Ctrl-C cancels and saves nothing\n"
        "exit codes: 0 done, 1 the work failed, 2 bad command line, 130 cancelled"))
    commands = parser.add_subparsers(dest="command", metavar="{compute,bake,lightmaps,probes,panorama}",
                                     parser_class=_Parser)

    compute = commands.add_parser("compute", help="compute one frame into the attributes",
                                  description="Compute one frame into the attributes hemishadow_radiance and "
                                              "hemishadow_ao of each object.")
    compute.add_argument("--frame", type=int, help="frame to compute (default: the scene's current frame)")
    _add_common(compute)

    bake = commands.add_parser("bake", help="bake a frame range into per-object caches",
                               description="Compute a frame range into a cache per object, beside the .blend "
                                           "(//hemishadow_cache/<object>.npz) or packed into it.")
    bake.add_argument("--start", type=int, help="first frame (default: the scene's start)")
    bake.add_argument("--end", type=int, help="last frame (default: the scene's end)")
    where = bake.add_mutually_exclusive_group()
    where.add_argument("--cache-dir", metavar="DIR",
                       help="folder of the cache files; `//` is the .blend's folder (default: //hemishadow_cache)")
    where.add_argument("--pack", action="store_true", help="pack the caches into the .blend (implies saving it)")
    bake.add_argument("--no-transfer", action="store_true",
                      help="store only radiance and AO, not the transfer vectors (smaller; lighting is then fixed)")
    _add_common(bake)
    from . import lightmaps_cli

    lightmaps_cli.add_parser(commands)
    from . import probes_cli

    probes_cli.add_parser(commands)
    from . import panorama_cli

    panorama_cli.add_parser(commands)
    return parser


def _add_common(parser):
    parser.add_argument("--objects", nargs="+", metavar="NAME",
                        help="mesh objects to compute (they get hemishadow enabled); default: all enabled")
    parser.add_argument("--save", action="store_true", help="save the .blend file afterwards")
    parser.add_argument("--scene", metavar="NAME", help="scene to use (default: the active scene)")


def main(argv) -> int:
    """The `hemishadow` command: run it with the arguments after the command id."""
    parser = build_parser()
    try:
        args = parser.parse_args(list(argv))
        if args.command is None:
            raise UsageError(f"{PROG}: error: a command is needed: compute or bake (see --help)")
        scene = _scene(args.scene)
        if args.command == "lightmaps":
            return _lightmaps(scene, args)
        if args.command in ("probes", "panorama"):
            return _baker(scene, args)
        objects = _objects(scene, args.objects)
        run = _compute if args.command == "compute" else _bake
        if not run(scene, objects, args):
            print("hemishadow: cancelled (Ctrl-C): nothing saved", file=sys.stderr)
            return 130
        if args.save or getattr(args, "pack", False):
            _save()
    except SystemExit as stop:          # --help, --version
        return int(stop.code or 0)
    except KeyboardInterrupt:           # Ctrl-C outside the engine's work
        print("hemishadow: cancelled (Ctrl-C): nothing saved", file=sys.stderr)
        return 130
    except UsageError as error:
        print(error, file=sys.stderr)
        return 2
    except (ValueError, RuntimeError, OSError, KeyError) as error:
        print(f"hemishadow: error: {error}", file=sys.stderr)
        return 1
    return 0


def _scene(name):
    if name is None:
        return bpy.context.scene
    scene = bpy.data.scenes.get(name)
    if scene is None:
        raise UsageError(f"{PROG}: error: no scene named {name!r}; scenes: {', '.join(bpy.data.scenes.keys())}")
    return scene


def _objects(scene, names):
    if not names:
        from . import engine_bridge

        objects = engine_bridge.enabled_objects(scene)  # one per mesh: linked duplicates share a result
        if not objects:
            raise UsageError(f"{PROG}: error: no object has hemishadow enabled: name them with --objects")
        return objects
    objects = []
    for name in names:
        obj = scene.objects.get(name)
        if obj is None or obj.type != "MESH":
            meshes = ", ".join(o.name for o in scene.objects if o.type == "MESH") or "none"
            what = "no object" if obj is None else f"{obj.type.lower()} object, not a mesh:"
            raise UsageError(f"{PROG}: error: {what} {name!r} in scene {scene.name!r}; mesh objects: {meshes}")
        obj.hemishadow.enabled = True
        objects.append(obj)
    return objects


def _named(name, message):
    """The message, with the object's name in front unless it starts with it already."""
    return message if message.startswith(f"{name}:") else f"{name}: {message}"


def _progress_bar(label):
    from hemishadow.cli import ProgressBar, cancel_on_ctrl_c

    bar = ProgressBar(label)
    return bar, cancel_on_ctrl_c(bar.interrupted)


def _compute(scene, objects, args) -> bool:
    """Returns False when cancelled."""
    import hemishadow

    from . import cache, engine_bridge

    frame = scene.frame_current if args.frame is None else args.frame
    t0 = time.perf_counter()
    with cache.baking():                 # step without the live handlers, then compute once
        scene.frame_set(frame)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    engine_bridge.last_timings.clear()
    bar, interrupts = _progress_bar("compute")
    with interrupts:
        try:
            bar(0.0)
            errors = engine_bridge.update_scene(scene, depsgraph, objects, force=True, progress=bar)
        except hemishadow.Cancelled:
            return False
        finally:
            bar.close()
    if bar.interrupted.is_set():
        return False
    for obj in objects:
        if obj.name in errors:
            continue
        count, io_seconds, engine_seconds = engine_bridge.last_timings[obj.name]
        print(f"hemishadow: {obj.name}: frame {frame}: {count} vertices, engine {engine_seconds * 1e3:.1f} ms, "
              f"Blender I/O {io_seconds * 1e3:.1f} ms")
    if errors:
        raise RuntimeError("; ".join(_named(name, message) for name, message in errors.items()))
    print(f"hemishadow: computed {len(objects)} object(s) in {(time.perf_counter() - t0):.2f} s")
    return True


def _bake(scene, objects, args) -> bool:
    """Returns False when cancelled."""
    from .operators.bake import bake_range

    start = scene.frame_start if args.start is None else args.start
    end = scene.frame_end if args.end is None else args.end
    if end < start:
        raise UsageError(f"{PROG}: error: --end {end} is before --start {start}")
    count = end - start + 1
    bar, interrupts = _progress_bar("bake")
    t0 = time.perf_counter()
    with interrupts:
        try:
            result = bake_range(scene, objects, start, end, fraction=bar, cancel=bar.interrupted,
                                location="PACKED" if args.pack else "FILE", directory=args.cache_dir,
                                store_transfer=not args.no_transfer)
        finally:
            bar.close()
    if result.cancelled:
        return False
    for name, where in result.saved.items():
        print(f"hemishadow: {name}: frames {start}..{end} -> {where}")
    print(f"hemishadow: baked {count} frames of {len(objects)} object(s) in {time.perf_counter() - t0:.2f} s "
          f"(engine {result.engine_seconds:.2f} s, Blender {result.blender_seconds:.2f} s)")
    return True


def _lightmaps(scene, args) -> int:
    import hemishadow

    from . import lightmaps_cli

    found = lightmaps_cli.objects(scene, args, lambda m: UsageError(f"{PROG}: error: {m}"))
    bar, interrupts = _progress_bar("lightmaps")
    with interrupts:
        try:
            lightmaps_cli.run(scene, found, args, bar)
        except hemishadow.Cancelled:
            print("hemishadow: cancelled (Ctrl-C): nothing written", file=sys.stderr)
            return 130
        finally:
            bar.close()
    return 0


def _baker(scene, args) -> int:
    """A baker's subcommand (probes_cli, panorama_cli): its `run` with a progress bar."""
    import importlib

    import hemishadow

    module = importlib.import_module(f"{__package__}.{args.command}_cli")
    bar, interrupts = _progress_bar(args.command)
    with interrupts:
        try:
            module.run(scene, args, lambda m: UsageError(f"{PROG}: error: {m}"), bar)
        except hemishadow.Cancelled:
            print("hemishadow: cancelled (Ctrl-C): nothing written", file=sys.stderr)
            return 130
        finally:
            bar.close()
    return 0


def _save():
    if not bpy.data.filepath:
        raise ValueError("the .blend file has never been saved, so --save has nowhere to write")
    bpy.ops.wm.save_mainfile()
    print(f"hemishadow: saved {bpy.data.filepath}")


_handle = None


def register():
    global _handle
    _handle = bpy.utils.register_cli_command("hemishadow", main)


def unregister():
    global _handle
    if _handle is not None:
        bpy.utils.unregister_cli_command(_handle)
        _handle = None
