"""The benchmark's measuring machinery (bench/curves.py, bench/peers.py): the equal-error
read-off on curves whose answer is known, and Embree on a process pool giving what one
process gives."""

import math
import pathlib
import sys

import numpy as np
import pytest

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "bench"))

import curves  # noqa: E402

A, PER_RAY = 0.6, 0.01  # error = A / sqrt(rays), ms = PER_RAY * rays: time = PER_RAY * A^2 / error^2


def law_curve(rays):
    return [(r, PER_RAY * r, A / math.sqrt(r)) for r in rays]


@pytest.mark.parametrize("b", [-0.5, -0.6, -0.75])
def test_fit_recovers_the_law(b):
    a, fitted, slope = curves.fit_law([64, 256, 1024], [A * n**b for n in (64, 256, 1024)])
    assert (a, fitted, slope) == pytest.approx((A, b, b), rel=1e-9)


@pytest.mark.parametrize("b, held", [(-1.2, -0.75), (0.1, -0.5)])
def test_fit_holds_the_exponent_within_monte_carlo_bounds(b, held):
    rays = [64, 256, 1024]
    a, fitted, slope = curves.fit_law(rays, [A * n**b for n in rays])
    assert slope == pytest.approx(b, rel=1e-9)
    assert fitted == held
    assert a * 1024**held == pytest.approx(A * 1024**b, rel=0.5)  # through the densest points


@pytest.mark.parametrize("error", [0.05, 0.02, 0.0123, A / 64 * 1.001])
def test_time_at_error_interpolates_log_log(error):
    curve = [(*p, "measured") for p in law_curve([64, 256, 1024, 4096])]
    ms, how = curves.time_at_error(error, curve)
    assert how == "interpolated"
    assert ms == pytest.approx(PER_RAY * A * A / error**2, rel=1e-9)


def test_time_at_error_outside_the_curve_follows_the_law():
    curve = [(*p, "measured") for p in law_curve([64, 256])]
    low, how_low = curves.time_at_error(A / 100, curve, -0.5)  # more accurate than 256 rays
    high, how_high = curves.time_at_error(A / 4, curve, -0.5)  # less accurate than 64 rays
    assert (how_low, how_high) == ("law, beyond 256 rays", "law, below 64 rays")
    assert low == pytest.approx(PER_RAY * 100**2, rel=1e-9)
    assert high == pytest.approx(PER_RAY * 4**2, rel=1e-9)


def test_extend_marks_and_fits_the_points_beyond_the_measured_ones():
    # measured with a fixed cost (BVH build) of 5 ms: time stays linear through the last two points;
    # stratified rays: error ~ N^-0.7
    measured = [(r, 5.0 + PER_RAY * r, A * r**-0.7) for r in (64, 256, 1024)]
    curve, b = curves.extend(measured, [64, 256, 1024, 4096, 16384])
    assert b == pytest.approx(-0.7, rel=1e-9)
    assert [p[3] for p in curve] == ["measured"] * 3 + ["fitted"] * 2
    r, ms, err, _ = curve[-1]
    assert r == 16384
    assert err == pytest.approx(A * 16384**-0.7, rel=1e-9)
    assert ms == pytest.approx(5.0 + PER_RAY * 16384, rel=1e-9)
    # read off the fitted part: the equal-error time of an error between 4096's and 16384's
    ms, how = curves.time_at_error(A * 8192**-0.7, curve, b)
    assert how == "interpolated"
    assert 5.0 + PER_RAY * 4096 < ms < 5.0 + PER_RAY * 16384
    # beyond the curve, time ~ rays ~ error^(1 / b)
    ms, how = curves.time_at_error(A * 65536**-0.7, curve, b)
    assert how == "law, beyond 16384 rays"
    assert ms == pytest.approx((5.0 + PER_RAY * 16384) * 4, rel=1e-9)


def occluded_sphere():
    import trimesh

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
    import reference

    sphere = trimesh.creation.icosphere(3)
    v = np.concatenate([sphere.vertices, 0.6 * sphere.vertices + [0.0, 0.0, 1.3]]).astype(np.float32)
    t = np.concatenate([sphere.faces, sphere.faces + len(sphere.vertices)])
    return v, t, reference.vertex_normals(v, t).astype(np.float32)


def test_embree_pool_gives_the_single_process_transfer():
    import peers

    v, t, n = occluded_sphere()
    single_T, single_ao = peers.embree_transfer(v, t, n, 1e-3, 8, seed=5)
    assert 0.05 < 1.0 - single_ao.min()  # some receivers are shadowed: the rays do something
    with peers.EmbreePool(workers=3) as pool:  # 3 uneven shares whatever the machine
        assert len(peers.shares(len(v), 3)) == 3
        pool_T, pool_ao = pool.solve(v, t, n, 1e-3, 8, seed=5)
        other_T, _ = pool.solve(v, t, n, 1e-3, 8, seed=6)
    np.testing.assert_array_equal(pool_T, single_T)
    np.testing.assert_array_equal(pool_ao, single_ao)
    assert np.abs(other_T - single_T).max() > 1e-3  # the seed matters: equality above is not vacuous


def test_shares_cover_every_receiver_once_in_whole_blocks():
    import peers

    for count in (1, 31, 130, 290, 1369, 10_000):
        for workers in (1, 2, 3, 8):
            parts = peers.shares(count, workers)
            assert sum(c for _, c in parts) == count
            assert all(first % peers.BLOCK == 0 for first, _ in parts)
            assert [f for f, _ in parts] == sorted(f for f, _ in parts)
            assert all(f + c == g for (f, c), (g, _) in zip(parts, parts[1:]))


def test_the_scale_target_reads_the_levels_timed_in_alternation():
    import report

    curve = [{"level": 3, "ms": 400.0, "vertices": 31658}, {"level": 4, "ms": 2000.0, "vertices": 126290}]
    pair = {"levels": [3, 4], "vertices": [31658, 126290], "ms": [400.0, 1700.0], "rounds": 8,
            "ratio": 4.25, "round_ratio_quartiles": [4.0, 4.2, 4.4]}
    row = report.scale_target({"vertex_curve": curve, "scale_pair": pair})
    assert "4.25x" in row and "alternation" in row and "quartiles 4.00 / 4.20 / 4.40" in row and "**met**" in row
    row = report.scale_target({"vertex_curve": curve})  # runs made before scale_pair: the curve's levels
    assert "5.00x" in row and "**not met**" in row
    assert "not in this run" in report.scale_target({"vertex_curve": curve[:1]})
