"""What a probe sees: six hemispheres (normals +X, -X, +Y, -Y, +Z, -Z), one raw visibility
mask each (`Scene.visibility`, hemispherical rasterization), turned into the six cube sides
and the SH9 projection of the incident radiance.

Side j integrates over the hemisphere of its own axis only (max(0, w.a_j) vanishes on the
other side) with the lightmap baker's cell weights (`lightmap.cells.lobe_weights`: exact
on an open hemisphere). The SH projection integrates over both hemispheres of an axis, which
cover the sphere once; a cell near the disk's rim spans up to 20 degrees, so each direction is
taken from the hemisphere whose pole it is nearest (the cube-map face of its largest
coordinate, at most 54.7 degrees from the pole). Each cell carries the integral of Y_k over
the part of its solid angle inside that face (fine quadrature, once) and the radiance at its
sample direction. The six frames are fixed, so all of this is per cell, not per probe.
"""

import collections
import functools

import numpy as np

from .. import sh_basis
from ..lightmap import cells
from .cube import AXES

_NT, _NPHI = 512, 1024


@functools.cache
def frame(j):
    """World tangent, bitangent, normal (3, 3 rows) of hemisphere j, as the engine builds them."""
    n = AXES[j][None]
    t, b = cells.engine_frame(n)
    f = np.stack([t[0], b[0], n[0]])
    assert np.allclose(np.abs(f).sum(axis=1), 1.0)  # axis-aligned, as `_local_moments` needs
    return f


@functools.cache
def cell_directions(j):
    """World direction (1024, 3) where each cell of hemisphere j samples the radiance."""
    return cells.radiance_directions() @ frame(j)


@functools.cache
def _local_moments():
    """(1024, 10): integral over each cell's solid angle of 1, x, y, z, xx, yy, zz, xy, yz, zx
    (receiver frame) inside the central face z >= |x|, |y|, by fine quadrature in (theta, phi)
    as `cells.moments` does. The engine's frames of the six axes have axis-aligned tangents,
    so this face is the cube-map face of the hemisphere's axis in every frame."""
    theta = (np.arange(_NT) + 0.5) * (np.pi / 2 / _NT)
    phi = (np.arange(_NPHI) + 0.5) * (2 * np.pi / _NPHI)
    st = np.sin(theta)[:, None]
    s = np.stack(np.broadcast_arrays(st * np.cos(phi), st * np.sin(phi), np.cos(theta)[:, None]), -1).reshape(-1, 3)
    weight = np.broadcast_to(st * (np.pi / 2 / _NT) * (2 * np.pi / _NPHI), (_NT, _NPHI)).reshape(-1)
    weight = weight * (s[:, 2] >= np.maximum(np.abs(s[:, 0]), np.abs(s[:, 1])))
    col = np.clip(((s[:, 0] + 1) * (cells.SIDE / 2)).astype(np.int64), 0, cells.SIDE - 1)
    row = np.clip(((s[:, 1] + 1) * (cells.SIDE / 2)).astype(np.int64), 0, cells.SIDE - 1)
    index = row * cells.SIDE + col
    m = np.stack([np.bincount(index, f * weight, cells.CELLS) for f in _monomials(s).T], axis=1)
    return m * (4 * np.pi / 6 / m[:, 0].sum())  # the face's ragged edge on the grid: 3e-5 of its solid angle


def _monomials(s):
    x, y, z = s[:, 0], s[:, 1], s[:, 2]
    return np.stack([np.ones_like(x), x, y, z, x * x, y * y, z * z, x * y, y * z, z * x], axis=1)


@functools.cache
def cell_sh(j):
    """(1024, 9): integral of Y_k (world) over each cell's solid angle inside face j. Bands
    0-2 are quadratic polynomials of the direction: fitted exactly on the sphere in the
    frame's local coordinates, then integrated with the cells' local moments."""
    rng = np.random.default_rng(0)
    local = rng.normal(size=(200, 3))
    local /= np.linalg.norm(local, axis=1, keepdims=True)
    y = sh_basis((local @ frame(j)).astype(np.float64), 3).astype(np.float64)
    coefficients, *_ = np.linalg.lstsq(_monomials(local), y, rcond=None)  # (10, 9), exact on the sphere
    return _local_moments() @ coefficients


@functools.cache
def _side_weights():
    """(1024,): the clamped cosine around the normal, per cell; they add up to pi."""
    return cells.lobe_weights(np.array([0.0, 0.0, 1.0]))


Views = collections.namedtuple("Views", "masks back gathered")


def views(scene, points, offset=None, bands=None, sides=True):
    """What each probe sees, one walk per hemisphere: `masks` (6, P, 16), the raw masks of
    its six hemispheres (+Z and -Z only, (2, P, 16), without `sides`); `back` (2, P), the
    fraction of the +Z and -Z hemispheres' cells whose nearest blocker shows its back
    (`validity`); `gathered` (P, bands^2, 3), with `bands`, the SH projection over the whole
    sphere of the radiance the scene's surfaces show (`Scene.gather`), else None. +Z and -Z
    come from the gather's ordered walks (`Scene.gather_views`), the four sides from plain
    mask walks (`Scene.visibility`)."""
    sh, z_masks, back, _ = scene.gather_views(points, None, bands=bands or 1, offset=offset)
    if not sides:
        return Views(z_masks, back, None)
    masks = np.empty((6, len(points), 16), np.uint64)
    for j in range(4):
        masks[j] = scene.visibility(points, np.broadcast_to(AXES[j], points.shape), offset=offset)
    masks[4:] = z_masks  # AXES[4], AXES[5] = +Z, -Z: the gather's hemispheres
    return Views(masks, back, sh.astype(np.float64) if bands else None)


