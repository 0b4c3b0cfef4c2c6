"""Bounce light gathered at fewer texels (issue 11, `hemishadow.lightmap.sparse_gather`):
which texels gather, what the others get, and a bake against gathering at every texel."""

import math

import numpy as np
import pytest

pytest.importorskip("hemishadow")
from hemishadow.lightmap import Sun, Surface, Target, bake, sparse_gather  # noqa: E402

from test_lightmap import cube, grid_plane, scene_of, uniform_sky  # noqa: E402


def plane_receivers(r, layers=1):
    """Receivers at the texel centres of an r x r map on the unit square z = 0, facing +Z."""
    cell = np.arange(layers * r * r)
    row, col = cell // r % r, cell % r
    points = np.stack([(col + 0.5) / r, 1 - (row + 0.5) / r, np.zeros(len(cell))], axis=1)
    normals = np.tile([0.0, 0.0, 1.0], (len(cell), 1))
    return points, normals, cell, (layers, r, r)


def run(field, r=32, valid=None, distance=np.inf, floor=None, contrast=sparse_gather.CONTRAST):
    """sparse_gather.gather of a known field(points) -> (N, K, 3); returns the result and
    which receivers gathered."""
    points, normals, cell, shape = plane_receivers(r)
    valid = np.ones(len(cell), bool) if valid is None else valid
    asked = []

    def gather_at(i):
        asked.append(np.asarray(i))
        return field(points[i]), np.full(len(i), distance, np.float32)

    out = sparse_gather.gather(gather_at, 9, points, normals, sparse_gather.Grid(cell, valid, shape), contrast=contrast,
                               floor=floor)
    gathered = np.zeros(len(cell), bool)
    for i in asked:
        assert not gathered[i].any()  # each receiver at most once
        gathered[i] = True
    return out, gathered, field(points)


def lattice_only(gathered, r=32):
    """Whether exactly the coarse lattice gathered, short of the map's last rows and columns
    (beyond the last lattice line, texels have a lattice neighbour on one side only)."""
    row, col = np.divmod(np.arange(r * r), r)
    inner = (row <= r - 4) & (col <= r - 4)
    return np.array_equal(gathered[inner], ((row % 4 == 0) & (col % 4 == 0))[inner])


def sh_field(values):
    """(N,) values -> (N, 9, 3) SH with every coefficient a fixed multiple of them."""
    scale = np.linspace(1.0, 0.2, 9, dtype=np.float32)[None, :, None] * np.array([1.0, 0.8, 0.6], np.float32)
    return (np.asarray(values, np.float32)[:, None, None] * scale).astype(np.float32)


def test_a_linear_field_gathers_on_the_coarse_lattice_only_and_is_exact():
    out, gathered, exact = run(lambda p: sh_field(1 + 0.7 * p[:, 0] - 0.4 * p[:, 1]))
    assert lattice_only(gathered)
    np.testing.assert_allclose(out, exact, rtol=1e-5, atol=1e-6)


def test_curving_light_gathers_where_a_mean_would_miss_by_more_than_the_contrast():
    """A bump of bounce light: the mean of two lattice texels misses by about an eighth of the
    second difference; every texel interpolated is near the contrast of the field (the second
    difference is estimated at the lattice texels, not where the mean is taken)."""
    bump = lambda p: sh_field(1 + 2.0 * np.exp(-((p[:, 0] - 0.5) ** 2 + (p[:, 1] - 0.5) ** 2) / 0.02))
    out, gathered, exact = run(bump)
    band0 = exact[:, 0, 0]
    error = np.abs(out - exact)[:, 0, 0] / band0
    assert 0.15 < gathered.mean() < 0.9, gathered.mean()  # the bump gathers, the flat outskirts do not
    assert error.max() < 1.25 * sparse_gather.CONTRAST and np.median(error[error > 0]) < 0.5 * sparse_gather.CONTRAST
    strict = run(bump, contrast=1e-6)[0]
    np.testing.assert_allclose(strict, exact, rtol=1e-6)  # no error allowed: every texel off the lattice gathers


def test_a_shadow_edge_between_lattice_texels_gathers_around_it():
    out, gathered, exact = run(lambda p: sh_field(np.where(p[:, 0] < 0.4, 1.0, 0.3)))
    np.testing.assert_allclose(out, exact, rtol=1e-6)
    points = plane_receivers(32)[0]
    assert gathered[np.abs(points[:, 0] - 0.4) < 1 / 32].all()


