"""How long a heavy mesh blocks Blender on a frame change, synchronous versus in the worker.

Run: .venv/bin/python bench/heavy_live.py [levels]   (default 4: Suzanne subdivided 4 times,
126,338 vertices, with a Wave modifier so every frame has another shape)
Prints, for one frame change:
- synchronous (what every frame change did before jobs.py, and what renders and scripts do):
  the time the main thread is blocked;
- interactive (jobs.py): the time the main thread is blocked by the request, the longest
  poll of the timer, the time until the new result is written, and how long a cancel takes
  to stop the engine.
"""

import functools
import pathlib
import sys
import time

import bpy

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
import addon  # noqa: E402  (the add-on from source, registered below)
from addon import engine_bridge, jobs  # noqa: E402

print = functools.partial(print, flush=True)  # noqa: A001  (progress of a long run)


def heavy_suzanne(levels):
    bpy.ops.mesh.primitive_monkey_add()
    obj = bpy.context.active_object
    obj.modifiers.new("subdivide", "SUBSURF").levels = levels
    bpy.ops.object.modifier_apply(modifier="subdivide")
    wave = obj.modifiers.new("wave", "WAVE")
    wave.height, wave.width, wave.speed = 0.2, 0.5, 0.05
    obj.hemishadow.enabled = True
    return obj


def poll_until_idle():
    longest = 0.0
    while True:
        t0 = time.perf_counter()
        again = jobs.poll()
        longest = max(longest, time.perf_counter() - t0)
        if again is None:
            return longest
        time.sleep(0.02)


def main(levels):
    bpy.ops.wm.read_homefile(use_empty=True)
    addon.register()
    scene = bpy.context.scene
    scene.hemishadow.lighting_source = "UNIFORM"
    obj = heavy_suzanne(levels)
    print(f"Suzanne, {levels} subdivisions: {len(obj.data.vertices)} vertices")
    jobs.update_scene(scene, bpy.context.evaluated_depsgraph_get(), [obj])  # builds the solver; frame 1 shown

    scene.frame_set(2)
    t0 = time.perf_counter()
    engine_bridge.update_scene(scene, bpy.context.evaluated_depsgraph_get(), [obj])
    print(f"synchronous frame change: main thread blocked {time.perf_counter() - t0:.2f} s")

    scene.frame_set(3)
    t0 = time.perf_counter()
    jobs.update_scene(scene, bpy.context.evaluated_depsgraph_get(), [obj], interactive=True)
    blocked = time.perf_counter() - t0
    print(f"interactive frame change: main thread blocked {blocked * 1e3:.1f} ms; status '{obj.hemishadow.status}'")
    longest = poll_until_idle()
    print(f"  result written after {time.perf_counter() - t0:.2f} s; longest poll {longest * 1e3:.1f} ms; "
          f"status '{obj.hemishadow.status}'")

    scene.frame_set(4)
    jobs.update_scene(scene, bpy.context.evaluated_depsgraph_get(), [obj], interactive=True)
    while not (jobs.pending() and jobs.pending()[0].fraction > 0):
        time.sleep(0.01)
    t0 = time.perf_counter()
    jobs.cancel()
    while jobs._worker is not None:
        time.sleep(0.005)
    print(f"cancel: the engine stopped {(time.perf_counter() - t0) * 1e3:.0f} ms after; status "
          f"'{obj.hemishadow.status}'")
    addon.unregister()


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 4)
