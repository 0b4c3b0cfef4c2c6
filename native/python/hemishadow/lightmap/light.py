"""Direct light at receivers: the environment (SH lighting) and sun lamps.

Both are integrated over the receiver's geometric hemisphere from the engine's raw
visibility masks (`Scene.visibility`, queried with the geometric normal): a lobe
max(0, v.s) for any unit v (the shading normal, an HL2 basis vector) gets the cell weights of
`cells.lobe_weights`, so a basis vector tilted 54.7 degrees from the normal sees only the
light above the surface, as Cycles does with a Normal Map node (0.7887 on an open plane).
The transfer vectors of `Scene.transfer` cannot clip a tilted lobe at the surface.

Environment: radiance per cell from the lighting rotated into each receiver's frame (fitted
exactly, band by band, on directions over the sphere). Suns: one exact shadow ray per sample,
the engine's segment test to a point beyond the scene (bounce receivers: a mask query through
the scene's proxies, whose normal is tilted so that the sun passes through a central cell).
"""

import functools
from dataclasses import dataclass

import numpy as np

from .. import _native, sh_basis
from . import basis, cells, lamps


@dataclass
class Sun:
    """A sun lamp: `direction` towards the light (world), `strength` the irradiance in W/m^2
    on a surface facing it (scalar or RGB, Blender's Strength x colour), `angle` its angular
    diameter in radians (its disk is sampled across a texel's samples). indirect_only: it
    lights bounce surfaces but not the maps (a lamp the game engine renders in real time)."""
    direction: tuple
    strength: object = 1.0
    angle: float = 0.0
    indirect_only: bool = False


def local_lighting(lighting, t, b, n):
    """Lighting SH (K, 3) expressed in each receiver's frame (rows t, b, n): (P, K, 3). The
    engine's SH rotation (`sh_rotation.rs`, as it turns transfer into world space): a band
    is fitted from its values at 2 l + 1 directions, all directions evaluated at once."""
    frames = np.ascontiguousarray(np.stack([t, b, n], axis=1), np.float32)     # (P, 3, 3), rows t, b, n
    return _native.sh_to_frames(np.ascontiguousarray(lighting, np.float32), frames)


@functools.cache
def _cell_values(bands):
    """SH basis at each cell's lighting direction, and a column of ones (AO): (1024, K + 1)."""
    y_cells = sh_basis(cells.radiance_directions(), bands) if bands else np.zeros((cells.CELLS, 0), np.float32)
    return y_cells, np.ascontiguousarray(np.concatenate([y_cells, np.ones((cells.CELLS, 1), np.float32)], axis=1),
                                         np.float32)


def bands_used(lighting):
    """The SH bands up to the last one with a coefficient other than 0 (0: no light). A plain
    World colour projects to band 0 alone: its 24 zero coefficients cost a rotation into every
    receiver's frame and 24 of 26 lobe integrals per cell (the room of bench/lightmap_cycles.py
    at 128 x 128: 0.19 s of 0.66 s) for nothing."""
    lighting = np.asarray(lighting)
    bands = int(round(np.sqrt(len(lighting))))
    while bands and not np.any(lighting[(bands - 1) ** 2:bands * bands]):
        bands -= 1
    return bands


def environment(masks, t, b, n, lobes, lighting, want_sh=False):
    """Irradiance / pi (P, L, 3) for unit lobe directions (P, L, 3) (world) of receivers with
    packed masks (P, 16) uint64 taken in the engine frame (t, b, n) of their geometric
    normals; the open fraction of the first lobe (P,); and with want_sh the L1 SH (P, 4, 3) of
    the incident radiance / pi (world), else None. The lobe integrals over the open cells run
    in the engine (`Scene.lobe_integrals`, `cells.lobe_weights` in numpy is the same)."""
    local = np.einsum("plj,pfj->plf", lobes, np.stack([t, b, n], axis=1))    # the lobes in the frame
    bands = 0 if lighting is None else bands_used(lighting)
    lighting = None if not bands else np.asarray(lighting)[:bands * bands]
    y_cells, values = _cell_values(bands)
    moments = np.ascontiguousarray(cells.moments()[:, :3], np.float32)
    out = _native.Scene.lobe_integrals(np.ascontiguousarray(masks), np.ascontiguousarray(local, np.float32), moments,
                                       values)
    ao = out[:, 0, -1] / cells.open_clamped_cosine(local[:, 0, 2]).astype(np.float32)
    if lighting is None:
        return np.zeros(lobes.shape[:2] + (3,), np.float32), ao.astype(np.float32), (np.zeros((len(t), 4, 3), np.float32) if want_sh else None)
    if bands == 1:  # a uniform sky: the same in every frame
        lit = np.broadcast_to(np.asarray(lighting, np.float32)[None], (len(t), 1, 3))
    else:
        lit = local_lighting(lighting, t, b, n)                 # (P, K, 3)
    maps = np.matmul(out[..., :-1], lit) / np.float32(np.pi)
    sh = None
    if want_sh:
        open_cells = (~cells.unpack(masks)).astype(np.float32)
        moments4 = cells.moments().astype(np.float32)
        per_cell = np.stack([basis.Y00 * moments4[:, 3], -basis.C1 * moments4[:, 1], basis.C1 * moments4[:, 2],
                             -basis.C1 * moments4[:, 0]], axis=1)  # integral of Y_k over each cell
        radiance = np.einsum("ck,pkj->pcj", y_cells, lit)
        local_sh = np.einsum("pc,pcj,ck->pkj", open_cells, radiance, per_cell)
        sh = basis.l1_to_world(local_sh, t, b, n) / np.float32(np.pi)
    return maps.astype(np.float32), ao.astype(np.float32), sh


