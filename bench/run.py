"""hemishadow benchmark: time-versus-error curves of hemishadow's settings and of Embree (all
cores) per mesh, the speed-up at equal error read off them, and the cost per vertex against
the vertex count (Suzanne subdivided 0..5).

    .venv/bin/python bench/run.py            # full run (< 25 minutes on 2 cores)
    .venv/bin/python bench/run.py --quick    # smoke run (< 2 minutes)

Writes bench/results.json (full) or bench/results_quick.json, then docs/benchmarks.md and
docs/images/bench_*.png (full run; a quick run reports to bench/quick/). `bench/report.py`
redraws the page from the JSON.
"""

import argparse
import datetime
import inspect
import json
import os
import pathlib
import platform
import subprocess
import sys
import time
import warnings

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT / "tests"))

import hemishadow  # noqa: E402
import peers  # noqa: E402
import reference  # noqa: E402
import scenes  # noqa: E402

# (label, TransferSolver keyword arguments); reuse is off everywhere: every receiver is computed.
VARIANTS = [
    ("default", {}),
    ("downsample 1", dict(downsample=1)),
    ("downsample 2", dict(downsample=2)),
    ("downsample 4", dict(downsample=4)),
    ("table 64", dict(table_resolution=64)),
    ("table 96", dict(table_resolution=96)),
    ("table 128", dict(table_resolution=128)),
    ("ring 1", dict(ring=1)),
    ("ring 2", dict(ring=2)),
    ("two levels (far_lod 0)", dict(far_lod=0.0)),
    ("far_lod 0.7", dict(far_lod=0.7)),
    ("PVS", {}),  # the default + build_pvs(the mesh's frames), when the engine has it
    ("PVS, half the poses", {}),  # build_pvs(frames 0, 2, 4, ...): the odd frames are unseen poses
]
PVS_POSES = {"PVS": slice(None), "PVS, half the poses": slice(None, None, 2)}

FULL = dict(
    meshes=["cloth", "suzanne_2k", "suzanne_8k", "suzanne_32k", "cesium_man", "fox", "rigged_figure"],
    frames=7, eval_frames=(2, 5), receivers=500, reference_side=128, embree_sides=(8, 16, 32, 64, 128),
    hemishadow_budget=1.5, max_passes=20, embree_budget=2.0, embree_cap=30.0,
    levels=(0, 1, 2, 3, 4, 5), level_frames=3, embree_levels=(0, 1, 2, 3, 4), curve_side=16, once_above=200_000,
    warm_up_cap=15.0, level_cap=240.0, pair_levels=(3, 4), pair_rounds=8,
)
QUICK = dict(
    meshes=["cloth", "suzanne_2k", "rigged_figure"],
    frames=3, eval_frames=(1,), receivers=150, reference_side=64, embree_sides=(8, 16, 32, 64, 128),
    hemishadow_budget=0.3, max_passes=3, embree_budget=0.3, embree_cap=0.5,
    levels=(0, 1, 2), level_frames=2, embree_levels=(0, 1, 2), curve_side=16, once_above=200_000,
    warm_up_cap=2.0, level_cap=10.0, pair_levels=(1, 2), pair_rounds=3,
)


# Subdivision levels of the Suzanne meshes, by the names of the report.
SUZANNE_LEVELS = {"2k": 1, "8k": 2, "32k": 3}


def make_mesh(name, cfg, quick):
    if name == "cloth":
        picks = (1, 12, 16, 20) if quick else (1, 24, 28, 32, 36, 40, 44, 48)
        return scenes.cloth(frames=picks, quick=quick)
    if name.startswith("suzanne_"):
        return scenes.suzanne(SUZANNE_LEVELS[name.split("_")[1]], n_frames=cfg["frames"])
    return scenes.character(name + ".glb", n_frames=cfg["frames"])


