"""Adaptive supersampling of lightmaps (issue 11, `hemishadow.lightmap.refine`): which texels
get all their samples, and what the bake gives with it against a sample everywhere."""

import math

import numpy as np
import pytest

pytest.importorskip("hemishadow")
from hemishadow.lightmap import Sun, Surface, Target, bake, refine  # noqa: E402

from test_lightmap import cube, grid_plane, scene_of, uniform_sky  # noqa: E402


def field(values, usable=None):
    """(1, R, R, 1) values and (1, R, R) usable centres (all by default)."""
    values = np.asarray(values, np.float32)
    usable = np.ones(values.shape, bool) if usable is None else usable
    return values[None, ..., None], usable[None]


def interior(r):
    inside = np.zeros((r, r), bool)
    inside[1:-1, 1:-1] = True
    return inside


def test_linear_light_of_any_slope_refines_only_the_map_edge():
    y, x = np.mgrid[0:16, 0:16]
    for slope in (0.001, 0.05, 0.5):
        refined = refine.texels_to_refine(*field(1 + slope * (3 * x + 2 * y)))[0]
        assert refined[~interior(16)].all()  # no neighbour beyond the map's edge
        assert not refined[interior(16)].any()


def test_an_edge_refines_the_texels_on_both_sides_only():
    light = np.where(np.arange(16)[None, :] < 8, 1.0, 0.6) * np.ones((16, 1))
    refined = refine.texels_to_refine(*field(light))[0] & interior(16)
    assert np.array_equal(np.nonzero(refined.any(axis=0))[0], [7, 8])


def test_curving_light_refines_where_it_bends_more_than_the_contrast():
    x = np.arange(32, dtype=np.float64)
    light = np.tile(1 + 0.5 * np.exp(-x / 3), (32, 1))  # falloff near a wall at x = 0
    second = np.abs(light[0, 1:-1] - (light[0, :-2] + light[0, 2:]) / 2) / light[0, 1:-1]
    refined = refine.texels_to_refine(*field(light), contrast=0.01)[0][16, 1:-1]
    assert np.array_equal(refined, second > 0.01)


def test_unusable_centres_refine_themselves_and_their_neighbours():
    usable = np.ones((9, 9), bool)
    usable[4, 4] = False  # inside solid geometry, or outside the UV triangles
    refined = refine.texels_to_refine(*field(np.ones((9, 9)), usable))[0]
    assert refined[3:6, 3:6].all()
    assert not refined[interior(9)][np.abs(np.mgrid[0:9, 0:9] - 4).max(axis=0)[interior(9)] > 1].any()


def test_dark_texels_compare_as_a_hundredth_of_the_brightest():
    """Departures in the dark count against contrast x 1 % of the brightest texel, not against
    their own tiny values."""
    rng = np.random.default_rng(3)
    light = np.full((12, 12), 1e-3) + rng.uniform(0, 1.5e-4, (12, 12))  # 150 % swings of the dark level
    light[0, 0] = 1.0
    refined = refine.texels_to_refine(*field(light))[0]
    assert not refined[2:-1, 2:-1].any()
    light[6, 6] += 4e-4  # above 0.02 x 0.01 of the brightest
    assert refine.texels_to_refine(*field(light))[0][6, 6]


def test_adaptive_bake_matches_every_sample_for_far_fewer_samples(monkeypatch):
    """A wall on a plane under a sky and a sun: shadow edge, contact with the wall's footprint,
    light curving near the wall. Every sample of every texel (a sun ray each) against the
    adaptive bake: the same maps within 1 % of the open value, from well under half the samples
    (without more samples on the sun's edge: `edge_samples` = samples)."""
    v, t, uv = grid_plane(size=4, n=16)
    wall = cube([-0.2, -1.0, 0], [0.2, 1.0, 0.8])
    scene, (plane, _) = scene_of((v, t), wall)
    queried = []
    original = scene.visibility
    monkeypatch.setattr(scene, "visibility", lambda p, *a, **k: queried.append(len(p)) or original(p, *a, **k))
    maps = {}
    for adaptive in (False, True):
        queried.clear()
        maps[adaptive] = bake(scene, [Target(Surface(plane, v, t), uv)], resolution=64, lighting=uniform_sky(),
                              suns=[Sun((0.6, 0.3, 0.75), 3.0, math.radians(2))], samples=9, bounces=0,
                              adaptive=adaptive, adaptive_suns=False, edge_samples=9)[0]
        maps[adaptive]["samples"] = sum(queried)
    every, adaptive = maps[False], maps[True]
    covered = every["coverage"] > 0
    open_value = every["flat"][covered].max()
    for name in ("flat", "b0", "b1", "b2", "ao"):
        worst = np.abs(adaptive[name] - every[name])[covered].max() / (open_value if name != "ao" else 1.0)
        print(f"{name}: worst difference {100 * worst:.2f} % of the open value")
        assert worst < 0.01
    print("samples:", every["samples"], "adaptive:", adaptive["samples"])
    assert adaptive["samples"] < 0.45 * every["samples"]


