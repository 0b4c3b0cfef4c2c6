"""Command-line entry point: `python -m hemishadow transfer MESH --env EXR ...`."""

from __future__ import annotations

import argparse
import math
import os
import sys
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
    return parser


def _output_paths(mesh_path: str, out: str | None) -> tuple[str, str]:
    """(colored mesh path, npz path) from --out."""
    if out is None:
        out = os.path.join("out", os.path.splitext(os.path.basename(mesh_path))[0])
    stem, ext = os.path.splitext(out)
    if ext.lower() not in (".glb", ".ply"):
        stem, ext = out, ".glb"
    return stem + ext, stem + ".npz"


def _is_y_up(mesh_path: str, up: str) -> bool:
    if up != "auto":
        return up == "y"
    return os.path.splitext(mesh_path)[1].lower() in _Y_UP_EXTENSIONS


def run_transfer(args) -> None:
    import hemishadow
    from .environment import default_hdri
    from .meshio import load_mesh, save_colored_mesh, save_npz

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

    start = time.perf_counter()
    transfer = hemishadow.transfer(world_v, triangles, world_n, bands=bands)
    elapsed_ms = (time.perf_counter() - start) * 1000.0

    albedo = np.full((len(vertices), 3), ALBEDO, dtype=np.float32)
    radiance = hemishadow.shade(transfer, lighting, albedo)
    ao = np.asarray(hemishadow.ambient_occlusion(transfer))

    save_colored_mesh(mesh_out, vertices, triangles, radiance)
    save_npz(npz_out, transfer=transfer, radiance=radiance, ambient_occlusion=ao, lighting=lighting)

    print(f"vertices: {len(vertices)}")
    print(f"triangles: {len(triangles)}")
    print(f"transfer time: {elapsed_ms:.1f} ms")
    print(f"ambient occlusion min: {ao.min():.4f}")
    print(f"ambient occlusion mean: {ao.mean():.4f}")
    print(f"ambient occlusion median: {np.median(ao):.4f}")
    print(f"ambient occlusion max: {ao.max():.4f}")
    print(f"wrote: {mesh_out}")
    print(f"wrote: {npz_out}")


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    try:
        if args.command == "transfer":
            run_transfer(args)
    except KeyboardInterrupt:
        print("hemishadow: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a tool for people: one clear line, no traceback
        print(f"hemishadow: error: {exc}", file=sys.stderr)
        return 2
    return 0
