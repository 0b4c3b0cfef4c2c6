"""Lightmap atlas, the engine part (issue 11): several targets baked into one map, each in its
slot, read the same texels as when baked alone; padding stays with its own islands.

Run from a worktree with PYTHONPATH=native/python when the installed package is another
checkout's.
"""

import numpy as np
import pytest

hemishadow = pytest.importorskip("hemishadow")
from hemishadow.lightmap import Sun, Surface, Target, bake  # noqa: E402
from test_lightmap import cube, cylinder, grid_plane, scene_of, uniform_sky  # noqa: E402

R = 64


def slot(uv, size, row, col, resolution=R):
    """UVs of a size x size map moved to texel (row, col) of a resolution x resolution map:
    alone texel (r, c) becomes atlas texel (r + row, c + col)."""
    uv = np.asarray(uv, np.float64)
    return np.stack([(uv[..., 0] * size + col) / resolution,
                     1 - ((1 - uv[..., 1]) * size + row) / resolution], axis=-1)


@pytest.mark.parametrize("plane_at, cylinder_at", [((4, 4), (4, 28)), ((5, 3), (5, 29))])
def test_atlas_texels_match_each_target_baked_alone(plane_at, cylinder_at):
    """Even and odd slot places: each texel's mask turns by its place relative to its
    triangle's UV box (`tilts.classes`), not by its row and column in the map."""
    v, t, plane_uv = grid_plane(size=2.0, n=4)
    plane_uv = 0.125 + 0.75 * plane_uv                 # room for padding inside its own 16^2 map
    cv, ct, cyl_uv = cylinder()                          # a UV seam: the stitch pass runs
    cv = cv + (1.6, 0.0, 0.0)
    box = cube([-0.4, -0.4, 0.3], [0.4, 0.4, 0.6])      # floating: a soft shadow on the plane
    scene, (pid, cid, _) = scene_of((v, t), (cv, ct), box)
    plane, cyl = Surface(pid, v, t, albedo=0.6), Surface(cid, cv, ct, albedo=0.5)
    kwargs = dict(lighting=uniform_sky(0.5), suns=[Sun((0.3, -0.6, 0.7), 3.0, 0.02)], bounces=1, margin=2,
                  samples=4)
    alone_plane = bake(scene, [Target(plane, plane_uv)], resolution=16, surfaces=[cyl], **kwargs)[0]
    alone_cyl = bake(scene, [Target(cyl, cyl_uv)], resolution=32, surfaces=[plane], **kwargs)[0]
    out = bake(scene, [Target(plane, slot(plane_uv, 16, *plane_at)), Target(cyl, slot(cyl_uv, 32, *cylinder_at))],
               resolution=R, atlas=True, **kwargs)
    assert len(out) == 1
    atlas = out[0]
    worst = {}
    for alone, (row, col, size) in ((alone_plane, (*plane_at, 16)), (alone_cyl, (*cylinder_at, 32))):
        window = (slice(row, row + size), slice(col, col + size))
        for name in ("flat", "b0", "b1", "b2", "ao", "coverage", "valid"):
            a, b = np.asarray(atlas[name][window], np.float64), np.asarray(alone[name], np.float64)
            worst[name] = max(worst.get(name, 0.0), np.abs(a - b).max())
        assert atlas["coverage"][window].sum() > 0.3 * size * size
    print(worst)
    assert max(worst.values()) < 1e-4                    # the same texels, remapped through the slot
    assert atlas["flat"][40:, :].max() == 0             # nothing outside the slots and their padding
    window = (slice(plane_at[0], plane_at[0] + 16), slice(plane_at[1], plane_at[1] + 16))
    assert np.abs(atlas["flat"][window] - alone_plane["flat"]).max() < 1e-4


def test_padding_does_not_cross_into_another_targets_islands():
    """A lit plane and a dark one (facing away from the sun) three texels apart, margin 4:
    each island keeps its own values and each gap texel its nearest island's."""
    quad = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]], np.float64)
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    down = quad + (3.0, 0.0, 0.0)
    down_tris = tris[:, ::-1]                            # faces -Z: the sun never reaches it
    unit = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float64)
    scene, (a, b) = scene_of((quad, tris), (down, down_tris))
    targets = [Target(Surface(a, quad, tris), slot(unit, 8, 4, 4, 32)),
               Target(Surface(b, down, down_tris), slot(unit[:, ::-1], 8, 4, 15, 32))]
    out = bake(scene, targets, resolution=32, suns=[Sun((0, 0, 1), 2.0)], bounces=0, margin=4, atlas=True)[0]
    flat = out["flat"][..., 0]
    assert np.abs(flat[4:12, 4:12] - 2 / np.pi).max() < 1e-4   # lit island: E / pi
    assert flat[4:12, 15:23].max() == 0                       # dark island: no light bled in
    assert np.abs(flat[4:12, 12:14] - 2 / np.pi).max() < 1e-4  # gap texels nearer the lit one
    assert flat[4:12, 14].max() == 0                           # and nearer the dark one
    assert flat[0, 4:12].min() > 0.6 and flat[4:12, 26].max() == 0  # 4 texels of padding each


def test_atlas_needs_one_resolution():
    v, t, uv = grid_plane()
    scene, (mid,) = scene_of((v, t))
    target = Target(Surface(mid, v, t), uv)
    with pytest.raises(ValueError, match="one resolution"):
        bake(scene, [target, target], resolution=[8, 16], atlas=True)