def machine():
    model = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")),
                 platform.processor())
    flags = next((line for line in open("/proc/cpuinfo") if line.startswith("flags")), "")

    def git(*args):
        return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True).stdout.strip()

    engine = pathlib.Path(hemishadow.__file__).resolve().parents[2]  # the checkout whose native/ is installed
    engine_commit = subprocess.run(["git", "-C", str(engine), "rev-parse", "--short", "HEAD"], capture_output=True,
                                   text=True).stdout.strip()
    engine_dirty = subprocess.run(["git", "-C", str(engine), "status", "--porcelain", "native"], capture_output=True,
                                  text=True).stdout.strip()
    import bpy

    return {
        "cpu": model, "cores": os.cpu_count(), "avx2": " avx2" in flags, "avx512f": " avx512f" in flags,
        "load_before": os.getloadavg(), "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "python": platform.python_version(), "blender": bpy.app.version_string,
        "commit": git("rev-parse", "--short", "HEAD") + ("+dirty" if git("status", "--porcelain", "bench") else ""),
        "engine": f"{engine} at {engine_commit}" + (" + uncommitted native/ changes" if engine_dirty else ""),
    }


def solver_defaults():
    """TransferSolver's keyword defaults, as the installed engine declares them."""
    params = inspect.signature(hemishadow.TransferSolver.__init__).parameters
    return {k: p.default for k, p in params.items() if p.default is not inspect.Parameter.empty}


def average(summaries):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # nan for "no dark vertices"
        return {k: float(np.nanmean([s[k] for s in summaries])) for k in summaries[0]}


def timed_frames(order, solve, budget, one_if_slower):
    """Run solve(frame) over `order` (eval frames first), at least the first two, more while
    the budget lasts; a frame slower than `one_if_slower` s stops after it."""
    times, spent = [], 0.0
    for k, f in enumerate(order):
        start = time.perf_counter()
        solve(f)
        times.append(time.perf_counter() - start)
        spent += times[-1]
        if times[-1] > one_if_slower or (spent > budget and k + 1 >= 2):
            break
    return times


def build_variants(frames, tris, normals, offset, log):
    """One warmed-up solver per variant that differs from the default -> (entries, rows of
    the variants not run: same as the default, no or failing build_pvs)."""
    defaults = solver_defaults()
    entries, skipped = [], []
    for label, kwargs in VARIANTS:
        pvs = label in PVS_POSES
        if pvs and not hasattr(hemishadow.TransferSolver, "build_pvs"):
            log(f"   {label:20s} not measured: this engine's TransferSolver has no build_pvs")
            continue
        if kwargs and all(defaults.get(k, object()) == v for k, v in kwargs.items()):
            skipped.append({"method": label, "kwargs": kwargs, "same_as_default": True})
            continue
        start = time.perf_counter()
        solver = hemishadow.TransferSolver(frames[0], tris, offset=offset, reuse=False, **kwargs)
        entry = {"label": label, "kwargs": kwargs, "solver": solver, "build_ms": 1e3 * (time.perf_counter() - start),
                 "pvs_ms": None, "times": [], "blockers": [], "out": {}}
        if pvs:
            start = time.perf_counter()
            try:
                poses = PVS_POSES[label]
                solver.build_pvs(np.ascontiguousarray(frames[poses], np.float32), np.asarray(normals)[poses])
            except Exception as error:  # an engine in the making: say so, keep the run
                log(f"   {label:20s} not measured: build_pvs(poses (F, N, 3) float32) raised {error!r}")
                skipped.append({"method": label, "kwargs": kwargs, "failed": repr(error)})
                continue
            entry["pvs_ms"] = 1e3 * (time.perf_counter() - start)
        entries.append(entry)
    return entries, skipped


