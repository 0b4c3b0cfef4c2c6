"""The solver's third level (group tree, `far_lod`) against the paper's two: time per frame,
blockers per receiver and error against the exact path on bent Suzannes of 8k, 32k and 126k
vertices, and the 126k / 32k time ratio (issue 9's target: at most 4.5x).

    .venv/bin/python bench/group_tree.py            # writes docs/benchmarks_group_tree.md

Each setting: one warm-up solve, then the median wall time of 3 frames (reuse off, both
cores). "two levels, 4096 cap" is the solver as it was before the tree (the coarse mesh
capped at 4096 triangles, `far_lod=0`). Errors: median and worst relative L2 of transfer
against `hemishadow.transfer` (every fine triangle a blocker) on 400 random receivers of
frame 2, with the mean over receivers with AO >= 0.1, and the largest AO difference; the
126k mesh is timed only.
"""

import datetime
import os
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT / "tests"))

import hemishadow  # noqa: E402
import scenes  # noqa: E402
from reference import relative_l2_errors  # noqa: E402

LEVELS = {2: "Suzanne 8k", 3: "Suzanne 32k", 4: "Suzanne 126k"}
SETTINGS = [("two levels, 4096 cap", dict(far_lod=0.0), True), ("two levels", dict(far_lod=0.0), False)] + [
    (f"far_lod {lod}", dict(far_lod=lod), False) for lod in (0.5, 0.7, 0.9)]
DEFAULT = hemishadow.TransferSolver.__init__.__kwdefaults__["far_lod"]
OUT = ROOT / "docs" / "benchmarks_group_tree.md"


def timed(frames, triangles, kwargs, capped):
    if capped:
        kwargs = dict(kwargs, coarse_triangles=min(4096, max(192, len(triangles) // 16)))
    solver = hemishadow.TransferSolver(frames[0], triangles, reuse=False, **kwargs)
    solver.solve(frames[0])
    times, results = [], {}
    for f in (1, 2, 3):
        start = time.perf_counter()
        results[f] = solver.solve(frames[f])
        times.append(time.perf_counter() - start)
    return float(np.median(times)), solver.stats["blockers_per_vertex"], results[2]


def errors(got, exact, rows):
    e = relative_l2_errors(got[rows], exact)
    ao = exact[:, 0] / hemishadow.AO_UNOCCLUDED
    worst_ao = np.abs(got[rows, 0] / hemishadow.AO_UNOCCLUDED - ao).max()
    return np.median(e), e[ao >= 0.1].mean(), worst_ao


def main():
    started = time.time()
    rows_out = {}
    for level, name in LEVELS.items():
        frames, triangles = scenes.suzanne(level, n_frames=3)
        rows = np.random.default_rng(level).choice(frames.shape[1], 400, replace=False)
        exact = hemishadow.transfer(frames[2], triangles, receivers=rows) if level < 4 else None
        for label, kwargs, capped in SETTINGS:
            seconds, blockers, result = timed(frames, triangles, kwargs, capped)
            err = errors(result, exact, rows) if exact is not None else None
            rows_out[(level, label)] = (seconds, blockers, err)
            shown = "" if err is None else f", median {err[0]:.2%}, mean (AO>=0.1) {err[1]:.2%}, worst AO {err[2]:.3f}"
            print(f"{name} ({frames.shape[1]} vertices), {label}: {seconds * 1000:.0f} ms, {blockers:.0f} blockers{shown}", flush=True)
    write(rows_out, time.time() - started)


def write(rows, seconds):
    cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")), "?")
    out = [
        "# The solver's third level: the group tree",
        "",
        f"Made by `.venv/bin/python bench/group_tree.py` on {cpu}, {os.cpu_count()} cores, "
        f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, in {seconds / 60:.1f} minutes. "
        f"The default is far_lod {DEFAULT}. See the script's docstring for the method and "
        "docs/algorithm.md (\"Third level\") for the algorithm.",
        "",
        "| mesh | setting | ms / frame | blockers / receiver | median error vs exact | mean (AO >= 0.1) | worst AO difference |",
        "|---|---|---|---|---|---|---|",
    ]
    for (level, label), (seconds_, blockers, err) in rows.items():
        e = ["–"] * 3 if err is None else [f"{err[0]:.2%}", f"{err[1]:.2%}", f"{err[2]:.3f}"]
        out.append(f"| {LEVELS[level]} | {label} | {seconds_ * 1000:.0f} | {blockers:.0f} | {' | '.join(e)} |")
    out += ["", "126k / 32k time per frame (4x the vertices; issue 9's target: at most 4.5x):", ""]
    for label, _, _ in SETTINGS:
        out.append(f"- {label}: {rows[(4, label)][0] / rows[(3, label)][0]:.2f}x")
    tmp = OUT.with_suffix(".md.tmp")
    tmp.write_text("\n".join(out) + "\n")
    os.replace(tmp, OUT)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
