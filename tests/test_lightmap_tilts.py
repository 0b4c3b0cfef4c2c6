"""Lightmaps (issue 11): masks through four turned lattices and the tent filter that averages
them (hemishadow/lightmap/tilts.py), against ray casting.

Run from a worktree with PYTHONPATH=native/python when the installed package is another
checkout's.
"""

import importlib
import math

import numpy as np
import pytest

hemishadow = pytest.importorskip("hemishadow")
import trimesh  # noqa: E402
from trimesh.ray.ray_pyembree import RayMeshIntersector  # noqa: E402

from hemishadow.lightmap import Surface, Target, bake, cells, sparse_gather, tent, tilts  # noqa: E402
from test_lightmap import cube, grid_plane, scene_of, uniform_sky  # noqa: E402

bake_module = importlib.import_module("hemishadow.lightmap.bake")  # `lm.bake` is the function


def test_a_texel_and_its_row_neighbour_turn_opposite_ways():
    dx, dy = np.meshgrid(np.arange(4), np.arange(4))
    first = tilts.classes(dx.ravel(), dy.ravel(), 0).reshape(4, 4)
    assert sorted(first[:2, :2].ravel()) == [0, 1, 2, 3]       # each 2 x 2 block: all four
    assert (first[:, 0::2] ^ 1 == first[:, 1::2]).all()        # side neighbours: opposite turns
    for x, y in ((0, 0), (3, 2), (5, 7)):
        assert sorted(tilts.classes(np.full(4, x), np.full(4, y), np.arange(4))) == [0, 1, 2, 3]  # a texel's samples
        assert tilts.classes(x, y, 0) ^ 1 == tilts.classes(x, y, 1)  # its samples 0 and 1: opposite turns


def test_tilted_normals_turn_by_the_tilt_and_cancel_in_pairs():
    rng = np.random.default_rng(3)
    ng = rng.normal(size=(50, 3))
    ng /= np.linalg.norm(ng, axis=1, keepdims=True)
    turned = [tilts.tilted_normals(ng, np.full(len(ng), k)) for k in range(4)]
    for k, n in enumerate(turned):
        assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
        assert np.allclose(np.arccos(np.clip((n * ng).sum(1), -1, 1)), tilts.TILT, atol=1e-9), k
    for k in (0, 2):                                           # opposite turns: the mean lies along ng
        mean = (turned[k] + turned[k + 1]) / 2
        assert np.allclose(mean, np.cos(tilts.TILT) * ng, atol=1e-12)
    t, b = cells.engine_frame(ng)
    assert np.allclose(((turned[0] - turned[1]) * b).sum(1), 0, atol=1e-12)    # 0 and 1 turn along t
    assert np.allclose(((turned[2] - turned[3]) * t).sum(1), 0, atol=1e-12)    # 2 and 3 along b
    assert (tilts.tilted_normals(ng, np.full(len(ng), -1)) == ng).all()        # -1: untouched


def _grid_samples(rows, cols, spacing=0.1):
    """One sample per texel of a rows x cols grid on the plane z = 0."""
    r, c = np.divmod(np.arange(rows * cols), cols)
    points = np.stack([c * spacing, -r * spacing, np.zeros(rows * cols)], axis=1)
    normals = np.tile([0.0, 0.0, 1.0], (rows * cols, 1))
    return points, normals, np.arange(rows * cols), (1, rows, cols)


def test_smoothed_is_a_tent_that_stays_on_its_surface():
    points, normals, cell, shape = _grid_samples(6, 6)
    rng = np.random.default_rng(0)
    values = rng.random((36, 2)).astype(np.float32)
    valid = np.ones(36, bool)
    spacing = np.full(36, 0.1)
    grid = sparse_gather.Grid(cell, valid, shape)
    out = tent.smoothed(values, grid, points, normals, spacing, valid)
    v = values.reshape(6, 6, 2)
    kernel = np.outer([1, 2, 1], [1, 2, 1]) / 16
    expected = (v[1:4, 1:4] * kernel[..., None]).sum((0, 1))    # texel (2, 2): inside, the full tent
    assert np.allclose(out[2 * 6 + 2], expected, atol=1e-6)
    corner = (v[:2, :2] * kernel[1:, 1:, None]).sum((0, 1)) / kernel[1:, 1:].sum()  # the map's corner: renormalised
    assert np.allclose(out[0], corner, atol=1e-6)

    use = valid.copy()
    use[3] = False                                              # not smoothed, and nobody's neighbour
    other = np.zeros(36, np.int64)
    other.reshape(6, 6)[:, 4:] = 1                             # columns 4, 5: another target (an atlas)
    far = points.copy()
    far.reshape(6, 6, 3)[4:, :, 2] += 1.0                      # rows 4, 5: another island, a metre up
    folded = normals.copy()
    folded.reshape(6, 6, 3)[:, 0] = (1.0, 0.0, 0.0)            # column 0: a wall at 90 degrees
    out = tent.smoothed(values, sparse_gather.Grid(cell, valid, shape, group=other), far, folded, spacing, use)
    assert (out[3] == values[3]).all()
    for r in range(6):
        for c in range(6):
            mine = 6 * r + c
            if not use[mine]:
                continue
            same = [(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1)
                    if 0 <= r + dr < 6 and 0 <= c + dc < 6 and use[6 * (r + dr) + c + dc]
                    and other[6 * (r + dr) + c + dc] == other[mine] and (r + dr >= 4) == (r >= 4)
                    and (c + dc == 0) == (c == 0)]
            w = np.array([(2 - abs(dr)) * (2 - abs(dc)) for dr, dc in same], float)
            want = (w[:, None] * np.array([values[6 * (r + dr) + c + dc] for dr, dc in same])).sum(0) / w.sum()
            assert np.allclose(out[mine], want, atol=1e-6), (r, c)


