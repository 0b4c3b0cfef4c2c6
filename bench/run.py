"""hemishadow benchmark: time per frame and error against a dense ray-traced reference, for
hemishadow's solver variants, Embree ray casting projected on SH, and Cycles' AO bake.

    .venv/bin/python bench/run.py            # full run (~10 minutes on 2 cores)
    .venv/bin/python bench/run.py --quick    # smoke run (< 1 minute)

Writes bench/results.json (full) or bench/results_quick.json, then docs/benchmarks.md and
docs/images/bench_*.png (full run only; `bench/report.py` redraws them from the JSON).
"""

import argparse
import datetime
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

# (name, TransferSolver keyword arguments); reuse is off everywhere: every frame is computed.
VARIANTS = [
    ("exact", dict(hierarchy=False, cull=False)),
    ("exact + cull", dict(hierarchy=False, cull=True)),
    ("hierarchy", dict(cull=False)),
    ("hierarchy + cull (default)", dict()),
    ("hierarchy + cull, ring 1", dict(ring=1)),
    ("hierarchy + cull, coarse x4", dict(coarse_factor=4)),
]
DEFAULT = "hierarchy + cull (default)"

FULL = dict(
    meshes=["cloth", "suzanne_2k", "suzanne_8k", "suzanne_32k", "cesium_man", "fox", "rigged_figure"],
    frames=7, eval_frames=(2, 5), receivers=800, n_side=64, rays=(16, 32, 64, 128, 256, 512),
    cycles_samples=(4, 16, 64, 256), budget=2.0, cycles_limit=25.0, skip_exact_above=20000,
)
QUICK = dict(
    meshes=["cloth", "suzanne_2k", "suzanne_8k", "rigged_figure"],
    frames=3, eval_frames=(1,), receivers=150, n_side=24, rays=(16, 64),
    cycles_samples=(4, 16), budget=0.3, cycles_limit=3.0, skip_exact_above=5000,
)


def make_mesh(name, cfg, quick):
    if name == "cloth":
        picks = (1, 12, 16, 20) if quick else (1, 24, 28, 32, 36, 40, 44, 48)
        return scenes.cloth(frames=picks, quick=quick)
    if name.startswith("suzanne_"):
        return scenes.suzanne({"2k": 1, "8k": 2, "32k": 3}[name.split("_")[1]], n_frames=cfg["frames"])
    return scenes.character(name + ".glb", n_frames=cfg["frames"])


def machine():
    model = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")),
                 platform.processor())
    flags = next((line for line in open("/proc/cpuinfo") if line.startswith("flags")), "")
    try:
        commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "native"], capture_output=True,
                               text=True).stdout.strip()
    except OSError:
        commit, dirty = "?", ""
    import bpy

    return {
        "cpu": model, "cores": os.cpu_count(), "avx2": " avx2" in flags, "avx512f": " avx512f" in flags,
        "load_before": os.getloadavg(), "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "python": platform.python_version(), "blender": bpy.app.version_string, "commit": commit + ("+dirty native/" if dirty else ""),
        "hemishadow_module": hemishadow.__file__,
    }


def summarize(T, ao, T_ref, ao_ref):
    s = reference.error_summary(T, T_ref, ao_ref)
    d = np.asarray(ao, np.float64) - ao_ref
    s["ao_mean_abs"] = float(np.abs(d).mean())
    s["ao_median_abs"] = float(np.median(np.abs(d)))
    s["ao_bias"] = float(d.mean())
    return s


def average(summaries):
    keys = summaries[0].keys()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # nan for "no dark vertices"
        return {k: float(np.nanmean([s[k] for s in summaries])) for k in keys}


def timed_frames(order, solve, budget, one_if_slower=5.0):
    """Run solve(frame) over `order` (eval frames first), at least over the eval frames,
    more while the budget lasts; a frame slower than `one_if_slower` s stops after it."""
    times, spent = [], 0.0
    for k, f in enumerate(order):
        start = time.perf_counter()
        solve(f)
        dt = time.perf_counter() - start
        times.append(dt)
        spent += dt
        if dt > one_if_slower or (spent > budget and k + 1 >= 2):
            break
    return times


