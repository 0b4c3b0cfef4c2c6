"""The probe baker's engine part: points in, ambient cubes and SH9 out (issue 12).

`bake(scene, points, lighting=..., suns=..., surfaces=..., bounces=N)` returns a dict:
`positions` (P, 3) (after moving invalid probes), `cube` (P, 6, 3) (irradiance / pi per
side, +X, -X, +Y, -Y, +Z, -Z), `sh9` (P, 9, 3) (SH projection of the incident radiance, the
convention of `hemishadow.project_environment`, not divided by pi), `valid` (P,), `moved`
(P,), `lightmapped` (mesh ids whose bounce light came from their baked lightmaps); `bake_grid`
adds `grid_matrix` (4, 4) and `grid_resolution` (3,). See docs/probes.md.
"""

import numpy as np

from ..lightmap.bake import (Steps, bounce_receivers, checked_lighting, checked_suns, emitters, positive_int,
                              vertex_bounce)
from ..lightmap import bounce, cells, lamps as lamp_models, texels
from . import baked, capture, grid, validity
from .cube import sh_to_cube

_CHUNK = 4096
GATHER_BANDS = 5  # bounce light as SH25: the cube's lobes from bands 0-4 (A_3 = 0, A_4 = -pi/24)


def _points(points):
    array = np.asarray(points, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"probe points must have shape (P, 3), got {array.shape}")
    if not len(array):
        raise ValueError("no probe points to bake")
    if not np.isfinite(array).all():
        raise ValueError(f"probe point {int(np.argwhere(~np.isfinite(array))[0, 0])} has a NaN or infinite coordinate")
    return array


def _cell(cell):
    if cell is None:
        return None
    c = np.asarray(cell, dtype=np.float64)
    c = np.diag(np.broadcast_to(c, (3,))) if c.ndim <= 1 else c
    if c.shape != (3, 3) or not np.isfinite(c).all():
        raise ValueError(f"cell must be a number, 3 numbers or a (3, 3) matrix of cell axes, got shape {c.shape}")
    return c


def bake(scene, points, *, lighting=None, suns=(), lamps=(), surfaces=(), bounces=2, cell=None, offset=None,
         lamp_points=220, lightmaps=None, progress=None):
    """Bakes probes at `points` (P, 3) in `scene` (a `hemishadow.Scene` of every blocker).

    lighting: environment radiance SH (K, 3), K = 1, 4, 9, 16, 25 (None: none).
    suns: `hemishadow.lightmap.Sun`s (strength = irradiance in W/m^2 facing the sun).
    lamps: `Point`, `Spot` and `Area` lamps (`hemishadow.lightmap`; DESIGN.md's power
        conventions), lit and shadowed as the lightmap baker does (`capture.lamp`); suns and
        lamps with `indirect_only` light the bounce surfaces only. lamp_points: about this
        many points on a lamp with a size (soft shadows; a Fibonacci lattice,
        `capture.lamp_shifts`).
    surfaces: `hemishadow.lightmap.Surface`s that reflect (albedo) or emit light; bounce
        receivers at their vertices, as in the lightmap baker. bounces: 0 = direct light only.
    lightmaps: {mesh_id: (V, 3)} the irradiance / pi at a surface's vertices from its baked
        lightmap (its `flat` map, `baked.vertex_light`): that surface then shows
        emission + albedo x it as its bounce radiance instead of the computed passes (which
        are skipped when every surface has one). Bake the lightmaps with bounces - 1 bounces
        for the same light as the computed path.
    cell: the grid's cell axes ((3, 3) columns, a number or 3 numbers), so that invalid probes
        may move up to half a cell; None: invalid probes stay, marked invalid.
    progress: callable(fraction); returning False raises `hemishadow.Cancelled`.
    """
    pts = _points(points)
    if scene.triangle_count == 0:
        raise ValueError("the scene has no geometry: add the meshes that block light before baking probes")
    bounces = positive_int(bounces, "bounces", 0)
    lighting, suns, cell = checked_lighting(lighting), checked_suns(suns), _cell(cell)
    lamps = [lamp_models.check(lamp, i) for i, lamp in enumerate(lamps)]
    lamp_points = positive_int(lamp_points, "lamp_points")
    surfaces = list(surfaces)
    emits = emitters([], surfaces)
    receivers = bounce_receivers([], surfaces) if surfaces and (bounces or emits) else []
    steps = Steps(progress, 3 * len(pts) + sum(len(r[1]) for r in receivers) * (1 + bounces), "probe bake")

    lightmapped, bands = [], None
    if receivers:  # what the surfaces show does not depend on the probes: it comes first
        fixed = baked.radiance(receivers, lightmaps) if bounces else {}
        lightmapped = sorted(fixed)
        if _show_surfaces(scene, receivers, lighting, suns, lamps, bounces, offset, steps, fixed):
            bands = GATHER_BANDS
    seen = capture.views(scene, pts, offset, bands)
    masks, gathered = seen.masks, seen.gathered
    valid = validity.check(seen.back)
    moved = np.zeros(len(pts), bool)
    if cell is not None and not valid.all():
        pts, moved = validity.relocate(scene, pts, valid, cell, offset)
        if moved.any():
            again = capture.views(scene, pts[moved], offset, bands)
            masks[:, moved] = again.masks
            if gathered is not None:
                gathered[moved] = again.gathered
            valid[moved] = True
    steps.step(len(pts))

    cube, sh9 = np.zeros((len(pts), 6, 3)), np.zeros((len(pts), 9, 3))
    for s in range(0, len(pts), _CHUNK):  # unpacked masks: 6 KiB a probe
        open_cells = np.stack([~cells.unpack(m[s:s + _CHUNK]) for m in masks])
        cube[s:s + _CHUNK], sh9[s:s + _CHUNK] = capture.environment(
            open_cells, None if lighting is None else lighting.astype(np.float64))
    for sun in [s for s in suns if not s.indirect_only]:
        c, s = capture.sun(scene, pts, sun, offset)
        cube += c
        sh9 += s
    for lamp in [lamp for lamp in lamps if not lamp.indirect_only]:
        c, s = capture.lamp(scene, pts, lamp, lamp_points, offset)
        cube += c
        sh9 += s
        steps.step(0)  # lets a cancel through between lamps
    steps.step(len(pts))
    if gathered is not None:
        cube += np.maximum(sh_to_cube(gathered), 0.0)
        sh9 += gathered[:, :9]
    steps.step(len(pts))
    cube, sh9 = _fill_invalid(pts, cube, sh9, valid)
    return {"positions": pts.astype(np.float32), "cube": cube.astype(np.float32), "sh9": sh9.astype(np.float32),
            "valid": valid, "moved": moved, "lightmapped": lightmapped}