def _canopy_scene():
    """A 2 x 2 m plane, half under a wide canopy 0.8 m up and with a small box floating over
    the other half: the canopy's edge crosses each texel's sky at an elevation that changes
    slowly across the map, so a single lattice steps where the edge crosses its cells."""
    v, t, uv = grid_plane(size=2.0, n=8)
    blockers = [cube([-3.0, -3.0, 0.8], [-0.2, 3.0, 0.9]), cube([0.3, -0.3, 0.5], [0.5, 0.3, 0.6])]
    scene, ids = scene_of((v, t), *blockers)
    return scene, Target(Surface(ids[0], v, t), uv), blockers


def _open_fraction_reference(blockers, r, n_side=32, seed=1):
    """The cosine-weighted open fraction (E / pi under a sky of radiance 1) of each texel, the
    mean over 2 x 2 points in it of n_side^2 stratified cosine-weighted rays (Embree)."""
    caster = RayMeshIntersector(trimesh.util.concatenate([trimesh.Trimesh(*b, process=False) for b in blockers]))
    c = (np.arange(r) + 0.5) / r * 2 - 1
    x, y = np.meshgrid(c, -c)
    rng = np.random.default_rng(seed)
    total = np.zeros(r * r)
    for dx, dy in ((-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)):
        points = np.stack([x.ravel() + dx * 2 / r, y.ravel() + dy * 2 / r, np.full(x.size, 1e-4)], axis=1)
        u1 = (np.arange(n_side)[:, None] + rng.random((n_side, n_side))) / n_side
        u2 = (np.arange(n_side)[None, :] + rng.random((n_side, n_side))) / n_side
        radius, phi = np.sqrt(u1.ravel()), 2 * math.pi * u2.ravel()
        dirs = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.sqrt(1 - radius ** 2)], axis=1)
        blocked = caster.intersects_any(np.repeat(points, len(dirs), axis=0), np.tile(dirs, (len(points), 1)))
        total += (~blocked.reshape(len(points), -1)).mean(axis=1) / 4
    return total.reshape(r, r)


def test_turned_lattices_take_the_steps_out_of_the_sky(monkeypatch):
    """Sky light on the canopy's plane against ray casting, as a share of the mean: 0.55 %
    on average and 2.2 % at worst with the turned lattices, 0.76 % and 3.1 % with one."""
    scene, target, blockers = _canopy_scene()
    r = 32
    reference = _open_fraction_reference(blockers, r)

    def errors():
        out = bake(scene, [target], resolution=r, lighting=uniform_sky(), bounces=0, basis="flat", margin=0)[0]
        keep = out["valid"] > 0
        keep[:2], keep[-2:], keep[:, :2], keep[:, -2:] = False, False, False, False  # the plane's rim
        error = np.abs(out["flat"][..., 0] - reference)[keep] / reference[keep].mean()
        return error.mean(), error.max()

    mean, worst = errors()
    print(f"turned lattices: mean {100 * mean:.2f} %, worst {100 * worst:.2f} %")
    assert mean < 0.0065 and worst < 0.027
    monkeypatch.setattr(tilts, "TILT", 0.0)
    monkeypatch.setattr(bake_module, "_smoothed_environment", lambda lit, smooth: lit)
    single_mean, single_worst = errors()
    print(f"one lattice: mean {100 * single_mean:.2f} %, worst {100 * single_worst:.2f} %")
    assert single_mean > 1.25 * mean and single_worst > 1.25 * worst   # what the turns are for