_TARGETS = [(x, y) for y in (-1 / 32, 1 / 32) for x in (-1 / 32, 1 / 32)]


def _branch_frame(q, sign):
    a = -1.0 / (sign + q[:, 2])  # the other branch is singular near its pole: NaN, rejected
    b = q[:, 0] * q[:, 1] * a
    t = np.stack([1.0 + sign * q[:, 0] ** 2 * a, sign * b, -sign * q[:, 0]], axis=1)
    bt = np.stack([b, sign + q[:, 1] ** 2 * a, -q[:, 1]], axis=1)
    return t, bt


def shadow_normals(directions, ng):
    """Query normals (P, 3) and cell indices (P,) such that `directions` pass through the
    centre of that mask cell; among the four central cells, the one whose normal leans most
    towards the geometric normal `ng` (the query point is lifted along it)."""
    best_q = directions.copy()
    best_cell = np.full(len(directions), -1)
    best_score = np.full(len(directions), -np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        _search(directions, ng, best_q, best_cell, best_score)
    return best_q, best_cell


def _search(directions, ng, best_q, best_cell, best_score):
    for x, y in _TARGETS:
        z = np.sqrt(1 - x * x - y * y)
        for sign in (1.0, -1.0):
            q = directions.copy()
            for _ in range(12):
                t, bt = _branch_frame(q, sign)
                q = directions - x * t - y * bt
                q /= np.linalg.norm(q, axis=1, keepdims=True)
            t, bt = engine_frame_f32(q)
            residual = np.abs((directions * t).sum(1) - x) + np.abs((directions * bt).sum(1) - y)
            ok = (np.where(np.signbit(q[:, 2]), -1.0, 1.0) == sign) & (residual < 1e-4) & np.isfinite(q).all(1)
            score = np.where(ok, (q * ng).sum(1), -np.inf)
            better = score > best_score
            best_q[better], best_score[better] = q[better], score[better]
            best_cell[better] = int(round((y + 1) * 16 - 0.5)) * 32 + int(round((x + 1) * 16 - 0.5))


def engine_frame_f32(q):
    """The engine's frame of normals as it sees them (float32)."""
    t, b = cells.engine_frame(q.astype(np.float32).astype(np.float64))
    return t, b


def sun_visibility(scene, points, ng, directions, offset=None, exact=True):
    """1.0 where the ray from each point towards `directions` (P, 3) is open, else 0.0.
    exact: the engine's segment test (`Scene.occluded`, every triangle, no proxies) to a
    point beyond the scene; else a mask query with the scene's proxies (`_mask_visibility`,
    soft bounce light only)."""
    if not exact:
        return _mask_visibility(scene, points, ng, directions, offset)
    start = points + ng * lamps.lift(scene, offset)
    far = start + directions * (2.0 * scene.size + 1.0)
    return (~scene.occluded(start, far, offset=offset)).astype(np.float32)


def _mask_visibility(scene, points, ng, directions, offset):
    """A visibility query whose normal is tilted so that the direction passes through the
    centre of one of the mask's four central cells (the four cells' mean where no normal was
    found, which does not happen for unit directions)."""
    q, cell = shadow_normals(directions, ng)
    blocked = cells.unpack(scene.visibility(points, q, offset=offset))
    found = cell >= 0
    lit = np.where(found, ~blocked[np.arange(len(q)), np.maximum(cell, 0)], False).astype(np.float32)
    if not found.all():
        centre = [15 * 32 + 15, 15 * 32 + 16, 16 * 32 + 15, 16 * 32 + 16]
        lit[~found] = (~blocked[~found][:, centre]).mean(axis=1)
    return lit


def sun_directions(sun, count, index, offsets):
    """Per sample, a direction inside the sun's disk (its centre when the angle is 0): sample
    `index` of a texel takes offset `index` of the texel's pattern, mapped onto the disk."""
    d = np.asarray(sun.direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    if sun.angle <= 0:
        return np.broadcast_to(d, (count, 3)).copy()
    u, v = offsets[index % len(offsets)].T * 2 - 1
    r = np.where(np.abs(u) > np.abs(v), u, v)  # concentric square -> disk (Shirley, Chiu 1997)
    phi = np.where(np.abs(u) > np.abs(v), np.pi / 4 * v / np.where(u == 0, 1, u), np.pi / 2 - np.pi / 4 * u / np.where(v == 0, 1, v))
    radius = np.tan(sun.angle / 2) * r
    t, b = cells.engine_frame(d[None])
    out = d + radius[:, None] * (np.cos(phi)[:, None] * t + np.sin(phi)[:, None] * b)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def sun_light(sun, lit, ng, lobes, directions, want_sh=False):
    """Irradiance / pi (P, L, 3) of a sun on lobes (P, L, 3), and its L1 SH (P, 4, 3) / pi."""
    rgb = np.broadcast_to(np.asarray(sun.strength, dtype=np.float64), (3,))
    facing = lit * ((directions * ng).sum(1) > 0)
    cosine = np.maximum((lobes * directions[:, None]).sum(-1), 0.0)
    maps = (facing[:, None, None] * cosine[..., None] * rgb / np.pi).astype(np.float32)
    sh = None
    if want_sh:
        y = np.stack([np.full(len(directions), basis.Y00), -basis.C1 * directions[:, 1], basis.C1 * directions[:, 2],
                      -basis.C1 * directions[:, 0]], axis=1)
        sh = (facing[:, None, None] * y[..., None] * rgb / np.pi).astype(np.float32)
    return maps, sh