def hemishadow_rows(frames, tris, normals, offset, order, errors_of, cfg, log):
    """Every variant timed side by side: frame after frame, each variant solves it in turn
    (the first one rotating), so a busy spell of the machine hits all variants alike; passes
    over the frames repeat while the budget lasts (up to `max_passes`), so that a fast mesh's
    median is not that of seven solves."""
    entries, skipped = build_variants(frames, tris, normals, offset, log)
    for e in entries:
        e["solver"].solve(frames[order[0]], normals[order[0]])  # warm-up
    spent = 0.0
    passes = order * cfg["max_passes"]  # the evaluated frames first, each pass
    for k, f in enumerate(passes):
        slowest = 0.0
        for e in entries[k % len(entries):] + entries[:k % len(entries)]:
            start = time.perf_counter()
            result = e["solver"].solve(frames[f], normals[f])
            e["times"].append(time.perf_counter() - start)
            e["blockers"].append(e["solver"].stats["blockers_per_vertex"])
            if f in errors_of.frames:
                e["out"][f] = result
            slowest = max(slowest, e["times"][-1])
        spent += sum(e["times"][-1] for e in entries)
        if slowest > 5.0 or (k + 1 >= 2 and spent > cfg["hemishadow_budget"] * len(entries)):
            break
    default_out = next(e["out"] for e in entries if e["label"] == "default")
    rows = []
    for e in entries:
        ms = 1e3 * float(np.median(e["times"]))
        row = {"method": e["label"], "kwargs": e["kwargs"], "ms": ms, "fps": 1e3 / ms, "frames_timed": len(e["times"]),
               "build_ms": e["build_ms"], "pvs_ms": e["pvs_ms"], "blockers_per_vertex": float(np.mean(e["blockers"])),
               "last_stats": {k: v for k, v in e["solver"].stats.items() if isinstance(v, (int, float, bool, str))},
               "error": errors_of(e["out"], lambda T: (T, T[:, 0] / reference.AO_SCALE)),
               "identical_to_default": all(np.array_equal(e["out"][f], default_out[f]) for f in e["out"])}
        rows.append(row)
        log(f"   {e['label']:20s} {ms:9.2f} ms {row['fps']:8.1f} FPS {row['blockers_per_vertex']:7.0f} blockers  "
            f"median {row['error']['median']:.4f} mean {row['error']['mean']:.4f}"
            + ("  (output = default)" if row["identical_to_default"] and e["label"] != "default" else "")
            + (f"  build_pvs {e['pvs_ms']:.0f} ms" if e["pvs_ms"] is not None else "") + f"  ({len(e['times'])} solves)")
    for row in skipped:
        log(f"   {row['method']:20s} " + ("= default" if row.get("same_as_default") else "failed"))
    order_of = {label: k for k, (label, _) in enumerate(VARIANTS)}
    return sorted(rows + skipped, key=lambda r: order_of[r["method"]])


def embree_rows(pool, frames, tris64, normals, offset, order, errors_of, cfg, log):
    rows, last_ms = [], None
    for side in cfg["embree_sides"]:
        rays = side * side
        if side * 2 > cfg["reference_side"]:
            break  # the reference must have at least 4x the rays of any point it judges
        if len(rows) >= 2 and last_ms * 4 / 1e3 > cfg["embree_cap"]:  # two points at least: a curve
            log(f"   Embree {rays:5d} rays not run (predicted {last_ms * 4 / 1e3:.0f} s per frame)")
            break
        out = {}

        def solve(f):
            out[f] = pool.solve(frames[f], tris64, normals[f], offset, side, seed=7000 + 31 * side + f)

        times = timed_frames(order, solve, cfg["embree_budget"], one_if_slower=3.0)
        last_ms = 1e3 * float(np.median(times))
        row = {"rays": rays, "side": side, "ms": last_ms, "fps": 1e3 / last_ms, "frames_timed": len(times),
               "error": errors_of(out, lambda r: r)}
        rows.append(row)
        log(f"   Embree {rays:5d} rays {last_ms:9.2f} ms {row['fps']:8.1f} FPS  median {row['error']['median']:.4f} "
            f"mean {row['error']['mean']:.4f}  ({len(times)} frames)")
    return rows


def prepared(frames, tris):
    """What every method is given with a mesh: int64 triangles (Embree's), area-weighted vertex
    normals per frame and the receiver offset (1e-3 x the rest pose's mean edge length)."""
    tris64 = tris.astype(np.int64)
    normals = np.stack([reference.vertex_normals(f, tris64) for f in frames]).astype(np.float32)
    return tris64, normals, 1e-3 * reference.mean_edge_length(frames[0], tris64)


