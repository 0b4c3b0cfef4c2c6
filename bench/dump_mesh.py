"""Writes a benchmark mesh of `scenes.py` for the engine's profiling example, without Python:

    .venv/bin/python bench/dump_mesh.py cloth cloth.bin
    .venv/bin/python bench/dump_mesh.py suzanne:2 suz2.bin        # Subdivision level 2 (8k)
    .venv/bin/python bench/dump_mesh.py character:Fox.glb fox.bin

then `native/target/release/examples/profile_solver suz2.bin` (see its module comment). The
file holds little-endian u32 frames, vertices and triangles, then f32 positions (frames x
vertices x 3, frame 0 the rest pose), then u32 triangles x 3: the welded frames the benchmark
times, byte for byte.
"""

import argparse
import pathlib

import numpy as np

import scenes


def mesh(name: str):
    """(frames, triangles) of a mesh named `cloth`, `suzanne:LEVEL` or `character:FILE`."""
    kind, _, argument = name.partition(":")
    if kind == "cloth":
        return scenes.cloth()
    if kind == "suzanne":
        return scenes.suzanne(int(argument or 2))
    if kind == "character":
        return scenes.character(argument)
    raise SystemExit(f"unknown mesh {name!r}: cloth, suzanne:LEVEL or character:FILE")


def write(path: pathlib.Path, frames: np.ndarray, triangles: np.ndarray) -> None:
    frames = np.ascontiguousarray(frames, dtype="<f4")
    triangles = np.ascontiguousarray(triangles, dtype="<u4")
    header = np.array([frames.shape[0], frames.shape[1], triangles.shape[0]], dtype="<u4")
    temporary = path.with_name(path.name + ".part")
    temporary.write_bytes(header.tobytes() + frames.tobytes() + triangles.tobytes())
    temporary.replace(path)  # never a half-written file under the final name


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mesh", help="cloth, suzanne:LEVEL or character:FILE (in ../shared/data)")
    parser.add_argument("out", type=pathlib.Path)
    args = parser.parse_args(argv)
    frames, triangles = mesh(args.mesh)
    write(args.out, frames, triangles)
    print(f"{args.out}: {frames.shape[0]} frames, {frames.shape[1]} vertices, {triangles.shape[0]} triangles")


if __name__ == "__main__":
    main()
