"""What shadow casters cost a live frame of `make demo` (issue 10), and where it goes.

Run: .venv/bin/python bench/live_casters.py [--rounds 3] [--frames 40]

Each round runs three modes, each in a fresh process, one after the other (so a busy
machine slows all three alike), on the demo's scene (scripts/demo_blender.py: cloth,
Suzanne with Subdivision Surface, a subdivided floor, Blender's forest HDRI):

- `self`: self-shadowing only, as before issue 10 (Suzanne and the floor never change);
- `casters`: cloth, Suzanne and floor in the scene's Shadow casters;
- `casters, cached`: the same frames played back from the animation cache baked with
  casters, which writes the same three objects' colours every frame but computes nothing:
  Blender's own share of a frame with casters (its evaluation of the three objects after
  the writes, reading the cache, the handlers).

Per mode: the median over frames 2..N of `scene.frame_set` (wall and CPU of all threads),
and for `self` and `casters` the add-on's own split per object (read, solve, shade, write).
Prints Markdown tables.
"""

import argparse
import json
import pathlib
import shutil
import statistics
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
MODES = ("self", "casters", "casters, cached")


def run_mode(mode, frames):
    """In this process: the scene, the cloth baked, Live on; returns the mode's medians."""
    sys.path.insert(0, str(ROOT / "scripts"))
    import demo_blender as demo

    _, site = demo.prepare_user_resources(str(ROOT / "out" / "blender_user_bench"))
    demo.use_addon(True, None, site)
    engine_bridge = sys.modules["addon.engine_bridge"]
    bake = sys.modules["addon.operators.bake"]
    scene, cloth, suzanne, floor = demo.build_scene(38, frames, "forest")
    out = ROOT / "out" / "bench_live_casters"
    out.mkdir(parents=True, exist_ok=True)
    shutil.rmtree(out / "hemishadow_cache", ignore_errors=True)  # an earlier run's bake would be played instead
    import bpy

    bpy.ops.wm.save_as_mainfile(filepath=str(out / "scene.blend"))  # a home for the cache (//)
    demo.bake_cloth(scene, cloth)
    objects = [cloth, suzanne, floor]
    for obj in objects:
        obj.hemishadow.enabled = True
        demo.demo_material(obj)
    scene.hemishadow.lighting_source = "WORLD"
    if mode != "self":
        demo.shadow_casters(scene, objects)
    scene.frame_set(1)
    bpy.ops.hemishadow.live_toggle()
    split = _split_timer(engine_bridge) if mode in ("self", "casters") else None
    if mode == "casters, cached":
        bake.bake_range(scene, objects, 1, frames)
        scene.frame_set(1)
    wall, cpu = [], []
    for frame in range(2, frames + 1):
        t0, c0 = time.perf_counter(), time.process_time()
        scene.frame_set(frame)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    result = {"wall": statistics.median(wall) * 1e3, "cpu": statistics.median(cpu) * 1e3}
    if split is not None:
        result["split"] = {k: v * 1e3 / len(wall) for k, v in sorted(split.items())}
    return result


def _split_timer(engine_bridge):
    """Wraps the add-on's read / solve / shade / write steps; returns their seconds per name."""
    totals = {}

    def timed(name, label):
        function = getattr(engine_bridge, name)

        def wrapper(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                key = f"{label} {args[0].name}"
                totals[key] = totals.get(key, 0.0) + time.perf_counter() - t0

        setattr(engine_bridge, name, wrapper)

    for name, label in (("read_object", "read"), ("solve_object", "solve"), ("_shade_request", "shade"),
                        ("_write", "write")):
        timed(name, label)
    return totals


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--mode", choices=MODES, help=argparse.SUPPRESS)  # one mode, in a child process
    args = parser.parse_args()
    if args.mode:
        print(json.dumps(run_mode(args.mode, args.frames)))
        return 0
    runs = {mode: [] for mode in MODES}
    for r in range(args.rounds):
        for mode in MODES:
            done = subprocess.run([sys.executable, __file__, "--mode", mode, "--frames", str(args.frames)],
                                  capture_output=True, text=True, check=True)
            runs[mode].append(json.loads(done.stdout.strip().splitlines()[-1]))
            print(f"round {r + 1}, {mode}: {runs[mode][-1]['wall']:.1f} ms wall, {runs[mode][-1]['cpu']:.1f} ms CPU",
                  file=sys.stderr)
    print("| mode | frame_set, wall (median per round) | CPU of all threads |")
    print("|---|---|---|")
    for mode in MODES:
        walls = ", ".join(f"{run['wall']:.1f}" for run in runs[mode])
        cpus = ", ".join(f"{run['cpu']:.1f}" for run in runs[mode])
        print(f"| {mode} | {walls} ms | {cpus} ms |")
    base = [run["wall"] for run in runs["self"]]
    ratio = [c["wall"] / s for c, s in zip(runs["casters"], base)]
    print(f"\ncasters / self, wall, per round: {', '.join(f'{x:.2f}' for x in ratio)}")
    for mode in ("self", "casters"):
        splits = [run["split"] for run in runs[mode]]
        keys = sorted(set().union(*splits))
        print(f"\n| step of a frame, {mode} (ms per frame) | " + " | ".join(f"round {i + 1}" for i in range(len(splits))) + " |")
        print("|---|" + "---|" * len(splits))
        for key in keys:
            print(f"| {key} | " + " | ".join(f"{s.get(key, 0.0):.2f}" for s in splits) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