def bench_mesh(pool, name, cfg, quick, log):
    t0 = time.perf_counter()
    load_start = os.getloadavg()[0]
    frames, tris = make_mesh(name, cfg, quick)
    tris64, normals, offset = prepared(frames, tris)
    n_vertices = frames.shape[1]
    log(f"\n== {name}: {n_vertices} vertices, {len(tris)} triangles, {len(frames)} frames "
        f"(made in {time.perf_counter() - t0:.1f} s)")
    eval_frames = list(cfg["eval_frames"])
    order = eval_frames + [f for f in range(1, len(frames)) if f not in eval_frames]
    ids = np.sort(np.random.default_rng(12345).choice(n_vertices, min(cfg["receivers"], n_vertices), replace=False))
    start = time.perf_counter()
    refs = {f: pool.reference(frames[f], tris64, normals[f], offset, cfg["reference_side"], 1000 * f, ids)
            for f in eval_frames}
    log(f"   reference: {len(ids)} receivers x {cfg['reference_side'] ** 2} rays x {len(eval_frames)} frames "
        f"in {time.perf_counter() - start:.1f} s")

    def errors_of(out, split):
        """Mean over the evaluated frames of error_summary on the reference's receivers."""
        summaries = []
        for f in eval_frames:
            if f in out:
                T, ao = split(out[f])
                s = reference.error_summary(T[ids], *refs[f])
                s["ao_mean_abs"] = float(np.abs(np.asarray(ao)[ids] - refs[f][1]).mean())
                summaries.append(s)
        return average(summaries)

    errors_of.frames = set(eval_frames)

    result = {"load_start": load_start, "vertices": n_vertices, "triangles": len(tris), "frames": len(frames),
              "eval_frames": eval_frames, "receivers": len(ids), "offset": offset}
    result["hemishadow"] = hemishadow_rows(frames, tris, normals, offset, order, errors_of, cfg, log)
    result["embree"] = embree_rows(pool, frames, tris64, normals, offset, order, errors_of, cfg, log)
    log(f"   ({time.perf_counter() - t0:.0f} s for {name})")
    return result


def vertex_curve(pool, cfg, log):
    """Default solve time and Embree's (curve_side^2 rays) against Suzanne's subdivision level."""
    rows = []
    for level in cfg["levels"]:
        predicted = predict_ms(rows)
        if predicted / 1e3 > cfg["level_cap"]:
            log(f"   level {level}: not run (predicted {predicted / 1e3:.0f} s per solve)")
            rows.append({"level": level, "skipped": f"predicted {predicted / 1e3:.0f} s per solve"})
            break
        t0 = time.perf_counter()
        frames, tris = scenes.suzanne(level, n_frames=cfg["level_frames"])
        tris64, normals, offset = prepared(frames, tris)
        n_vertices = frames.shape[1]
        made = time.perf_counter() - t0
        solver = hemishadow.TransferSolver(frames[0], tris, offset=offset, reuse=False)
        once = n_vertices > cfg["once_above"] or predicted / 1e3 > cfg["warm_up_cap"]
        if not once:
            solver.solve(frames[1], normals[1])  # warm-up
        blockers = []

        def solve(f):
            solver.solve(frames[f], normals[f])
            blockers.append(solver.stats["blockers_per_vertex"])

        times = timed_frames(range(1, len(frames)), solve, 0.0 if once else cfg["hemishadow_budget"], 5.0)
        ms = 1e3 * float(np.median(times))
        row = {"level": level, "vertices": n_vertices, "triangles": len(tris), "ms": ms, "frames_timed": len(times),
               "warm_up": not once, "blockers_per_vertex": float(np.mean(blockers)), "embree_ms": None}
        del solver
        done = [r for r in rows if r.get("embree_ms")]
        if level in cfg["embree_levels"] and (not done or done[-1]["embree_ms"] * n_vertices / done[-1]["vertices"]
                                              < 1e3 * cfg["level_cap"] / 4):
            side = cfg["curve_side"]
            e_times = timed_frames(range(1, len(frames)), lambda f: pool.solve(frames[f], tris64, normals[f], offset,
                                                                                side, seed=f), 0.0, 3.0)
            row["embree_ms"] = 1e3 * float(np.median(e_times))
            row["embree_rays"] = side * side
        rows.append(row)
        log(f"   level {level}: {n_vertices:7d} vertices {len(tris):8d} triangles  hemishadow {ms:10.1f} ms "
            f"({1e6 * ms / n_vertices / 1e3:.2f} us/vertex, {len(times)} frames{'' if row['warm_up'] else ', no warm-up'})"
            + (f"  Embree {row['embree_ms']:10.1f} ms" if row["embree_ms"] else "") + f"  (mesh made in {made:.1f} s)")
    return rows