def bake_grid(scene, matrix, resolution, **kwargs):
    """`bake` on the probes of a grid (`grid.grid_points`), cell = the matrix's axes; the
    result also holds `grid_matrix` and `grid_resolution`."""
    m, res = grid.matrix4(matrix), grid.resolution3(resolution)
    kwargs.setdefault("cell", m[:3, :3])
    out = bake(scene, grid.grid_points(m, res), **kwargs)
    out["grid_matrix"], out["grid_resolution"] = m.astype(np.float64), res
    return out


def _show_surfaces(scene, receivers, lighting, suns, lamps, bounces, offset, steps, fixed):
    """Shows each surface's radiance to the scene for the probes' gather: after `bounces`
    passes (the lightmap baker's vertex receivers, `vertex_bounce`), or for surfaces in
    `fixed` ({mesh_id: radiance (V, 3)}, from their lightmaps) that instead. False when
    every surface stays black."""
    if len(fixed) == len(receivers):
        radiance = [fixed[r[0]] for r in receivers]
        for (mesh_id, *_), rgb in zip(receivers, radiance):
            scene.set_radiance(mesh_id, rgb)
        steps.step(sum(len(r[1]) for r in receivers) * (1 + bounces))  # the passes' share
    else:
        radiance = vertex_bounce(scene, receivers, lighting, suns, lamps, bounces, offset, steps)
        for i, (mesh_id, *_) in enumerate(receivers):
            if mesh_id in fixed:
                radiance[i] = fixed[mesh_id]
                scene.set_radiance(mesh_id, radiance[i])
    return any(r.any() for r in radiance)


def _fill_invalid(points, cube, sh9, valid):
    """Invalid probes (left out of interpolation) take their nearest valid probe's values,
    so that a file read without `valid` never shows a black cube; all invalid: unchanged."""
    bad = np.flatnonzero(~valid)
    good = np.flatnonzero(valid)
    if len(bad) and len(good):
        d = ((points[bad][:, None] - points[good][None]) ** 2).sum(-1)
        nearest = good[np.argmin(d, axis=1)]
        cube[bad], sh9[bad] = cube[nearest], sh9[nearest]
    return cube, sh9
