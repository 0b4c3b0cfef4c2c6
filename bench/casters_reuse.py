"""What still-caster reuse saves (native/engine/src/caster_reuse.rs): a 120 x 120 floor with a
still box and a small ball moving in a corner; CPU ms per solve once the solver has learnt
which caster moves, against the same solves with reuse off.

Run: PYTHONPATH=native/python .venv/bin/python bench/casters_reuse.py
"""

import pathlib
import sys
import time

import numpy as np
import trimesh

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
import hemishadow  # noqa: E402
from meshes import grid  # noqa: E402


def cpu_ms_per_solve(reuse, frames=12):
    floor_v, floor_t = grid(4.0, 120)
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    box.apply_translation((0.0, 0.0, 0.5))
    ball = trimesh.creation.icosphere(2, 0.2)
    scene = hemishadow.Scene()
    scene.add_instance(scene.add_mesh(np.asarray(box.vertices), np.asarray(box.faces)), np.eye(4))
    moving = scene.add_instance(scene.add_mesh(np.asarray(ball.vertices), np.asarray(ball.faces)), np.eye(4))
    solver = hemishadow.TransferSolver(floor_v, floor_t, reuse=reuse)
    times = []
    for f in range(frames):
        m = np.eye(4)
        m[:3, 3] = (3.0 + 0.05 * f, 3.0, 0.4)
        scene.set_matrix(moving, m)
        t0 = time.process_time()
        solver.solve(floor_v, casters=scene)
        times.append(time.process_time() - t0)
    return 1000 * float(np.median(times[3:]))


if __name__ == "__main__":
    on, off = cpu_ms_per_solve(True), cpu_ms_per_solve(False)
    print(f"14,400 receivers, CPU ms per solve: reuse on {on:.1f}, reuse off {off:.1f} ({off / on:.1f}x)")
