"""The hemispherical rasterizer against an exact per-cell test of the three half-spaces.

A cell of the 32x32 disk mask is inside a blocker triangle when the direction through its
centre lies on the inner side of the three planes through the receiver and an edge. The
engine looks the half-space masks up in a table of quantised plane normals, so cells within
about one table texel of an edge may differ; nothing else may.
"""

import json
import pathlib

import numpy as np
import pytest

import hemishadow

SIDE = 32
RESULTS = pathlib.Path(__file__).parent / ".results"


def cell_directions():
    centres = -1 + (np.arange(SIDE) + 0.5) / 16
    x, y = np.meshgrid(centres, centres)  # x along columns, y along rows
    r2 = x * x + y * y
    inside = r2 < 1
    z = np.sqrt(np.clip(1 - r2, 0, None))
    return np.stack([x, y, z], axis=-1), inside


DIRS, DISK = cell_directions()


def exact_mask(tri):
    """Cells whose centre direction is in the cone of tri (float64, no table)."""
    a, b, c = np.asarray(tri, dtype=np.float64)
    det = np.dot(np.cross(a, b), c)
    if abs(det) <= 1e-6 * np.linalg.norm(a) * np.linalg.norm(b) * np.linalg.norm(c):
        return np.zeros((SIDE, SIDE), bool)
    sign = np.sign(det)
    inside = DISK.copy()
    for p, q in ((a, b), (b, c), (c, a)):
        inside &= (DIRS @ (sign * np.cross(p, q))) >= 0
    return inside


def random_triangles(rng, count):
    """Blockers of every kind: above, crossing the horizon, below, near and far, large and sliver."""
    centres = rng.normal(size=(count, 3)) * rng.choice([0.3, 1.0, 3.0], size=(count, 1))
    centres[:, 2] += rng.uniform(-0.5, 1.5, size=count)
    sizes = rng.choice([0.05, 0.3, 1.0, 4.0], size=(count, 1, 1))
    return centres[:, None, :] + rng.normal(size=(count, 3, 3)) * sizes


def test_random_triangles_match_exact_half_spaces():
    rng = np.random.default_rng(1)
    tris = random_triangles(rng, 4000)
    wrong = covered = 0
    worst = 0
    for tri in tris:
        exact = exact_mask(tri)
        got = hemishadow.rasterize_local(tri[None])
        assert not (got & ~DISK).any(), "cells outside the disk must never be set"
        diff = int((got != exact).sum())
        wrong += diff
        covered += int(exact.sum())
        worst = max(worst, diff)
    share_of_cells = wrong / (len(tris) * int(DISK.sum()))
    share_of_covered = wrong / covered
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "rasterizer.json").write_text(json.dumps({
        "triangles": len(tris), "wrong_cells": wrong, "share_of_all_disk_cells": share_of_cells,
        "share_of_covered_cells": share_of_covered, "worst_triangle_wrong_cells": worst}, indent=1))
    print(f"\nrasterizer: {wrong} wrong cells over {len(tris)} triangles: {share_of_cells:.4%} of all disk "
          f"cells, {share_of_covered:.3%} of covered cells, worst triangle {worst} cells")
    assert share_of_cells < 0.002
    assert share_of_covered < 0.02


def test_wrong_cells_lie_next_to_an_edge_plane():
    """Quantisation may only flip cells whose centre is within a texel's angle of an edge plane."""
    rng = np.random.default_rng(2)
    texel_angle = 2.0 / 128  # cube-map texel width at the face centre, in radians (upper bound ~2x)
    for tri in random_triangles(rng, 1500):
        diff = hemishadow.rasterize_local(tri[None]) != exact_mask(tri)
        if not diff.any():
            continue
        a, b, c = tri
        planes = [np.cross(p, q) / np.linalg.norm(np.cross(p, q)) for p, q in ((a, b), (b, c), (c, a))]
        distance = np.min([np.abs(DIRS[diff] @ m) for m in planes], axis=0)
        assert distance.max() < 2 * texel_angle, distance.max()


def test_occluder_fusion_has_no_cracks():
    """Two triangles sharing an edge rasterize to the exact quad: no gap along the seam."""
    quad = np.array([[-0.8, -0.6, 1.0], [0.9, -0.5, 0.7], [0.7, 0.8, 1.2], [-0.6, 0.7, 0.9]])
    halves = np.array([quad[[0, 1, 2]], quad[[0, 2, 3]]])
    fused = hemishadow.rasterize_local(halves)
    exact = exact_mask(halves[0]) | exact_mask(halves[1])
    assert (fused != exact).sum() <= 4
    # In any order, and repeated: OR is order-independent and idempotent.
    assert (hemishadow.rasterize_local(halves[::-1]) == fused).all()
    assert (hemishadow.rasterize_local(np.concatenate([halves, halves])) == fused).all()


def test_overlapping_triangles_fuse_to_union():
    rng = np.random.default_rng(3)
    tris = random_triangles(rng, 30)
    union = np.zeros((SIDE, SIDE), bool)
    for tri in tris:
        union |= hemishadow.rasterize_local(tri[None])
    assert (hemishadow.rasterize_local(tris) == union).all()


def test_horizon_crossing_triangle():
    tri = np.array([[2.0, -1.0, -0.5], [2.0, 1.0, -0.5], [0.5, 0.0, 2.0]])
    got = hemishadow.rasterize_local(tri[None])
    exact = exact_mask(tri)
    assert exact.sum() > 50
    assert (got != exact).sum() <= 0.05 * exact.sum()


@pytest.mark.parametrize("tri", [
    [[1.0, 0.0, -0.1], [0.0, 1.0, -0.2], [-1.0, -1.0, -0.3]],    # below the horizon
    [[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]],         # touches the receiver
    [[1.0, 0.0, 1.0], [2.0, 0.0, 2.0], [3.0, 0.0, 3.0]],         # collinear
    [[1.0, 1.0, 1.0], [1.0, 1.0, 1.0], [0.0, 1.0, 2.0]],         # repeated vertex
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, -1.0, 0.0]],       # in the tangent plane, around the receiver
    [[-1.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 0.0, 2.0]],        # its plane contains the receiver
])
def test_degenerate_triangles_cover_nothing(tri):
    assert not hemishadow.rasterize_local(np.array([tri])).any()


def test_triangle_behind_covers_only_its_upper_part():
    """A triangle behind the receiver (mostly below) covers exactly its part above the horizon."""
    tri = np.array([[-1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-0.2, 0.0, 0.3]])
    got = hemishadow.rasterize_local(tri[None])
    assert (got != exact_mask(tri)).sum() <= 3


def test_huge_roof_blocks_nearly_the_whole_disk():
    roof = np.array([[[-1e4, -1e4, 1.0], [1e4, -1e4, 1.0], [1e4, 1e4, 1.0]],
                     [[-1e4, -1e4, 1.0], [1e4, 1e4, 1.0], [-1e4, 1e4, 1.0]]])
    got = hemishadow.rasterize_local(roof)
    assert got.sum() >= DISK.sum() - 4