def test_contrast_must_be_positive():
    v, t, uv = grid_plane()
    scene, (plane,) = scene_of((v, t))
    for bad in (0, -0.1, float("nan")):
        with pytest.raises(ValueError, match="contrast"):
            bake(scene, [Target(Surface(plane, v, t), uv)], resolution=8, lighting=uniform_sky(), contrast=bad)


def test_departures_within_least_never_refine():
    """A closed room's AO: a few cells of window, swinging by up to `AO_CELLS` cells from texel
    to texel (the mask's resolution) refines nothing; one cell more does."""
    from hemishadow.lightmap import cells

    cell = cells.largest_cell_ao()
    least = np.array([refine.AO_CELLS * cell])
    swings = np.where((np.add.outer(np.arange(12), np.arange(12)) % 2) == 0, 0.0, 0.999 * least[0])
    ao = 0.01 + swings
    assert refine.texels_to_refine(*field(ao))[0][interior(12)].all()  # without `least`: all of them
    assert not refine.texels_to_refine(*field(ao), full=np.array([1.0]), least=least)[0][interior(12)].any()
    ao[6, 6] += 2.1 * least[0]  # departs from its neighbours' mean by 1.1 x least
    refined = refine.texels_to_refine(*field(ao), full=np.array([1.0]), least=least)[0]
    assert refined[6, 6] and refined[interior(12)].sum() == 1 + 4
    assert refined[5, 5] and refined[7, 7] and refined[5, 7] and refined[7, 5]  # their diagonal means rise 1.05 x least
    assert 1 / 810 < cell < 1 / 790


def test_a_sun_edge_along_a_column_of_texels_takes_more_samples():
    """A wall's sun shadow whose edge runs along a row of texels, between a texel's samples
    (2 x 2) and its neighbour's: with 4 samples the texel is lit wholly, not for the part the
    sun reaches. Texels whose samples disagree on the sun, or agree but not with a side
    neighbour's, take `EDGE_SAMPLES` x 4 = 16: every texel within 0.1 of its lit fraction,
    from a 32 x 32 grid of exact rays per texel (`Scene.occluded`), the wall's footprint left
    out as the bake leaves out samples inside solid geometry."""
    v, t, uv = grid_plane(size=4, n=2)
    wall = cube([-2.0, -0.05, 0.0], [2.0, 0.05, 1.0])            # along x: its shadow edge runs along x too
    scene, (plane, _) = scene_of((v, t), wall)
    r = 16
    sun = Sun((0.0, -0.6, 0.8), 3.0, 0.0)                          # towards -y: the shadow falls on +y
    # the edge: where the ray clears the wall's top (y = 0.05, z = 1): y = 0.05 + 0.75 = 0.8, a
    # fifth into row 4 (y in [1, 0.75]), whose sample rows lie at y = 0.9375 and 0.8125
    target = [Target(Surface(plane, v, t), uv)]
    maps = {e: bake(scene, target, resolution=r, suns=[sun], samples=4, bounces=0, edge_samples=e)[0]["flat"][..., 0]
            for e in (4, None)}
    # reference: the fraction of a 32 x 32 grid of points per texel that the sun reaches
    g = (np.arange(32) + 0.5) / 32
    rows, cols = np.mgrid[0:r, 0:r]
    x = -2 + 4 * (cols[..., None, None] + g[None, None, None, :]) / r
    y = 2 - 4 * (rows[..., None, None] + g[None, None, :, None]) / r
    pts = np.stack(np.broadcast_arrays(x, y, np.zeros_like(x)), axis=-1).reshape(-1, 3).astype(np.float32)
    d = np.asarray(sun.direction) / np.linalg.norm(sun.direction)
    open_ = ~scene.occluded(pts + [0, 0, 1e-4], pts + 20 * d, offset=0.0)
    outside = np.abs(pts[:, 1]) > 0.05                              # the wall's footprint: invalid samples, left out
    lit = (open_ & outside).reshape(r, r, -1).sum(axis=-1) / np.maximum(outside.reshape(r, r, -1).sum(axis=-1), 1)
    full = maps[None].max()
    coarse = np.abs(maps[4] / full - lit).max()
    fine = np.abs(maps[None] / full - lit).max()
    print(f"worst texel off its lit fraction: 4 samples {coarse:.3f}, with edge samples {fine:.3f}")
    assert coarse > 0.15 and fine < 0.1
