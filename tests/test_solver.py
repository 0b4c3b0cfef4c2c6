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


@pytest.mark.parametrize("far_lod", [hemishadow.TransferSolver.__init__.__kwdefaults__["far_lod"], 0.0, 0.9])
def test_reuse_returns_what_a_fresh_solve_returns(spot, far_lod):
    """Also with the group tree drawing most groups through proxies (0.9): a receiver is
    reused only when its walk down the tree is the same in both frames."""
    v, t = spot
    reusing = hemishadow.TransferSolver(v, t, far_lod=far_lod)
    fresh = hemishadow.TransferSolver(v, t, reuse=False, far_lod=far_lod)
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


def terrain(n=90):
    """Rolling hills on an n x n grid: every receiver sees distant slopes above its horizon."""
    x, y = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    z = 0.15 * np.sin(4 * x) * np.cos(3 * y) + 0.1 * x * x
    v = np.stack([x, y, z], axis=-1).reshape(-1, 3).astype(np.float32)
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    return v, np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)]).astype(np.uint32)


def test_group_tree_draws_distant_groups_coarser():
    """The third level: distant groups through proxies cost fewer blockers for a small error."""
    v, t = terrain()
    exact = hemishadow.TransferSolver(v, t, hierarchy=False, reuse=False).solve(v)
    two_levels = hemishadow.TransferSolver(v, t, far_lod=0, reuse=False)
    three = hemishadow.TransferSolver(v, t, far_lod=0.9, reuse=False)
    base, coarser = two_levels.solve(v), three.solve(v)
    assert three.stats["blockers_per_vertex"] < 0.8 * two_levels.stats["blockers_per_vertex"]
    lit = exact[:, 0] / hemishadow.AO_UNOCCLUDED >= 0.1
    for got in (base, coarser):
        errors = relative_l2_errors(got, exact)
        assert np.median(errors) <= 0.02 and errors[lit].mean() <= 0.05


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
    from meshes import rolled_sheet

    v, t = rolled_sheet()
    v = v.astype(np.float32)
    exact = hemishadow.transfer(v, t)
    lit = exact[:, 0] / hemishadow.AO_UNOCCLUDED >= 0.1
    worst, means = {}, {}
    for scale in (0.0, 2.5):
        solved = hemishadow.TransferSolver(v, t, coarse_triangles=150, near_scale=scale).solve(v)
        worst[scale] = np.abs(hemishadow.ambient_occlusion(solved) - hemishadow.ambient_occlusion(exact)).max()
        means[scale] = relative_l2_errors(solved, exact)[lit].mean()
    print(f"\nrolled sheet vs exact, max |dAO|: ring only {worst[0.0]:.3f}, near_scale 2.5 {worst[2.5]:.3f}")
    assert worst[0.0] > 0.5  # the coarse mesh cuts through the next turn: black speckles
    assert worst[2.5] <= 0.1 and means[2.5] <= 0.05


def test_progress_reports_rise_to_one_and_do_not_change_the_result(spot):
    v, t = spot
    dense = np.concatenate([v + np.float32(3 * i) for i in range(4)])  # 4 copies: several chunks
    tris = np.concatenate([t + len(v) * i for i in range(4)]).astype(np.uint32)
    reports = []
    with_progress = hemishadow.TransferSolver(dense, tris, bands=3).solve(dense, progress=reports.append)
    assert len(reports) >= 2 and reports[-1] == 1.0 and all(a < b for a, b in zip(reports, reports[1:]))
    assert np.array_equal(with_progress, hemishadow.TransferSolver(dense, tris, bands=3).solve(dense))
    reports.clear()
    ids = np.arange(2500)  # three chunks of the exact path
    exact = hemishadow.transfer(v, t, bands=3, receivers=ids, progress=reports.append)
    assert len(reports) == 3 and reports[-1] == 1.0
    assert np.array_equal(exact, hemishadow.transfer(v, t, bands=3, receivers=ids))


def test_cancel_stops_and_leaves_the_solver_as_it_was(spot):
    v, t = spot
    solver = hemishadow.TransferSolver(v, t, bands=3)
    first = solver.solve(v)
    moved = v * np.float32(1.01)
    with pytest.raises(hemishadow.Cancelled):
        solver.solve(moved, progress=lambda fraction: False)
    with pytest.raises(hemishadow.Cancelled):
        hemishadow.transfer(v, t, bands=3, progress=lambda fraction: False)
    assert np.array_equal(solver.solve(v), first)  # reuse still refers to the last finished frame
    assert solver.stats["reused"] == solver.stats["computed"] + solver.stats["reused"]


def test_progress_callback_errors_propagate(spot):
    v, t = spot

    def broken(fraction):
        raise KeyError("from the callback")

    with pytest.raises(KeyError, match="from the callback"):
        hemishadow.TransferSolver(v, t, bands=3).solve(v, progress=broken)
    with pytest.raises(ValueError, match="progress"):
        hemishadow.transfer(v, t, progress=3)


def test_receivers_subset_equals_rows_of_the_whole(spot):
    v, t = spot
    ids = np.array([5, 0, 3000, 5])
    assert np.array_equal(hemishadow.transfer(v, t, bands=3, receivers=ids), hemishadow.transfer(v, t, bands=3)[ids])
    for bad in ([len(v)], [-1], [[1, 2]], [0.5]):
        with pytest.raises(ValueError, match="receivers"):
            hemishadow.transfer(v, t, receivers=bad)


def test_loose_vertices_do_not_change_other_vertices(spot):
    v, t = spot
    loose = np.concatenate([v, np.float32([[40.0, -7.0, 90.0], [-300.0, 0.0, 0.0]])])
    base = hemishadow.TransferSolver(v, t).solve(v)
    with_loose = hemishadow.TransferSolver(loose, t).solve(loose)
    assert np.array_equal(with_loose[:len(v)], base) and not with_loose[len(v):].any()
    with pytest.warns(RuntimeWarning, match="2 vertices"):
        exact = hemishadow.transfer(loose, t)
    assert np.array_equal(exact[:len(v)], hemishadow.transfer(v, t))


def test_many_solvers_in_python_objects(spot):
    """Python allocates objects 16-byte aligned; the solver's 64-byte aligned masks must not
    live inside them (aligned vector loads crashed about every other solver)."""
    v, t = spot
    first = hemishadow.TransferSolver(v, t, bands=3).solve(v)
    for _ in range(8):
        np.testing.assert_array_equal(hemishadow.TransferSolver(v, t, bands=3).solve(v), first)
