"""bench/dump_mesh.py: the file the engine's profiling example reads (its `read_mesh`), byte
layout and values, and no half-written file."""

import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "bench"))

import dump_mesh  # noqa: E402


def test_dump_holds_header_frames_and_triangles_in_order(tmp_path):
    rng = np.random.default_rng(5)
    frames = rng.normal(size=(3, 7, 3)).astype(np.float64)  # converted to f32 on the way
    triangles = np.array([[0, 1, 2], [2, 3, 4], [4, 5, 6]], dtype=np.int64)
    path = tmp_path / "mesh.bin"
    dump_mesh.write(path, frames, triangles)
    data = path.read_bytes()
    header = np.frombuffer(data[:12], dtype="<u4")
    assert header.tolist() == [3, 7, 3]
    positions = np.frombuffer(data[12:12 + 3 * 7 * 3 * 4], dtype="<f4").reshape(3, 7, 3)
    np.testing.assert_array_equal(positions, frames.astype(np.float32))
    tris = np.frombuffer(data[12 + 3 * 7 * 3 * 4:], dtype="<u4").reshape(-1, 3)
    np.testing.assert_array_equal(tris, triangles)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mesh.bin"]
