"""What a lower `near_scale` does to the bounds of tests/test_solver_trust.py: per mesh, the
largest AO above and below the exact path (leaks and false shadows), the vertices more than
0.1 off and the blockers per receiver; on spot and cesium_man, the largest AO change under the
rotations and mirrors of the trust test and, on spot, the move 50 sizes away (largest change,
vertices above 0.005). docs/solver_speed.md quotes it.

--fixed-hierarchy measures the invariance with one solver per mesh, built from the mesh and
solving the moved and turned positions (the turns that keep the winding): the engine's own
noise, without the simplifier's choosing another coarse mesh for the moved or turned copy.

With --scales 1e-6 --far-lod 0 every receiver sees the coarse mesh alone, which shows how
far apart the coarse meshes of the moved and turned copies are.

--all-meshes measures the invariance on every mesh, each moved too, and counts the cases
beyond the test's bounds ("!"); then each copy against its own exact path (about 2 minutes).

Run: .venv/bin/python bench/near_scale_sweep.py [--scales 1.0 1.5 2.0 2.5] [--fixed-hierarchy]
[--far-lod F] [--all-meshes]   (about 10 seconds on 2 cores)
"""

import argparse
import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
import hemishadow  # noqa: E402
from test_solver_trust import (BANDS, MOVE_BOUND, MOVE_NOTICEABLE, MOVE_NOTICEABLE_SHARE, STATIC,  # noqa: E402
                               TURN_BOUND, TURN_MEAN_BOUND, TURNS, ao, as_engine, moved_and_turned, moved_away,
                               receivers, turned)


INVARIANCE_BOUNDS = f"bounds: {TURN_BOUND} turned; moved {MOVE_BOUND}"


def solver_of(v, t, scale, settings):
    """The solver at `near_scale` `scale`, with the command line's other `settings`."""
    return hemishadow.TransferSolver(v, t, bands=BANDS, near_scale=scale, **settings)


def against_exact(name, scales, settings):
    v, t = as_engine(STATIC[name])
    ids = receivers(len(v))
    exact = ao(hemishadow.transfer(v, t, bands=BANDS, receivers=ids))
    cells = []
    for scale in scales:
        solver = solver_of(v, t, scale, settings)
        d = ao(solver.solve(v))[ids] - exact
        cells.append(f"{scale}: +{d.max():.3f} / -{max(-d.min(), 0):.3f}, {(np.abs(d) > 0.1).sum()} off, "
                     f"{solver.stats['blockers_per_vertex']:.0f} blockers")
    print(f"{name} ({len(v)}): " + " | ".join(cells), flush=True)


def invariance(name, scales, settings, with_move):
    """A solver built anew for every moved and turned copy, as the trust test builds them.
    Returns how many cases are beyond the test's bounds (marked "!")."""
    v, t = as_engine(STATIC[name])
    beyond = 0
    for scale in scales:
        base = ao(solver_of(v, t, scale, settings).solve(v))
        cells = []
        for case, m in TURNS.items():
            moved, tris = turned(v, t, m)
            d = np.abs(ao(solver_of(moved, tris, scale, settings).solve(moved)) - base)
            fails = bool(d.max() > TURN_BOUND or d.mean() > TURN_MEAN_BOUND)
            beyond += fails
            cells.append(f"{case} {d.max():.3f}" + "!" * fails)
        if with_move:
            far = moved_away(v)
            d = np.abs(ao(solver_of(far, t, scale, settings).solve(far)) - base)
            fails = bool(d.max() > MOVE_BOUND or (d > MOVE_NOTICEABLE).mean() > MOVE_NOTICEABLE_SHARE)
            beyond += fails
            cells.append(moved_cell(d) + "!" * fails)
        print(f"{name} near_scale {scale}: " + ", ".join(cells), flush=True)
    return beyond


def copies_against_exact(name, scales, settings):
    """The largest AO above the exact path over the mesh as given, moved and turned (each
    copy against its own exact path, every vertex), with the blockers per vertex."""
    v, t = as_engine(STATIC[name])
    copies = [(v, t), *moved_and_turned(v, t)]
    exact = [ao(hemishadow.transfer(*copy, bands=BANDS)) for copy in copies]
    cells = []
    for scale in scales:
        solvers = [solver_of(*copy, scale, settings) for copy in copies]
        worst = max((ao(s.solve(c[0])) - e).max() for s, c, e in zip(solvers, copies, exact))
        blockers = np.mean([s.stats["blockers_per_vertex"] for s in solvers])
        cells.append(f"{scale}: +{worst:.3f}{'!' * bool(worst > 0.1)}, {blockers:.0f} blockers")
    print(f"{name} ({len(v)}), worst of its copies: " + " | ".join(cells), flush=True)


def fixed_invariance(name, scales, settings):
    """One solver, built from the mesh, solving its moved and turned positions (the turns
    that keep the winding, which the solver's fixed triangles need)."""
    v, t = as_engine(STATIC[name])
    for scale in scales:
        solver = solver_of(v, t, scale, {**settings, "reuse": False})
        base = ao(solver.solve(v))
        cells = [f"{case} {np.abs(ao(solver.solve(turned(v, t, m)[0])) - base).max():.3f}"
                 for case, m in TURNS.items() if np.linalg.det(m) > 0]
        cells.append(moved_cell(np.abs(ao(solver.solve(moved_away(v))) - base)))
        print(f"{name} near_scale {scale}, hierarchy fixed: " + ", ".join(cells), flush=True)


def moved_cell(d):
    """The move's largest AO change and its vertices above MOVE_NOTICEABLE, with the test's bound."""
    allowed = int(MOVE_NOTICEABLE_SHARE * d.size)
    return f"moved {d.max():.4f} ({(d > MOVE_NOTICEABLE).sum()} above {MOVE_NOTICEABLE}, bound {allowed})"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scales", type=float, nargs="+", default=[1.0, 1.5, 2.0, 2.5])
    parser.add_argument("--fixed-hierarchy", action="store_true", help="only the invariance, one solver per mesh")
    parser.add_argument("--far-lod", type=float, help="the group tree's far_lod (0: no proxies)")
    parser.add_argument("--all-meshes", action="store_true",
                        help="only the invariance, on every mesh (the test checks spot and cesium_man), moved too")
    args = parser.parse_args()
    settings = {} if args.far_lod is None else {"far_lod": args.far_lod}
    if args.fixed_hierarchy:
        print(f"invariance with the hierarchy fixed, {INVARIANCE_BOUNDS}")
        for name in ("spot", "cesium_man"):
            fixed_invariance(name, args.scales, settings)
        return
    if args.all_meshes:
        print(f"invariance on every mesh, {INVARIANCE_BOUNDS}")
        beyond = sum(invariance(name, args.scales, settings, True) for name in sorted(STATIC))
        print(f"cases beyond the bounds: {beyond} of {len(STATIC) * (len(TURNS) + 1) * len(args.scales)}")
        print("AO above the exact path on the copies, bound: 0.1")
        for name in sorted(STATIC):
            copies_against_exact(name, args.scales, settings)
        return
    print("AO against the exact path (above / below it), bounds: 0.1")
    for name in sorted(STATIC):
        against_exact(name, args.scales, settings)
    print(f"invariance, {INVARIANCE_BOUNDS}")
    for name in ("spot", "cesium_man"):
        invariance(name, args.scales, settings, name == "spot")


if __name__ == "__main__":
    main()
