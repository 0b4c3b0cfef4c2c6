"""docs/images/panorama_web.png: the web viewer (with its panel) on a baked panorama of a small scene.

    .venv/bin/python docs/panorama_web_figure.py [--size 1024x512]

A room (8 x 6 x 3 m, no ceiling, so the sky is background), Spot (tests/assets/spot.obj), a pillar and a ball,
baked with hemishadow.panorama.bake (16 coefficients) from (-0.5, -0.8, 1.4) into out/panorama_web/panorama.json,
then served and screenshot by scripts/panorama_web_screenshot.py with a sun, a point lamp and the forest HDRI.
"""

import argparse
import pathlib
import runpy
import sys
import time

import numpy as np
import trimesh

import hemishadow
import hemishadow.panorama as hp

ROOT = pathlib.Path(__file__).resolve().parent.parent
QUERY = "sun=0.45,-0.55,0.7,3&point=1.3,0,1,80&env=forest,0.5&exposure=-1"
ORIGIN = (-0.5, -0.8, 1.4)


def scene_meshes():
    """(vertices, triangles, albedo) per object, +Z up."""
    room = trimesh.creation.box(bounds=[[-4, -3, 0], [4, 3, 3]])
    room.invert()  # seen from inside
    room = trimesh.Trimesh(room.vertices, room.faces[~np.all(np.isclose(room.vertices[room.faces][:, :, 2], 3), 1)])
    spot = trimesh.load(ROOT / "tests" / "assets" / "spot.obj", force="mesh")
    v = spot.vertices @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]])  # OBJ's +Y up -> +Z up
    v *= 1.6 / np.ptp(v, axis=0).max()
    v += np.array([1.8, 0.6, 0]) - [v[:, 0].mean(), v[:, 1].mean(), v[:, 2].min()]
    pillar = trimesh.creation.box(bounds=[[-1.6, -1.8, 0], [-1.0, -1.2, 2.2]])
    ball = trimesh.creation.icosphere(3, 0.6)
    return [(room.vertices, room.faces, (0.75, 0.72, 0.65)), (v, spot.faces, (0.85, 0.45, 0.35)),
            (pillar.vertices, pillar.faces, (0.35, 0.55, 0.8)), (ball.vertices + [-1.0, 1.5, 0.6], ball.faces, (0.8, 0.8, 0.3))]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--size", default="1024x512")
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.size.split("x"))
    scene = hemishadow.Scene()
    albedo = []
    for vertices, triangles, colour in scene_meshes():
        scene.add_instance(scene.add_mesh(np.asarray(vertices, np.float32), np.asarray(triangles, np.int32)))
        albedo.append(colour)
    start = time.perf_counter()
    panorama = hp.bake(scene, ORIGIN, size=(width, height), bands=4, albedo=np.array(albedo, np.float32))
    print(f"baked {width} x {height} x 16 in {time.perf_counter() - start:.1f} s")
    path = ROOT / "out" / "panorama_web" / "panorama.json"
    panorama.save(path)
    shots = runpy.run_path(str(ROOT / "scripts" / "panorama_web_screenshot.py"))
    return shots["main"]([str(path), str(ROOT / "docs" / "images" / "panorama_web.png"), "--query", QUERY,
                          "--window", "1100x700"])


if __name__ == "__main__":
    sys.exit(main())
