"""What a lower `near_scale` does to the bounds of tests/test_solver_trust.py: per mesh, the
largest AO above and below the exact path (leaks and false shadows), the vertices more than
0.1 off and the blockers per receiver; on spot and cesium_man, the largest AO change under the
rotations and mirrors of the trust test and, on spot, the move 50 sizes away (largest change,
vertices above 0.005). docs/solver_speed.md quotes it.

Run: .venv/bin/python bench/near_scale_sweep.py [--scales 1.0 1.5 2.0 2.5]   (about 10 seconds on 2 cores)
"""

import argparse
import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
import hemishadow  # noqa: E402
from test_solver_trust import BANDS, STATIC, TURNS, ao, as_engine, receivers, turned  # noqa: E402


def against_exact(name, scales):
    v, t = as_engine(STATIC[name])
    ids = receivers(len(v))
    exact = ao(hemishadow.transfer(v, t, bands=BANDS, receivers=ids))
    cells = []
    for scale in scales:
        solver = hemishadow.TransferSolver(v, t, bands=BANDS, near_scale=scale)
        d = ao(solver.solve(v))[ids] - exact
        cells.append(f"{scale}: +{d.max():.3f} / -{max(-d.min(), 0):.3f}, {(np.abs(d) > 0.1).sum()} off, "
                     f"{solver.stats['blockers_per_vertex']:.0f} blockers")
    print(f"{name} ({len(v)}): " + " | ".join(cells), flush=True)


def turned_ao(v, t, matrix, scale):
    moved, tris = turned(v, t, matrix)
    return ao(hemishadow.TransferSolver(moved, tris, bands=BANDS, near_scale=scale).solve(moved))


def invariance(name, scales):
    v, t = as_engine(STATIC[name])
    for scale in scales:
        base = ao(hemishadow.TransferSolver(v, t, bands=BANDS, near_scale=scale).solve(v))
        cells = [f"{case} {np.abs(turned_ao(v, t, m, scale) - base).max():.3f}" for case, m in TURNS.items()]
        if name == "spot":
            far = v + np.float32(50.0)
            d = np.abs(ao(hemishadow.TransferSolver(far, t, bands=BANDS, near_scale=scale).solve(far)) - base)
            cells.append(f"moved {d.max():.4f} ({(d > 0.005).sum()} above 0.005)")
        print(f"{name} near_scale {scale}: " + ", ".join(cells), flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scales", type=float, nargs="+", default=[1.0, 1.5, 2.0, 2.5])
    args = parser.parse_args()
    print("AO against the exact path (above / below it), bounds: 0.1")
    for name in sorted(STATIC):
        against_exact(name, args.scales)
    print("invariance, bounds: 0.025 turned; moved 0.01 and 16 vertices above 0.005")
    for name in ("spot", "cesium_man"):
        invariance(name, args.scales)


if __name__ == "__main__":
    main()
