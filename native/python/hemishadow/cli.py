"""Command-line entry point: `python -m hemishadow transfer MESH --env EXR ...`.

The transfer is computed by `TransferSolver` (built from the mesh, solved once), with a
progress bar on stderr: redrawn in place (`\r[#####.........] 35 %`) when stderr is a
terminal, one line per 10 % otherwise (logs, pipes). Ctrl-C cancels: the solve stops between
chunks of vertices, nothing is written, and the exit code is 130.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import signal
import sys
import threading
import time

import numpy as np

ALBEDO = 0.8  # grey, like Blender's default material

# Files whose format defines +Y as up; Blender's importers turn them to +Z up with
# (x, y, z) -> (x, -z, y), and lighting follows Blender's +Z-up world.
_Y_UP_EXTENSIONS = {".obj", ".gltf", ".glb"}
_Y_UP_TO_Z_UP = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=np.float32)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hemishadow",
        description="Soft self-shadowing from environment lighting by hemispherical rasterization.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_serve_parser(sub)
    t = sub.add_parser(
        "transfer", help="compute per-vertex SH transfer of a mesh and shade it with an HDRI",
        description="Compute per-vertex spherical-harmonic transfer vectors (self-shadowed "
                    "diffuse) of MESH, light it with an equirectangular EXR, and write a "
                    "vertex-colored mesh (.glb or .ply) and an .npz with the arrays.")
    t.add_argument("mesh", metavar="MESH", help="mesh file (OBJ, PLY, glTF/GLB, ...)")
    t.add_argument("--env", metavar="EXR",
                   help="equirectangular environment map (default: Blender's 'forest' HDRI "
                        "from the bpy module)")
    t.add_argument("--bands", type=int, choices=(9, 16, 25), default=25,
                   help="number of SH coefficients (default: 25)")
    t.add_argument("--out", metavar="PATH",
                   help="output path without extension, or ending in .glb or .ply "
                        "(default: out/<mesh name>); the .npz goes beside it")
    t.add_argument("--intensity", type=float, default=1.0,
                   help="scale applied to the environment's radiance (default: 1.0)")
    t.add_argument("--up", choices=("auto", "y", "z"), default="auto",
                   help="the file's up axis; auto = y for OBJ and glTF, z otherwise. "
                        "Lighting is computed in Blender's +Z-up world; written vertices "
                        "stay as in the input file")
    _add_panorama_commands(sub)
    _add_farm(sub)
    return parser


def _add_serve_parser(sub) -> None:
    s = sub.add_parser(
        "serve", help="relight a compact panorama in the web viewer",
        description="Serve the web viewer and a compact panorama (the panorama.json written by "
                    "Panorama.save) on 127.0.0.1 and open it in a browser.")
    s.add_argument("panorama", metavar="PANORAMA.json", help="the compact panorama's JSON")
    s.add_argument("--port", type=int, default=8765, help="port (default: 8765; 0 picks a free one)")
    s.add_argument("--no-browser", action="store_true", help="do not open a browser")


def run_serve(args) -> int:
    import webbrowser

    from .panorama.server import make_server

    try:
        server = make_server(args.panorama, args.port)
    except OSError as exc:
        raise OSError(f"cannot serve on 127.0.0.1:{args.port} ({exc.strerror}); pick another with --port") from None
    url = "http://%s:%d/" % server.server_address[:2]
    print(f"serving {args.panorama} at {url} (Ctrl-C stops)", flush=True)
    if not args.no_browser:
        webbrowser.open(url)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        print("stopped")
    finally:
        server.server_close()
    return 0


def _triple_list(text: str, count: int, what: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{what} must be {count} comma-separated numbers, got {text!r}")
    return values


def _add_panorama_commands(sub) -> None:
    """`relight` and `panorama` (issue 13): relightable panoramas without Blender."""
    r = sub.add_parser(
        "relight", help="relight a baked panorama with suns, point lights and an environment",
        description="Relight a panorama baked by `hemishadow panorama` (or Blender's panorama bake): "
                    "lights are summed; OUT.exr is linear radiance, OUT.png sRGB (Blender's Standard view).")
    r.add_argument("panorama", metavar="FILE", help="panorama .exr, or the compact form's .json")
    r.add_argument("--sun", action="append", default=[], metavar="X,Y,Z,STRENGTH",
                   help="a sun: direction towards the light, strength in W/m^2 as in Blender (repeatable)")
    r.add_argument("--point", action="append", default=[], metavar="X,Y,Z,POWER",
                   help="a point lamp at X,Y,Z of POWER watts as in Blender (repeatable)")
    r.add_argument("--env", metavar="EXR[,STRENGTH]", help="an equirectangular environment (World HDRI)")
    r.add_argument("--env-rotation", type=float, default=0.0, metavar="DEG",
                   help="the environment's rotation about Z in degrees (the World's Mapping node)")
    r.add_argument("--exposure", type=float, default=0.0, metavar="EV", help="exposure in stops (default 0)")
    r.add_argument("--maps", choices=("8bit", "float16"),
                   help="the maps to read (default: 8bit for a .json, float16 for an .exr)")
    r.add_argument("--out", required=True, metavar="OUT", help="OUT.exr (linear) or OUT.png (sRGB)")
    p = sub.add_parser(
        "panorama", help="bake a relightable panorama of a mesh from a viewpoint",
        description="Bake a relightable panorama of MESH seen from --at: per pixel, SH coefficients of "
                    "its response to light (albedo 0.8). FILE.exr holds float maps, FILE.json the compact "
                    "8-bit form (a folder of PNG maps).")
    p.add_argument("mesh", metavar="MESH", help="mesh file (OBJ, PLY, glTF/GLB, ...)")
    p.add_argument("--at", required=True, metavar="X,Y,Z", help="the viewpoint (world, +Z up)")
    p.add_argument("--size", default="1024x512", metavar="WxH", help="panorama size (default 1024x512)")
    p.add_argument("--coefficients", type=int, choices=(9, 16, 25), default=16,
                   help="SH coefficients per pixel (default 16)")
    p.add_argument("--up", choices=("auto", "y", "z"), default="auto",
                   help="the file's up axis; auto = y for OBJ and glTF, z otherwise")
    p.add_argument("--out", required=True, metavar="FILE", help="FILE.exr or FILE.json")


def run_relight(args) -> int:
    from . import panorama as pano
    from .panorama import picture

    panorama = pano.Panorama.load(args.panorama)
    lights = [pano.Sun(v[:3], v[3]) for v in (_triple_list(s, 4, "--sun") for s in args.sun)]
    lights += [pano.Point(v[:3], v[3]) for v in (_triple_list(s, 4, "--point") for s in args.point)]
    background = None
    if args.env:
        import hemishadow
        from .environment import read_exr
        from .sh import euler_to_matrix

        path, _, strength = args.env.partition(",")
        strength = _triple_list(strength, 1, "--env strength")[0] if strength else 1.0
        image = read_exr(path)
        mapping = euler_to_matrix((0.0, 0.0, math.radians(args.env_rotation)))
        sh = hemishadow.project_environment(image, bands=panorama.bands, rotation=mapping)
        lights.append(pano.Environment(sh, strength))
        dirs = pano.directions(panorama.width, panorama.height, panorama.rotation)
        background = picture.sample_equirectangular(image, dirs, mapping) * np.float32(strength)
    if not lights:
        raise ValueError("no light: give --sun, --point or --env")
    start = time.perf_counter()
    image = pano.relight(panorama, lights, exposure=args.exposure, background=background, maps=args.maps)
    elapsed = (time.perf_counter() - start) * 1000.0
    picture.write(args.out, image)
    print(f"panorama: {panorama.width} x {panorama.height}, {panorama.coefficient_count} coefficients")
    print(f"relight time: {elapsed:.1f} ms")
    print(f"wrote: {args.out}")
    return 0


def run_panorama(args) -> int:
    import hemishadow
    from . import panorama as pano
    from .meshio import load_mesh

    at = _triple_list(args.at, 3, "--at")
    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        raise ValueError(f"--size must be WxH, e.g. 1024x512, got {args.size!r}") from None
    if os.path.splitext(args.out)[1].lower() not in (".exr", ".json"):
        raise ValueError(f"--out must end in .exr or .json, got {args.out!r}")
    vertices, triangles, _ = load_mesh(args.mesh)
    if _is_y_up(args.mesh, args.up):
        vertices = np.ascontiguousarray(vertices @ _Y_UP_TO_Z_UP.T)
    scene = hemishadow.Scene()
    scene.add_instance(scene.add_mesh(vertices, triangles))
    bar = ProgressBar("panorama")
    with cancel_on_ctrl_c(bar.interrupted):
        start = time.perf_counter()
        try:
            baked = pano.bake(scene, at, size=(width, height), bands=math.isqrt(args.coefficients), progress=bar)
        except hemishadow.Cancelled:
            return _cancelled()
        finally:
            bar.close()
        elapsed = time.perf_counter() - start
        if bar.interrupted.is_set():
            return _cancelled()
        report = baked.save(args.out)
    print(f"triangles: {len(triangles)}")
    print(f"panorama: {width} x {height}, {args.coefficients} coefficients, {int(baked.mask.sum())} pixels hit")
    print(f"bake time: {elapsed:.1f} s")
    print(f"file size: {report['bytes']} bytes")
    if "max_quantization_error" in report:
        print(f"8-bit maps: {report['map_bytes']} bytes, largest quantization error {report['max_quantization_error']:.3g}")
    print(f"wrote: {args.out}")
    return 0


def _add_farm(sub):
    """`farm` (hemishadow.farm.command): listed here, parsed there, as its other options go to the workers."""
    sub.add_parser("farm", add_help=False, help="run a bake, lightmaps, probes or panoramas on a Dask cluster "
                                                "(python -m hemishadow farm --help; docs/farm.md)")


def _output_paths(mesh_path: str, out: str | None) -> tuple[str, str]:
    """(colored mesh path, npz path) from --out."""
    if out is None:
        out = os.path.join("out", os.path.splitext(os.path.basename(mesh_path))[0])
    stem, ext = os.path.splitext(out)
    if ext.lower() not in (".glb", ".ply"):
        stem, ext = out, ".glb"
    return stem + ext, stem + ".npz"


class ProgressBar:
    """A progress callback for the engine (fraction done, 0..1) that draws on `stream`: a bar
    redrawn in place on a terminal, else a line each time another `step` (10 %) is reached. Returns False, which
    cancels the engine's work, once `interrupted` is set (by Ctrl-C, see `cancel_on_ctrl_c`)."""

    def __init__(self, label: str, stream=None, width: int = 30, step: int = 10):
        self.label, self.stream, self.width, self.step = label, stream or sys.stderr, width, step
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.interrupted = threading.Event()
        self._shown = -1

    def __call__(self, fraction: float) -> bool:
        if self.interrupted.is_set():
            return False
        percent = int(min(max(float(fraction), 0.0), 1.0) * 100)
        if percent < self._shown:   # a new pass (the next object): start over
            self.close()
            self._shown = -1
        if self.tty and percent != self._shown:
            filled = percent * self.width // 100
            self.stream.write(f"\r{self.label} [{'#' * filled}{'.' * (self.width - filled)}] {percent:3d} %")
            self.stream.flush()
            self._shown = percent
        elif not self.tty and percent // self.step > self._shown // self.step:
            self.stream.write(f"{self.label}: {percent} %\n")
            self.stream.flush()
            self._shown = percent
        return True

    def close(self) -> None:
        """End the bar's line on a terminal (after the work, done or not)."""
        if self.tty and self._shown >= 0:
            self.stream.write("\n")
            self.stream.flush()
            self._shown = -1


