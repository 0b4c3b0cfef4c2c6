"""Time of a lightmap bake: a 6 m floor (3,200 triangles) with a sphere (5,120) and a wall,
forest HDRI (9 coefficients; --bands 5: 25, as the add-on), a sun, 2 bounces, HL2 basis.

    PYTHONPATH=native/python .venv/bin/python bench/lightmap_speed.py [--resolution 128] [--samples 4] [--bands 3]

Wall time and CPU time (all threads: on a machine shared with other work, CPU time is the
fair measure) of the bake, the engine's scene build apart.
"""

import argparse
import sys
import time

import numpy as np
import trimesh

import hemishadow
from hemishadow.environment import default_hdri
from hemishadow.lightmap import Sun, Surface, Target, bake


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--samples", type=int, default=4)
    parser.add_argument("--bounces", type=int, default=2)
    parser.add_argument("--bands", type=int, default=3, help="SH bands of the HDRI (the add-on projects 5)")
    args = parser.parse_args(argv)
    n, size = 40, 6.0
    g = np.linspace(-size / 2, size / 2, n + 1)
    x, y = np.meshgrid(g, g)
    floor_v = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    i = np.arange(n)
    a = (i[:, None] * (n + 1) + i[None, :]).ravel()
    floor_t = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)])
    uv = floor_v[:, :2] / size + 0.5
    ball = trimesh.creation.icosphere(4, 0.8)
    ball.apply_translation((0.5, 0, 0.8))
    wall = trimesh.creation.box(bounds=[[-2, -1, 0], [-1.5, 1, 1.5]])
    scene = hemishadow.Scene()
    ids = []
    for v, t in ((floor_v, floor_t), (ball.vertices, ball.faces), (wall.vertices, wall.faces)):
        ids.append(scene.add_mesh(np.asarray(v), np.asarray(t)))
        scene.add_instance(ids[-1])
    lighting = hemishadow.project_environment(default_hdri(), bands=args.bands)
    surfaces = [Surface(ids[1], np.asarray(ball.vertices), np.asarray(ball.faces)),
                Surface(ids[2], np.asarray(wall.vertices), np.asarray(wall.faces))]
    build = time.process_time()
    scene.prepare()  # the engine's scene build, timed apart (once per scene)
    build = time.process_time() - build
    t0, c0 = time.perf_counter(), time.process_time()
    bake(scene, [Target(Surface(ids[0], floor_v, floor_t, name="floor"), uv)], resolution=args.resolution,
         samples=args.samples, lighting=lighting, suns=[Sun((0.5, 0.3, 0.8), 3.0, 0.01)], bounces=args.bounces,
         surfaces=surfaces)
    print(f"{scene.triangle_count} triangles, {args.resolution}^2 texels x {args.samples} samples, "
          f"{args.bounces} bounces: {time.perf_counter() - t0:.1f} s ({time.process_time() - c0:.1f} s CPU, all "
          f"threads; scene build {build:.1f} s CPU apart)")


if __name__ == "__main__":
    sys.exit(main())