def bench_mesh(name, cfg, quick, log):
    t0 = time.perf_counter()
    load_start = os.getloadavg()[0]
    frames, tris = make_mesh(name, cfg, quick)
    tris64 = tris.astype(np.int64)
    n_vertices, n_tris = frames.shape[1], len(tris)
    normals = np.stack([reference.vertex_normals(f, tris64) for f in frames]).astype(np.float32)
    offset = 1e-3 * reference.mean_edge_length(frames[0], tris64)
    log(f"\n== {name}: {n_vertices} vertices, {n_tris} triangles, {len(frames)} frames "
        f"(made in {time.perf_counter() - t0:.1f} s)")
    eval_frames = list(cfg["eval_frames"])
    order = eval_frames + [f for f in range(1, len(frames)) if f not in eval_frames]
    rng = np.random.default_rng(12345)
    ids = np.sort(rng.choice(n_vertices, min(cfg["receivers"], n_vertices), replace=False))
    refs = {}
    start = time.perf_counter()
    for f in eval_frames:
        refs[f] = reference.transfer_reference(frames[f], tris64, normals[f], n_side=cfg["n_side"], offset=offset,
                                               vertex_ids=ids, seed=1000 + f, return_ao=True)
    log(f"   reference: {len(ids)} receivers x {cfg['n_side'] ** 2} rays x {len(eval_frames)} frames "
        f"in {time.perf_counter() - start:.1f} s")
    out = {"load_start": load_start, "vertices": n_vertices, "triangles": n_tris, "frames": len(frames), "eval_frames": eval_frames,
           "receivers": len(ids), "offset": offset, "hemishadow": [], "embree": [], "cycles": []}
    # bounding-box diagonal, for the AO distance of Cycles
    diag = float(np.linalg.norm(np.ptp(frames.reshape(-1, 3), axis=0)))

    # --- hemishadow ------------------------------------------------------------------------
    default_coarse = None
    for label, kwargs in VARIANTS:
        kwargs = dict(kwargs)
        if label == "exact" and n_vertices > cfg["skip_exact_above"]:
            log(f"   {label:30s} skipped (same cost as exact + cull on this mesh)")
            continue
        if quick and label not in ("exact + cull", DEFAULT, "hierarchy + cull, coarse x4"):
            continue
        factor = kwargs.pop("coarse_factor", None)
        if factor:
            kwargs["coarse_triangles"] = min(n_tris, factor * default_coarse)
        start = time.perf_counter()
        solver = hemishadow.TransferSolver(frames[0], tris, offset=offset, reuse=False, **kwargs)
        build = time.perf_counter() - start
        if label == DEFAULT:
            default_coarse = solver.coarse_triangles
        solver.solve(frames[0], normals[0])  # warm-up (also builds the plane table once)
        results, blockers = {}, []

        def solve(f):
            results[f] = solver.solve(frames[f], normals[f])
            blockers.append(solver.stats["blockers_per_vertex"])

        times = timed_frames(order, solve, cfg["budget"])
        errs = [summarize(results[f][ids], results[f][ids, 0] / reference.AO_SCALE, *refs[f])
                for f in eval_frames if f in results]
        ms = 1e3 * float(np.median(times))
        bpv = float(np.mean(blockers))
        row = {"method": label, "ms": ms, "fps": 1e3 / ms, "frames_timed": len(times), "build_ms": build * 1e3,
               "blockers_per_vertex": bpv, "coarse_triangles": solver.coarse_triangles if kwargs.get("hierarchy", True) else None,
               "ns_per_triangle": ms * 1e6 * os.cpu_count() / (n_vertices * bpv) if bpv > 0 else float("nan"),
               "bytes_per_vertex": solver.memory_bytes / n_vertices, "error": average(errs),
               "ao_first_frame": errs[0]["ao_mean_abs"], "kwargs": kwargs}
        out["hemishadow"].append(row)
        log(f"   {label:30s} {ms:9.2f} ms {row['fps']:8.1f} FPS  {bpv:7.0f} blockers  "
            f"{row['ns_per_triangle']:6.1f} ns/tri  median {row['error']['median']:.4f} mean {row['error']['mean']:.4f} "
            f"AO abs {row['error']['ao_mean_abs']:.4f}  ({len(times)} frames)")

    # --- Embree ----------------------------------------------------------------------------
    peers.EmbreeTransfer(tris64, 16, 0).solve(frames[0], normals[0], offset)  # warm-up
    for rays in cfg["rays"]:
        peer = peers.EmbreeTransfer(tris64, rays, seed=777 + rays)
        results = {}

        def solve(f):
            results[f] = peer.solve(frames[f], normals[f], offset)

        times = timed_frames(order, solve, cfg["budget"], one_if_slower=30.0)
        errs = [summarize(results[f][0][ids], results[f][1][ids], *refs[f]) for f in eval_frames if f in results]
        ms = 1e3 * float(np.median(times))
        out["embree"].append({"method": f"Embree {rays} rays", "rays": rays, "ms": ms, "fps": 1e3 / ms,
                              "frames_timed": len(times), "error": average(errs), "ao_first_frame": errs[0]["ao_mean_abs"]})
        log(f"   Embree {rays:4d} rays {'':15s} {ms:9.2f} ms  median {average(errs)['median']:.4f} "
            f"mean {average(errs)['mean']:.4f} AO abs {average(errs)['ao_mean_abs']:.4f}")

    # --- Cycles AO bake (first eval frame) ----------------------------------------------
    f = eval_frames[0]
    cycles = peers.CyclesAO(frames[f], tris64, normals[f], distance=10.0 * diag)
    last = None
    for s in cfg["cycles_samples"]:
        if last is not None and last[1] * s / last[0] > cfg["cycles_limit"]:  # predicted too slow
            log(f"   Cycles AO {s:4d} samples skipped (predicted > {cfg['cycles_limit']:.0f} s)")
            continue
        sec, ao = cycles.bake(s)
        last = (s, sec)
        d = ao[ids] - refs[f][1]
        out["cycles"].append({"method": f"Cycles AO {s} samples", "samples": s, "ms": sec * 1e3,
                              "ao_mean_abs": float(np.abs(d).mean()), "ao_median_abs": float(np.median(np.abs(d))),
                              "ao_bias": float(d.mean())})
        log(f"   Cycles AO {s:4d} samples {'':10s} {sec * 1e3:9.1f} ms  AO abs {np.abs(d).mean():.4f}")
    log(f"   ({time.perf_counter() - t0:.0f} s for {name})")
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="smoke run: small meshes, few rays and samples")
    parser.add_argument("--meshes", nargs="*", help="only these meshes (names as in the report)")
    parser.add_argument("--no-report", action="store_true", help="write the JSON only")
    args = parser.parse_args()
    cfg = QUICK if args.quick else FULL
    meshes = args.meshes or cfg["meshes"]
    info = machine()

    def log(msg):
        print(msg, flush=True)

    log(f"{info['cpu']}, {info['cores']} cores, load {info['load_before'][0]:.2f}, {info['date']}")
    start = time.perf_counter()
    results = {"machine": info, "config": {k: v for k, v in cfg.items()}, "quick": args.quick,
               "command": ".venv/bin/python bench/run.py" + (" --quick" if args.quick else ""), "meshes": {}}
    for name in meshes:
        results["meshes"][name] = bench_mesh(name, cfg, args.quick, log)
    results["machine"]["load_after"] = os.getloadavg()
    results["seconds"] = time.perf_counter() - start
    path = HERE / ("results_quick.json" if args.quick else "results.json")
    path.write_text(json.dumps(results, indent=1))
    log(f"\nwrote {path.relative_to(ROOT)} ({results['seconds']:.0f} s)")
    if not args.no_report:
        import report

        report.main(path, write_docs=not args.quick and not args.meshes)


if __name__ == "__main__":
    main()
