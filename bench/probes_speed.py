"""Time of a probe bake: the scene of bench/lightmap_speed.py (a 6 m floor of 3,200
triangles, a sphere of 5,120, a wall), forest HDRI (9 coefficients), a sun, a grid over the
floor, with and without 2 bounces; probes per second (first call's one-off tables apart).

    PYTHONPATH=native/python .venv/bin/python bench/probes_speed.py [--resolution 16 16 4] [--bounces 2]
"""

import argparse
import sys
import time

import numpy as np
import trimesh

import hemishadow
import hemishadow.probes as hp
from hemishadow.environment import default_hdri
from hemishadow.lightmap import Sun, Surface


def scene():
    n, size = 40, 6.0
    g = np.linspace(-size / 2, size / 2, n + 1)
    x, y = np.meshgrid(g, g)
    floor_v = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    i = np.arange(n)
    a = (i[:, None] * (n + 1) + i[None, :]).ravel()
    floor_t = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)])
    ball = trimesh.creation.icosphere(4, 0.8)
    ball.apply_translation((0.5, 0, 0.8))
    wall = trimesh.creation.box(bounds=[[-2, -1, 0], [-1.5, 1, 1.5]])
    sc = hemishadow.Scene()
    meshes = [(floor_v, floor_t), (np.asarray(ball.vertices), np.asarray(ball.faces)),
              (np.asarray(wall.vertices), np.asarray(wall.faces))]
    surfaces = []
    for v, t in meshes:
        mesh_id = sc.add_mesh(v, t)
        sc.add_instance(mesh_id)
        surfaces.append(Surface(mesh_id, v, t))
    return sc, surfaces


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, nargs=3, default=(16, 16, 4))
    parser.add_argument("--bounces", type=int, default=2)
    args = parser.parse_args(argv)
    sc, surfaces = scene()
    lighting = hemishadow.project_environment(default_hdri(), bands=3)
    matrix = hp.bounds_matrix((-3, -3, 0), (3, 3, 2), args.resolution)
    hp.bake(sc, np.zeros((1, 3)) + (0, 0, 3), lighting=lighting)  # one-off cell tables
    for bounces in sorted({0, args.bounces}):
        t0 = time.perf_counter()
        out = hp.bake_grid(sc, matrix, args.resolution, lighting=lighting, suns=[Sun((0.5, 0.3, 0.8), 3.0)],
                           surfaces=surfaces, bounces=bounces)
        dt = time.perf_counter() - t0
        p = len(out["positions"])
        print(f"{sc.triangle_count} triangles, {p} probes ({(~out['valid']).sum()} invalid, {out['moved'].sum()} "
              f"moved), {bounces} bounces: {dt:.2f} s, {p / dt:.0f} probes/s")


if __name__ == "__main__":
    sys.exit(main())