def environment(open_cells, lighting):
    """Cube (P, 6, 3) and SH9 (P, 9, 3) of the environment seen through open cells (6, P, 1024)."""
    p = open_cells.shape[1]
    cube = np.zeros((p, 6, 3))
    sh9 = np.zeros((p, 9, 3))
    if lighting is None:
        return cube, sh9
    bands = int(round(np.sqrt(len(lighting))))
    for j in range(6):
        radiance = sh_basis(cell_directions(j).astype(np.float32), bands).astype(np.float64) @ lighting  # (1024, 3)
        o = open_cells[j].astype(np.float32)
        cube[:, j] = o @ (_side_weights()[:, None] * radiance).astype(np.float32) / np.pi
        per_cell = (cell_sh(j)[:, :, None] * radiance[:, None, :]).reshape(cells.CELLS, 27).astype(np.float32)
        sh9 += (o @ per_cell).reshape(p, 9, 3)  # the six faces cover the sphere once
    return cube, sh9


def sun(scene, points, sun_lamp, offset=None):
    """Cube (P, 6, 3) and SH9 (P, 9, 3) of a sun lamp (`lightmap.Sun`, direction checked and
    unit): one exact shadow ray per probe towards the sun's centre (`light.sun_visibility`)."""
    from ..lightmap import light
    d = np.broadcast_to(np.asarray(sun_lamp.direction, np.float64), points.shape).copy()
    lit = light.sun_visibility(scene, points, d, d, offset=offset).astype(np.float64)
    rgb = np.broadcast_to(np.asarray(sun_lamp.strength, np.float64), (3,))
    cosine = np.maximum(AXES @ d[0], 0.0)
    cube = lit[:, None, None] * cosine[None, :, None] * rgb / np.pi
    y = sh_basis(d[:1].astype(np.float32), 3).astype(np.float64)[0]
    sh9 = lit[:, None, None] * y[None, :, None] * rgb  # a delta of irradiance `strength`
    return cube, sh9


#: The axis of the two hemispheres that take a lamp's light. Together they see every direction
#: once, and no lamp lies in their dividing plane by accident (one level with a probe would lie
#: in the plane of +Z and -Z, counted by neither).
LAMP_AXIS = np.array([0.267261, 0.534522, 0.801784])
_LAMP_CHUNK = 256
_FIBONACCI = (1, 2, 3, 5, 8, 13, 21, 34, 55, 89, 144, 233, 377)


def lamp_shifts(lamp_points):
    """Shifts (K, 2) of the lamp's 2 x 2 grid for about `lamp_points` points (4 K): a
    Fibonacci lattice, K = F_m, shift k = ((k + 1/2) / F_m, (k F_(m-1) mod F_m + 1/2) / F_m).
    A probe is one sample: a plain g x g grid would move a shadow edge parallel to its rows
    in steps of 1 / g of the lamp (6 % of a 1 m area lamp's light 1 m from a box's edge with
    8 x 8 points); the lattice's points project onto 2 K distinct rows and columns."""
    m = max(i for i, f in enumerate(_FIBONACCI) if f <= max(lamp_points // 4, 1) or i == 0)
    k_count, step = _FIBONACCI[m], _FIBONACCI[max(m - 1, 0)]
    k = np.arange(k_count)
    return np.stack([(k + 0.5) / k_count, ((k * step) % k_count + 0.5) / k_count], axis=1)


def lamp(scene, points, lamp_model, lamp_points=220, offset=None):
    """Cube (P, 6, 3) and SH9 (P, 9, 3) of a point, spot or area lamp (`lightmap.lamps`,
    checked): the lightmap baker's `lamp_light` (exact segment shadows) on the two hemispheres
    of LAMP_AXIS, with the six axes as lobes; a lamp with a size is seen through about
    `lamp_points` points (`lamp_shifts`), one without through its centre."""
    from ..lightmap import lamps as lamp_models

    sized = isinstance(lamp_model, lamp_models.Area) or lamp_model.radius > 0
    shifts = lamp_shifts(lamp_points) if sized else np.full((1, 2), 0.5)
    k = len(shifts)
    p = len(points)
    cube, sh9 = np.zeros((p, 6, 3)), np.zeros((p, 9, 3))
    for s in range(0, p, _LAMP_CHUNK):
        pts = np.repeat(points[s:s + _LAMP_CHUNK], k, axis=0)  # each probe once per shift
        index = np.tile(np.arange(k), len(pts) // k)
        lobes = np.broadcast_to(AXES, (len(pts), 6, 3))
        for sign in (1.0, -1.0):
            ng = np.broadcast_to(sign * LAMP_AXIS, pts.shape)
            m, h = lamp_models.lamp_light(scene, lamp_model, pts, ng, lobes, index, shifts, 4, offset,
                                          want_sh=True, sh_bands=3)
            cube[s:s + _LAMP_CHUNK] += m.reshape(-1, k, 6, 3).mean(axis=1)
            sh9[s:s + _LAMP_CHUNK] += np.pi * h.reshape(-1, k, 9, 3).mean(axis=1)  # lamp_light's SH is / pi
    return cube, sh9
