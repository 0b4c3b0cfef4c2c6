"""Error and time of diffuse transfer on spot.obj for each integration block size.

Run: .venv/bin/python docs/accuracy_by_downsample.py (prints the table in docs/algorithm.md).
"""

import pathlib
import sys
import time

import numpy as np
import trimesh

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
import reference as ref  # noqa: E402

import hemishadow  # noqa: E402

mesh = trimesh.load(pathlib.Path(__file__).resolve().parents[1] / "tests/assets/spot.obj", process=False, force="mesh")
V, F = ref.weld(np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces))[:2]
N = ref.vertex_normals(V, F)
offset = 1e-3 * ref.mean_edge_length(V, F)
ids = np.random.default_rng(0).choice(len(V), 600, replace=False)
T_ref = ref.transfer_reference(V, F, N, offset=offset, vertex_ids=ids, n_side=96)
print("| downsample | grey term | median | mean (AO >= 0.1) | time for 2930 vertices |")
print("|---|---|---|---|---|")
for downsample in (8, 4, 2, 1):
    start = time.perf_counter()
    T = hemishadow.transfer(V, F, N, offset=offset, downsample=downsample)
    seconds = time.perf_counter() - start
    s = ref.error_summary(T[ids], T_ref)
    side = 32 // downsample
    print(f"| {downsample} | {side}x{side} | {s['median']:.2%} | {s['mean']:.2%} | {seconds * 1000:.0f} ms |")
