"""How far the per-frame solver (what the add-on runs) can be from the exact path, vertex by
vertex, on whole meshes: the shared scans and characters at rest, every frame of the
characters' animations, and the same meshes scaled from 0.001 to 1000.

Run: .venv/bin/python bench/solver_trust.py   (about 5 minutes on 2 cores)
Writes docs/solver_trust.md. The tests (tests/test_solver_trust.py) check the same bounds on
a fixed subset of receivers of the large scans.
"""

import argparse
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
import hemishadow  # noqa: E402
from animated import CHARACTERS, character_frames  # noqa: E402
from meshes import MESHES, load_asset  # noqa: E402

BANDS = 3  # AO is T_0; the band count does not change which blockers are used
OUT = ROOT / "docs" / "solver_trust.md"
STATIC = dict(MESHES, armadillo=lambda: load_asset("armadillo.obj"))


def ao(transfer):
    return hemishadow.ambient_occlusion(transfer)


def timed(function, *args):
    start = time.perf_counter()
    value = function(*args)
    return value, time.perf_counter() - start


def static_rows():
    rows = []
    for name, make in STATIC.items():
        v, t = (np.asarray(a, dt) for a, dt in zip(make(), (np.float32, np.uint32)))
        exact, exact_s = timed(lambda: ao(hemishadow.transfer(v, t, bands=BANDS)))
        solver = hemishadow.TransferSolver(v, t, bands=BANDS, reuse=False)
        solved, solve_s = timed(lambda: ao(solver.solve(v)))
        d = np.abs(solved - exact)
        rows.append(f"| {name} | {len(v):,} | {d.max():.3f} | {(d > 0.1).sum()} | {np.median(d):.4f} | "
                    f"{1000 * solve_s:.0f} ms | {exact_s:.1f} s |")
        print(rows[-1], flush=True)
    return rows


def jumps(series, actions):
    same = np.array([a == b for a, b in zip(actions[:-1], actions[1:])])
    return np.abs(np.diff(series, axis=0))[same]


def animation_rows():
    rows = []
    for name in CHARACTERS:
        triangles, frames = character_frames(name)
        solver = hemishadow.TransferSolver(frames[0][2], triangles, bands=BANDS)
        exact = np.array([ao(hemishadow.transfer(v, triangles, bands=BANDS)) for _, _, v in frames])
        solved = np.array([ao(solver.solve(v)) for _, _, v in frames])
        d = np.abs(solved - exact)
        actions = [a for a, _, _ in frames]
        je, js = jumps(exact, actions), jumps(solved, actions)
        rows.append(f"| {name} | {len(frames)} | {d.max():.3f} | {(d > 0.1).sum()} | {(je > 0.2).sum()} / "
                    f"{(js > 0.2).sum()} | {je.max():.3f} / {js.max():.3f} |")
        print(rows[-1], flush=True)
    return rows


def scale_rows():
    rows = []
    for name in ("spot", "teapot", "cesium_man", "rolled_sheet"):
        v, t = (np.asarray(a, dt) for a, dt in zip(MESHES[name](), (np.float32, np.uint32)))
        base_s = ao(hemishadow.TransferSolver(v, t, bands=BANDS).solve(v))
        base_e = ao(hemishadow.transfer(v, t, bands=BANDS))
        cells = []
        for scale in (1e-3, 1e-2, 1e2, 1e3):
            s = v * np.float32(scale)
            ds = np.abs(ao(hemishadow.TransferSolver(s, t, bands=BANDS).solve(s)) - base_s).max()
            de = np.abs(ao(hemishadow.transfer(s, t, bands=BANDS)) - base_e).max()
            cells.append(f"{ds:.4f} / {de:.4f}")
        rows.append(f"| {name} | " + " | ".join(cells) + " |")
        print(rows[-1], flush=True)
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, default=OUT, help=f"Markdown file to write (default: {OUT})")
    out = parser.parse_args().out
    static, animated, scaled = static_rows(), animation_rows(), scale_rows()
    text = [
        "# How far the solver is from the exact path",
        "",
        "Made by `.venv/bin/python bench/solver_trust.py` (2 cores; times are indicative, the",
        "benchmarks are in [benchmarks.md](benchmarks.md)). The solver is `hemishadow.TransferSolver`",
        "at its defaults (what the add-on runs every frame); the exact path is `hemishadow.transfer`",
        "(every triangle a blocker). |dAO| is the absolute difference of ambient occlusion per vertex.",
        "",
        "## Whole meshes at rest",
        "",
        "| mesh | vertices | max \\|dAO\\| | vertices > 0.1 | median \\|dAO\\| | solve | exact |",
        "|---|---|---|---|---|---|---|",
        *static,
        "",
        "## Every frame of the characters' animations (all actions)",
        "",
        "Frame-to-frame jumps |dAO| > 0.2 are counted over vertex-frames; the exact path has them",
        "too, where skinning pushes vertices through the body.",
        "",
        "| character | frames | max \\|dAO\\| | vertex-frames > 0.1 | jumps > 0.2 (exact / solver) | "
        "largest jump (exact / solver) |",
        "|---|---|---|---|---|---|",
        *animated,
        "",
        "## Size: largest per-vertex change of AO against the mesh at scale 1 (solver / exact)",
        "",
        "| mesh | x 0.001 | x 0.01 | x 100 | x 1000 |",
        "|---|---|---|---|---|",
        *scaled,
        "",
    ]
    out.write_text("\n".join(text))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
