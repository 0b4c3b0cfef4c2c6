"""Per-frame times of live self-shadowing on the shared animated characters, in Blender.

Run: .venv/bin/python bench/characters_live.py
For each character: import the glTF, enable hemishadow on its meshes, play every frame with
scene.frame_set (the live handlers compute) and report medians of the engine time (transfer
and shading) and the Blender I/O time (reading the evaluated mesh, writing attributes), as
the add-on measures them (engine_bridge.last_timings), and of the whole frame_set.
"""

import pathlib
import statistics
import sys
import time

import bpy

ROOT = pathlib.Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
sys.path.insert(0, str(ROOT))
import addon  # noqa: E402  (the add-on from source, registered below)
from addon import engine_bridge  # noqa: E402


def play(name):
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=str(DATA / name))
    scene = bpy.context.scene
    meshes = [o for o in scene.objects if o.type == "MESH"]
    for obj in meshes:
        obj.hemishadow.enabled = True
    actions = [a.frame_range for a in bpy.data.actions]
    start, end = int(min(r[0] for r in actions)), int(max(r[1] for r in actions))
    scene.hemishadow.live = True
    scene.frame_set(start)  # first compute builds the solvers
    engine, io, whole = [], [], []
    for frame in range(start + 1, end + 1):
        engine_bridge.last_timings.clear()
        t0 = time.perf_counter()
        scene.frame_set(frame)
        whole.append(time.perf_counter() - t0)
        timings = engine_bridge.last_timings.values()
        engine.append(sum(t[2] for t in timings))
        io.append(sum(t[1] for t in timings))
    vertices = sum(len(o.data.vertices) for o in meshes)
    ms = lambda values: 1000 * statistics.median(values)  # noqa: E731
    print(f"| {name} ({end - start} frames) | {vertices:,} | {ms(engine):.1f} ms | {ms(io):.1f} ms | {ms(whole):.1f} ms |")


if __name__ == "__main__":
    addon.register()
    print("| character | vertices | engine | Blender I/O | whole frame_set |")
    print("|---|---|---|---|---|")
    for name in ("cesium_man.glb", "fox.glb", "rigged_figure.glb"):
        play(name)
    addon.unregister()