def test_the_direct_light_floor_lets_dim_bounce_interpolate():
    """Bounce light bending at 30 % of itself gathers everywhere on its own, but not where
    direct light 100 times brighter lands: the error is measured against all the light."""
    ripple = lambda p: sh_field(0.01 * (1 + 0.3 * np.sin(20 * p[:, 0])))
    _, alone, _ = run(ripple)
    out, lit, exact = run(ripple, floor=np.full((32 * 32, 3), 1.0, np.float32))
    assert alone.mean() > 0.9 and lattice_only(lit)
    assert np.abs(out - exact)[:, 0].max() < sparse_gather.CONTRAST * 1.0


def test_receivers_near_what_they_see_gather():
    """Irradiance caching's distance: texels 1/32 apart, seeing geometry 0.05 away, all gather
    (spacing 4/32 > 0.05), whatever the light; at distance 1 the lattice alone does."""
    flat = lambda p: sh_field(np.ones(len(p)))
    assert run(flat, distance=0.05)[1].mean() > 0.9
    assert lattice_only(run(flat, distance=1.0)[1])


def test_invalid_receivers_gather_nothing_and_break_the_means_around_them():
    points, *_ = plane_receivers(32)
    valid = np.linalg.norm(points[:, :2] - 0.5, axis=1) > 0.1  # a leg's footprint
    out, gathered, exact = run(lambda p: sh_field(1 + p[:, 0]), valid=valid)
    assert not gathered[~valid].any() and not out[~valid].any()
    np.testing.assert_allclose(out[valid], exact[valid], rtol=1e-5)


def test_a_texel_across_a_seam_from_its_neighbours_gathers():
    """Texels side by side in UV space but far apart on the surface (another island) never
    interpolate between them: column 7 lies between columns 6 and 8, on two sides."""

    def gathered_columns(seam):
        points, normals, cell, shape = plane_receivers(16)
        if seam:
            points[points[:, 0] > 0.5, 2] += 3.0  # columns 8-15 are elsewhere
        asked = []
        out = sparse_gather.gather(lambda i: (asked.append(i), (sh_field(np.ones(len(i))), np.full(len(i), np.inf)))[1],
                                   9, points, normals, sparse_gather.Grid(cell, np.ones(len(cell), bool), shape))
        np.testing.assert_allclose(out, sh_field(np.ones(len(cell))))
        gathered = np.zeros(len(cell), bool)
        gathered[np.concatenate(asked)] = True
        return gathered.reshape(16, 16)

    assert gathered_columns(True)[:, 7].all()
    assert not gathered_columns(False)[:12, 7].any()


def test_bake_matches_gathering_at_every_texel(monkeypatch):
    """A wall on a plane under a sky, a sun and its bounce: the bake with sparse gathers
    against a gather at every texel (LEVELS = 0), within 1 % of each texel's light (0.1 % on
    average; measured 0.42 % and 0.019 %), from far fewer gathers (724 of 3,968)."""
    v, t, uv = grid_plane(size=4, n=16)
    wall = cube([-0.1, -1.0, 0], [0.1, 1.0, 1.2])
    scene, (plane, wall_id) = scene_of((v, t), wall)
    target = [Target(Surface(plane, v, t, albedo=0.8), uv)]
    counts, maps = {}, {}
    original = scene.gather_views
    for levels in (0, sparse_gather.LEVELS):
        monkeypatch.setattr(sparse_gather, "LEVELS", levels)
        asked = []
        monkeypatch.setattr(scene, "gather_views", lambda p, *a, **k: asked.append(len(p)) or original(p, *a, **k))
        maps[levels] = bake(scene, target, resolution=64, lighting=uniform_sky(0.5), surfaces=[Surface(wall_id, *wall, albedo=0.8)],
                            suns=[Sun((0.6, 0.3, 0.75), 3.0, math.radians(2))], bounces=2, samples=1)[0]["flat"]
        counts[levels] = sum(asked)
    every, sparse = maps[0], maps[sparse_gather.LEVELS]
    relative = np.abs(sparse - every).max(axis=-1) / np.maximum(every.max(axis=-1), 1e-6)
    print(f"gathers: {counts[0]} -> {counts[sparse_gather.LEVELS]}; worst {100 * relative.max():.2f} %, "
          f"mean {100 * relative.mean():.3f} %")
    assert relative.max() < 0.01 and relative.mean() < 0.001
    assert counts[sparse_gather.LEVELS] < 0.4 * counts[0]