@contextlib.contextmanager
def cancel_on_ctrl_c(flag: threading.Event):
    """While inside, Ctrl-C sets `flag` instead of raising KeyboardInterrupt anywhere: the
    engine's progress callback sees it and cancels between chunks, and a write in progress is
    finished (callers check the flag after). Outside the main thread nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return
    previous = signal.signal(signal.SIGINT, lambda *_: flag.set())
    try:
        yield flag
    finally:
        signal.signal(signal.SIGINT, previous)


def _is_y_up(mesh_path: str, up: str) -> bool:
    if up != "auto":
        return up == "y"
    return os.path.splitext(mesh_path)[1].lower() in _Y_UP_EXTENSIONS


def run_transfer(args) -> int:
    import hemishadow
    from .environment import default_hdri
    from .meshio import colored_mesh_bytes, load_mesh, npz_bytes, write_files

    if not math.isfinite(args.intensity) or args.intensity < 0:
        raise ValueError(f"--intensity must be a non-negative number, got {args.intensity}")
    mesh_out, npz_out = _output_paths(args.mesh, args.out)
    bands = math.isqrt(args.bands)
    vertices, triangles, normals = load_mesh(args.mesh)
    world_v, world_n = vertices, normals
    if _is_y_up(args.mesh, args.up):
        world_v = np.ascontiguousarray(vertices @ _Y_UP_TO_Z_UP.T)
        world_n = None if normals is None else np.ascontiguousarray(normals @ _Y_UP_TO_Z_UP.T)
    env = args.env if args.env is not None else default_hdri()
    lighting = hemishadow.project_environment(os.fspath(env), bands=bands)
    lighting = (np.asarray(lighting, dtype=np.float32) * np.float32(args.intensity))

    bar = ProgressBar("transfer")
    with cancel_on_ctrl_c(bar.interrupted):
        start = time.perf_counter()
        bar(0.0)   # building the solver takes a while on large meshes, without progress of its own
        try:
            solver = hemishadow.TransferSolver(world_v, triangles, bands=bands)
            transfer = solver.solve(world_v, world_n, progress=bar) if not bar.interrupted.is_set() else None
        except hemishadow.Cancelled:
            transfer = None
        finally:
            bar.close()
        if transfer is None:
            return _cancelled()
        elapsed_ms = (time.perf_counter() - start) * 1000.0

        albedo = np.full((len(vertices), 3), ALBEDO, dtype=np.float32)
        radiance = hemishadow.shade(transfer, lighting, albedo)
        ao = np.asarray(hemishadow.ambient_occlusion(transfer))
        files = {mesh_out: colored_mesh_bytes(mesh_out, vertices, triangles, radiance),
                 npz_out: npz_bytes(transfer=transfer, radiance=radiance, ambient_occlusion=ao, lighting=lighting)}
        if bar.interrupted.is_set():
            return _cancelled()
        write_files(files)   # not interrupted: both files or none

    print(f"vertices: {len(vertices)}")
    print(f"triangles: {len(triangles)}")
    print(f"transfer time: {elapsed_ms:.1f} ms")
    print(f"ambient occlusion min: {ao.min():.4f}")
    print(f"ambient occlusion mean: {ao.mean():.4f}")
    print(f"ambient occlusion median: {np.median(ao):.4f}")
    print(f"ambient occlusion max: {ao.max():.4f}")
    print(f"wrote: {mesh_out}")
    print(f"wrote: {npz_out}")
    return 0


def _cancelled() -> int:
    print("hemishadow: cancelled (Ctrl-C): nothing written", file=sys.stderr)
    return 130


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["farm"]:
        from .farm.command import main as farm

        return farm(argv[1:])
    args = _parser().parse_args(argv)
    try:
        if args.command == "serve":
            return run_serve(args)
        if args.command == "transfer":
            return run_transfer(args)
        if args.command in ("relight", "panorama"):
            return {"relight": run_relight, "panorama": run_panorama}[args.command](args)
    except KeyboardInterrupt:   # Ctrl-C while loading the mesh or the environment
        return _cancelled()
    except Exception as exc:  # a tool for people: one clear line, no traceback
        print(f"hemishadow: error: {exc}", file=sys.stderr)
        return 2
    return 0