def scale_pair(cfg, log):
    """The cost ratio of two subdivision levels (the target's 126k / 32k), timed in alternation:
    round after round each level solves its next moving frame, the first one alternating, so
    that a busy spell of the shared machine hits both alike (timed minutes apart, as the
    curve's levels are, the ratio moved by a third between runs)."""
    solvers = []
    for level in cfg["pair_levels"]:
        frames, tris = scenes.suzanne(level, n_frames=cfg["level_frames"])
        _, normals, offset = prepared(frames, tris)
        solver = hemishadow.TransferSolver(frames[0], tris, offset=offset, reuse=False)
        solver.solve(frames[1], normals[1])  # warm-up
        solvers.append((solver, frames, normals))
    times = [[], []]
    for k in range(cfg["pair_rounds"]):
        for i in (0, 1) if k % 2 == 0 else (1, 0):
            solver, frames, normals = solvers[i]
            f = 1 + k % (len(frames) - 1)
            start = time.perf_counter()
            solver.solve(frames[f], normals[f])
            times[i].append(time.perf_counter() - start)
    ratios = np.array(times[1]) / np.array(times[0])
    pair = {"levels": list(cfg["pair_levels"]), "vertices": [len(s[1][0]) for s in solvers],
            "ms": [1e3 * float(np.median(t)) for t in times], "rounds": cfg["pair_rounds"],
            "ratio": float(np.median(times[1]) / np.median(times[0])),
            "round_ratio_quartiles": [float(q) for q in np.percentile(ratios, [25, 50, 75])]}
    log(f"   levels {pair['levels'][1]} / {pair['levels'][0]} in alternation: {pair['ms'][1]:.1f} / {pair['ms'][0]:.1f} ms "
        f"= {pair['ratio']:.2f}x over {pair['rounds']} rounds (per round: quartiles "
        + " / ".join(f"{q:.2f}" for q in pair["round_ratio_quartiles"]) + ")")
    return pair


def predict_ms(rows):
    """The next level's solve time (4x the vertices of the last level run), if the growth of
    the cost per vertex between the last two levels continues; 0 before two levels ran."""
    done = [r for r in rows if "ms" in r]
    if len(done) < 2:
        return 0.0
    a, b = done[-2:]
    per_vertex = b["ms"] / b["vertices"]
    return 4 * b["ms"] * max(1.0, per_vertex / (a["ms"] / a["vertices"]))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="smoke run: small meshes, few rays")
    parser.add_argument("--meshes", nargs="*", help="only these meshes (names as in the report)")
    parser.add_argument("--no-curve", action="store_true", help="skip the vertex-count curve")
    parser.add_argument("--no-report", action="store_true", help="write the JSON only")
    args = parser.parse_args()
    cfg = QUICK if args.quick else FULL
    meshes = cfg["meshes"] if args.meshes is None else args.meshes

    def log(msg):
        print(msg, flush=True)

    start = time.perf_counter()
    with peers.EmbreePool() as pool:  # started before anything is timed
        info = machine()
        log(f"{info['cpu']}, {info['cores']} cores, load {info['load_before'][0]:.2f}, {info['date']}; "
            f"engine {info['engine']}; Embree pool of {pool.workers} processes")
        defaults = solver_defaults()
        log("TransferSolver defaults: " + ", ".join(f"{k}={v!r}" for k, v in defaults.items()))
        results = {"machine": info, "config": cfg, "quick": args.quick, "solver_defaults": {k: repr(v) for k, v in defaults.items()},
                   "pvs_available": hasattr(hemishadow.TransferSolver, "build_pvs"), "embree_workers": pool.workers,
                   "command": ".venv/bin/python bench/run.py" + (" --quick" if args.quick else ""), "meshes": {}}
        for name in meshes:
            results["meshes"][name] = bench_mesh(pool, name, cfg, args.quick, log)
        if not args.no_curve:
            log("\n== vertex-count curve (Suzanne subdivision levels)")
            results["vertex_curve"] = vertex_curve(pool, cfg, log)
            results["scale_pair"] = scale_pair(cfg, log)
    results["machine"]["load_after"] = os.getloadavg()
    results["seconds"] = time.perf_counter() - start
    path = HERE / ("results_quick.json" if args.quick else "results.json")
    path.write_text(json.dumps(results, indent=1))
    log(f"\nwrote {path.relative_to(ROOT)} ({results['seconds']:.0f} s)")
    if not args.no_report:
        import report

        report.main(path, write_docs=not args.quick and args.meshes is None and not args.no_curve)


if __name__ == "__main__":
    main()
