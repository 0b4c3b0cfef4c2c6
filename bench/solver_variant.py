"""Time and error of one `TransferSolver` setting on a benchmark Suzanne, the way bench/run.py
measures them, for trying a change to the solver without the whole benchmark (the numbers
of docs/solver_speed.md's tries):

    .venv/bin/python bench/solver_variant.py                         # the default, 8k Suzanne
    .venv/bin/python bench/solver_variant.py --set near_scale=1.0 --set far_lod=0.7
    .venv/bin/python bench/solver_variant.py --level 3 --rounds 1    # the 32k Suzanne
    .venv/bin/python bench/solver_variant.py --level 3 --pvs         # and with build_pvs, side by side
    .venv/bin/python bench/solver_variant.py --mesh fox --pvs        # bench/run.py's other meshes

Two builds of the engine compare the same way, run after run: an older one unpacked where
PYTHONPATH puts it ahead of the installed one (the first line printed names the engine used):

    repo=$PWD; git worktree add /tmp/old <rev>
    (cd /tmp/old/native && $repo/.venv/bin/maturin build --release -o /tmp/wheel)
    .venv/bin/python -m zipfile -e /tmp/wheel/hemishadow-*.whl /tmp/old_engine
    PYTHONPATH=/tmp/old_engine .venv/bin/python bench/solver_variant.py --mesh cloth
    .venv/bin/python bench/solver_variant.py --mesh cloth

The frames (`run.make_mesh`, 7 of them, frame 0 the rest pose), normals, offset, the 500
receivers and their reference (128^2 rays, frames 2 and 5, on all cores) are bench/run.py's;
they are cached in out/solver_variant/ (the reference takes a minute). Prints the median time
per `solve` over `--rounds` passes of the moving frames (reuse off), the blockers per
receiver, and the median and mean (AO >= 0.1) error of frames 2 and 5. With `--pvs`, a second
solver of the same setting after `build_pvs(every frame)` is timed in alternation with the
first, solve by solve (on a shared machine only numbers taken side by side compare).
"""

import argparse
import ast
import pathlib
import sys
import time

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

import hemishadow  # noqa: E402
import peers  # noqa: E402
import reference  # noqa: E402
import run  # noqa: E402
import scenes  # noqa: E402

EVALUATED = run.FULL["eval_frames"]
CACHE = HERE.parent / "out" / "solver_variant"


def mesh_frames(mesh):
    """(frames, triangles): `suzanne_<level>` for any level, else bench/run.py's mesh."""
    level = mesh.removeprefix("suzanne_")
    if level.isdigit():
        return scenes.suzanne(int(level), n_frames=run.FULL["frames"])[:2]
    return run.make_mesh(mesh, run.FULL, quick=False)[:2]


def cache_name(mesh):
    """bench/run.py's Suzanne names (suzanne_8k) as their level (suzanne_2): one cache file per
    level, whichever name asks."""
    size = mesh.removeprefix("suzanne_")
    return f"suzanne_{run.SUZANNE_LEVELS[size]}" if size in run.SUZANNE_LEVELS else mesh


def prepared(mesh):
    """The mesh, its frames and the reference of the evaluated frames, cached per mesh."""
    mesh = cache_name(mesh)
    path = CACHE / f"{mesh}.npz"
    if not path.exists():
        frames, tris = mesh_frames(mesh)
        tris64, normals, offset = run.prepared(frames, tris)
        count = min(frames.shape[1], run.FULL["receivers"])  # all vertices when fewer, as bench/run.py
        ids = np.sort(np.random.default_rng(12345).choice(frames.shape[1], count, replace=False))
        with peers.EmbreePool() as pool:
            refs = {f: pool.reference(frames[f], tris64, normals[f], offset, run.FULL["reference_side"], 1000 * f, ids)
                    for f in EVALUATED}
        CACHE.mkdir(parents=True, exist_ok=True)
        part = path.with_name(path.stem + ".part.npz")
        np.savez(part, frames=frames, tris=tris, normals=normals, offset=offset, ids=ids,
                 **{f"T{f}": refs[f][0] for f in EVALUATED}, **{f"ao{f}": refs[f][1] for f in EVALUATED})
        part.replace(path)
    return np.load(path)


def setting(text):
    """`name=value` -> (name, value), the value a Python literal."""
    name, _, value = text.partition("=")
    if not name or not value:
        raise argparse.ArgumentTypeError(f"expected name=value, got {text!r}")
    return name, ast.literal_eval(value)


def timed(solvers, frames, normals, rounds):
    """Per solver, its solve times over `rounds` passes of the moving frames, in alternation."""
    times = {label: [] for label in solvers}
    for _ in range(rounds):
        for f in range(1, len(frames)):
            for label, solver in solvers.items():
                start = time.perf_counter()
                solver.solve(frames[f], normals[f])
                times[label].append(time.perf_counter() - start)
    return times


def report(label, solver, times, data):
    ids = data["ids"]
    blockers = solver.stats["blockers_per_vertex"]
    outputs = {f: solver.solve(data["frames"][f], data["normals"][f]) for f in EVALUATED}
    summaries = [reference.error_summary(outputs[f][ids], data[f"T{f}"], data[f"ao{f}"]) for f in EVALUATED]
    median, mean = (100 * np.mean([s[k] for s in summaries]) for k in ("median", "mean"))
    print(f"{label}: {1000 * np.median(times):.2f} ms per solve (fastest {1000 * min(times):.2f}), "
          f"{blockers:.0f} blockers per receiver, median error {median:.3f} %, mean {mean:.3f} %")
    return outputs


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--set", type=setting, action="append", default=[], metavar="NAME=VALUE",
                        help="a TransferSolver keyword (repeatable)")
    parser.add_argument("--level", type=int, default=2, help="Subdivision Surface level (2: 8k vertices)")
    parser.add_argument("--mesh", choices=run.FULL["meshes"], help="one of bench/run.py's meshes instead of Suzanne")
    parser.add_argument("--rounds", type=int, default=3, help="passes over the moving frames timed")
    parser.add_argument("--pvs", action="store_true", help="also the setting with build_pvs(every frame), side by side")
    args = parser.parse_args()
    print(f"engine: {pathlib.Path(hemishadow.__file__).parent}")
    data = prepared(args.mesh or f"suzanne_{args.level}")
    frames, normals = data["frames"], data["normals"]
    keywords = dict(args.set)
    label = str(keywords or "default")
    make = lambda: hemishadow.TransferSolver(frames[0], data["tris"], offset=float(data["offset"]), reuse=False, **keywords)  # noqa: E731
    solvers = {label: make()}
    if args.pvs:
        solvers["PVS"] = make()
        start = time.perf_counter()
        solvers["PVS"].build_pvs(frames, normals)
        print(f"build_pvs of {len(frames)} poses: {time.perf_counter() - start:.1f} s")
    for solver in solvers.values():
        solver.solve(frames[1], normals[1])  # warm-up
    times = timed(solvers, frames, normals, args.rounds)
    outputs = {name: report(name, solver, times[name], data) for name, solver in solvers.items()}
    if args.pvs:
        same = all(np.array_equal(outputs["PVS"][f], outputs[label][f]) for f in EVALUATED)
        print(f"PVS output on frames {EVALUATED}: {'identical to' if same else 'differs from'} the setting's")


if __name__ == "__main__":
    main()
