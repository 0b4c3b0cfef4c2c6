"""The per-mesh solver: the exact path equals `transfer`; the hierarchy stays close to it;
reuse never returns stale results; bad input is refused."""

import pathlib

import numpy as np
import pytest
import trimesh

import hemishadow
from reference import relative_l2_errors

DATA = pathlib.Path(__file__).resolve().parents[2] / "shared" / "data"


def load(name):
    mesh = trimesh.load(DATA / name, force="mesh", process=False)
    return np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.uint32)


@pytest.fixture(scope="module")
def spot():
    return load("spot.obj")




def test_exact_path_equals_transfer(spot):
    v, t = spot
    solver = hemishadow.TransferSolver(v, t, hierarchy=False)
    assert np.array_equal(solver.solve(v), hemishadow.transfer(v, t))
    unculled = hemishadow.TransferSolver(v, t, hierarchy=False, cull=False)
    assert np.array_equal(unculled.solve(v), hemishadow.transfer(v, t))


@pytest.mark.parametrize("name", ["spot.obj", "cesium_man.glb", "fox.glb"])
def test_hierarchy_stays_close_to_the_exact_path(name):
    v, t = load(name)
    exact = hemishadow.transfer(v, t)
    solver = hemishadow.TransferSolver(v, t)
    approx = solver.solve(v)
    lit = exact[:, 0] / hemishadow.AO_UNOCCLUDED >= 0.1
    errors = relative_l2_errors(approx, exact)
    print(f"\n{name}: coarse {solver.coarse_triangles} triangles, {solver.stats['blockers_per_vertex']:.0f} blockers"
          f" per vertex, vs exact: median {np.median(errors):.4f}, mean (AO>=0.1) {errors[lit].mean():.4f}")
    assert np.median(errors) <= 0.02
    assert errors[lit].mean() <= 0.05
    assert solver.stats["blockers_per_vertex"] < 0.25 * len(t)


def test_reuse_returns_what_a_fresh_solve_returns(spot):
    v, t = spot
    reusing = hemishadow.TransferSolver(v, t)
    fresh = hemishadow.TransferSolver(v, t, reuse=False)
    first = reusing.solve(v)
    again = reusing.solve(v)
    assert reusing.stats["reused"] == len(np.unique(v, axis=0)) and np.array_equal(first, again)
    # Move one region only: receivers whose blockers moved are recomputed, and every result
    # equals what a solver without reuse computes.
    moved = v.copy()
    region = v[:, 1] > np.percentile(v[:, 1], 90)
    moved[region] += np.array([0.0, 0.05, 0.02], np.float32)
    got = reusing.solve(moved)
    assert 0 < reusing.stats["reused"] < len(v)
    assert np.array_equal(got, fresh.solve(moved))


def test_glossy_solver_matches_transfer_on_the_exact_path(spot):
    v, t = spot
    view = np.array([0.2, 0.3, 0.93], np.float32)
    solver = hemishadow.TransferSolver(v, t, brdf="phong", exponent=8, hierarchy=False)
    expected = hemishadow.transfer(v, t, brdf="phong", exponent=8, view=view)
    assert np.array_equal(solver.solve(v, view=view), expected)
    with pytest.raises(ValueError, match="view"):
        solver.solve(v)


def test_bad_input(spot):
    v, t = spot
    solver = hemishadow.TransferSolver(v, t)
    with pytest.raises(ValueError, match="topology changed"):
        solver.solve(v[:-1])
    bad = v.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        solver.solve(bad)
    with pytest.raises(ValueError, match="ring"):
        hemishadow.TransferSolver(v, t, ring=3)
    with pytest.raises(ValueError, match="coarse_triangles"):
        hemishadow.TransferSolver(v, t, coarse_triangles=0)
    with pytest.raises(ValueError, match="empty"):
        hemishadow.TransferSolver(np.zeros((0, 3)), np.zeros((0, 3), int))


@pytest.mark.parametrize("name", ["spot.obj", "cesium_man.glb"])
def test_state_per_vertex_is_under_a_kilobyte(name):
    v, t = load(name)
    solver = hemishadow.TransferSolver(v, t)
    solver.solve(v)
    per_vertex = solver.memory_bytes / solver.vertex_count
    print(f"\n{name}: {per_vertex:.0f} bytes of solver state per vertex")
    assert per_vertex <= 1024


def test_close_geometry_far_along_the_surface_is_seen_at_full_resolution():
    """A rolled sheet: its turns are close in space but far apart along the surface, where a
    k-ring alone would leave the coarse mesh cutting through them."""
    from test_transfer_accuracy import rolled_sheet

    v, t = rolled_sheet()
    v = v.astype(np.float32)
    exact = hemishadow.transfer(v, t)
    lit = exact[:, 0] / hemishadow.AO_UNOCCLUDED >= 0.1
    means = {}
    for scale in (0.0, 1.5):
        solver = hemishadow.TransferSolver(v, t, coarse_triangles=150, near_scale=scale)
        means[scale] = relative_l2_errors(solver.solve(v), exact)[lit].mean()
    print(f"\nrolled sheet vs exact, mean (AO>=0.1): ring only {means[0.0]:.4f}, near_scale 1.5 {means[1.5]:.4f}")
    assert means[1.5] < 0.6 * means[0.0]
    assert means[1.5] <= 0.05
