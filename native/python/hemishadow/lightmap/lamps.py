"""Point, spot and area lamps at receivers (DESIGN.md's power conventions, as Cycles renders
them): a point lamp of power P radiates P / (4 pi) W/sr, a spot the same masked by its cone
and blend, an area lamp of power P and area A is a one-sided Lambertian emitter of radiance
P / (pi A) facing its local -Z. Colour multiplies power (`power` may be RGB).

A mask has no depth, so lamps at a finite distance use the engine's exact segment test
(`Scene.occluded`). Soft shadows: each receiver sample sees `points` stratified points on the
lamp (a g x g grid on the lamp's disk or rectangle, shifted by the sample's offset inside its
texel, so a texel's samples see different points; deterministic, no noise between bakes).
Each point carries its share of the lamp: I / n for points and spots (the lamp's sphere or
disk only softens shadows, as in Cycles), L A / n x cos at the lamp for areas.
"""

from dataclasses import dataclass

import numpy as np

from .. import sh_basis
from . import basis, cells

SHAPES = ("SQUARE", "RECTANGLE", "DISK", "ELLIPSE")


@dataclass
class Point:
    """A point lamp at `position` (world) of `power` W (scalar or RGB, power x colour) with
    Blender's `radius` (m; softens shadows). indirect_only: lights bounce, not the maps."""
    position: tuple
    power: object = 1000.0
    radius: float = 0.0
    indirect_only: bool = False


@dataclass
class Spot:
    """A spot lamp: a point lamp masked by a cone around `direction` (where it points, world;
    Blender's local -Z) of full angle `spot_size` (radians) with `spot_blend` (0..1)."""
    position: tuple
    direction: tuple
    power: object = 1000.0
    radius: float = 0.0
    spot_size: float = np.pi / 4
    spot_blend: float = 0.15
    indirect_only: bool = False


@dataclass
class Area:
    """An area lamp centred at `position`, emitting along `direction` (its local -Z, world),
    `axis_u` its local +X (world); Blender's shape and size (`size_y` for RECTANGLE and
    ELLIPSE, else `size`)."""
    position: tuple
    direction: tuple
    axis_u: tuple
    power: object = 1000.0
    shape: str = "SQUARE"
    size: float = 1.0
    size_y: float = 1.0
    indirect_only: bool = False


def check(lamp, i):
    """The lamp with float arrays, or ValueError naming it."""
    label = f"lamp {i} ({type(lamp).__name__})"
    pos = _vector(lamp.position, f"{label}: position")
    power = np.broadcast_to(np.asarray(lamp.power, dtype=np.float64), (3,)).copy()
    if np.asarray(lamp.power).size not in (1, 3) or not np.isfinite(power).all():
        raise ValueError(f"{label}: power must be a finite number or RGB triple")
    if isinstance(lamp, (Point, Spot)):
        if not (np.isfinite(lamp.radius) and lamp.radius >= 0):
            raise ValueError(f"{label}: radius must be >= 0, got {lamp.radius!r}")
    if isinstance(lamp, Point):
        return Point(pos, power, float(lamp.radius), bool(lamp.indirect_only))
    if isinstance(lamp, Spot):
        if not (0 < lamp.spot_size <= np.pi and 0 <= lamp.spot_blend <= 1):
            raise ValueError(f"{label}: spot_size must be in (0, pi] and spot_blend in [0, 1]")
        return Spot(pos, _unit(lamp.direction, f"{label}: direction"), power, float(lamp.radius),
                    float(lamp.spot_size), float(lamp.spot_blend), bool(lamp.indirect_only))
    if isinstance(lamp, Area):
        if lamp.shape not in SHAPES:
            raise ValueError(f"{label}: shape must be one of {SHAPES}, got {lamp.shape!r}")
        d = _unit(lamp.direction, f"{label}: direction")
        u = _vector(lamp.axis_u, f"{label}: axis_u")
        u = u - d * (u @ d)
        if not np.linalg.norm(u) > 1e-9:
            raise ValueError(f"{label}: axis_u must not be parallel to direction")
        sy = lamp.size_y if lamp.shape in ("RECTANGLE", "ELLIPSE") else lamp.size
        if not (lamp.size > 0 and sy > 0):
            raise ValueError(f"{label}: size must be > 0")
        return Area(pos, d, u / np.linalg.norm(u), power, lamp.shape, float(lamp.size), float(sy),
                    bool(lamp.indirect_only))
    raise ValueError(f"{label}: not a lamp (Point, Spot or Area)")


def _vector(v, what):
    a = np.asarray(v, dtype=np.float64)
    if a.shape != (3,) or not np.isfinite(a).all():
        raise ValueError(f"{what} must be 3 finite numbers")
    return a


def _unit(v, what):
    a = _vector(v, what)
    if not np.linalg.norm(a) > 0:
        raise ValueError(f"{what} is zero")
    return a / np.linalg.norm(a)


def grid(points):
    """The g x g stratified pattern (n, 2) in [0, 1)^2 before the per-sample shift, n = g^2."""
    g = max(int(round(np.sqrt(points))), 1)
    x, y = np.meshgrid(np.arange(g) / g, np.arange(g) / g)
    return np.stack([x.ravel(), y.ravel()], axis=1), g


def _patterns(offsets, points, sized):
    """(K, n, 2) points in [0, 1)^2, one set per pattern: the grid shifted by the pattern's
    offset (one point at the centre for lamps without size)."""
    if not sized or points <= 1:
        return np.full((len(offsets), 1, 2), 0.5)
    pattern, g = grid(points)
    return pattern[None] + np.asarray(offsets)[:, None] / g


def _disk(uv):
    """Concentric map of [0, 1)^2 onto the unit disk (Shirley, Chiu 1997): (..., 2)."""
    u, v = uv[..., 0] * 2 - 1, uv[..., 1] * 2 - 1
    big = np.abs(u) > np.abs(v)
    r = np.where(big, u, v)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(big, np.pi / 4 * v / np.where(u == 0, 1, u), np.pi / 2 - np.pi / 4 * u / np.where(v == 0, 1, v))
    return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)


def samples(lamp, receivers, index, offsets, points):
    """Lamp points (P, n, 3) seen by receiver samples (P, 3) and the intensity factor (P, n)
    of each: irradiance on a surface facing it at distance d is factor / d^2 (W/m^2)."""
    pts, _, _, factor = _sampled(lamp, receivers, index, offsets, points)
    return pts, factor


def _sampled(lamp, receivers, index, offsets, points):
    """`samples`' lamp points and factors, with the unit directions (P, n, 3) and squared
    distances (P, n) to them, float32: the only arrays of size P x n, each made once. For
    20,000 samples of a 64-point lamp over a table, made in float64, twice, and gathered for
    the rays, they took 240 ms, of which the rays 30-40 ms; 113 ms now."""
    receivers = np.asarray(receivers, np.float32)
    index = np.asarray(index) % len(offsets)
    if isinstance(lamp, Area):
        table, count = _area_points(lamp, offsets, points)
        pts = table[index]  # a handful of patterns: look each sample's up
    else:
        pts, count = _point_points(lamp, receivers, index, offsets, points)
    to = pts - receivers[:, None]
    # einsum: numpy sums a last axis of 3 far slower than it multiplies
    d2 = np.maximum(np.einsum("pnd,pnd->pn", to, to), np.float32(1e-30))
    w = to * (1 / np.sqrt(d2))[..., None]
    if isinstance(lamp, Area):
        area = lamp.size * lamp.size_y * (np.pi / 4 if lamp.shape in ("DISK", "ELLIPSE") else 1.0)
        radiance = 1.0 / (np.pi * area)  # per watt
        # einsum, not `@`: numpy < 2 (Blender 4.2 to 5.0) hands matrix-vector products to
        # OpenBLAS's threads, which then spin beside the engine (see hemishadow.products)
        cos_lamp = np.maximum(-np.einsum("pnd,d->pn", w, np.asarray(lamp.direction, np.float32)), 0)
        return pts, w, d2, cos_lamp * np.float32(radiance * area / count)
    factor = np.full(d2.shape, 1.0 / (4 * np.pi * count), np.float32)
    if isinstance(lamp, Spot):
        factor *= spot_mask(lamp, _away(lamp, receivers)).astype(np.float32)[:, None]
    return pts, w, d2, factor


def _area_points(lamp, offsets, points):
    """World points (K, n, 3) float32 of each pattern on an area lamp, and n."""
    uv = _patterns(offsets, points, True)
    if lamp.shape in ("DISK", "ELLIPSE"):
        uv = _disk(uv) * 0.5 + 0.5
    local = (uv - 0.5) * [lamp.size, lamp.size_y]
    axes = np.array([lamp.axis_u, _axis_v(lamp)], np.float64)  # (2, 3): the lamp's +X and +Y
    table = np.einsum("knj,jd->knd", local, axes) + np.asarray(lamp.position, np.float64)
    return table.astype(np.float32), uv.shape[1]


def _point_points(lamp, receivers, index, offsets, points):
    """Points (P, n, 3) float32 on the disk of a point or spot lamp facing each receiver, and n."""
    disk = _disk(_patterns(offsets, points, lamp.radius > 0)) * lamp.radius  # (K, n, 2)
    position = np.asarray(lamp.position, np.float32)
    if lamp.radius <= 0:
        return np.broadcast_to(position, (len(receivers), 1, 3)), 1
    t, b = _facing_frame(lamp, receivers)
    d = disk.astype(np.float32)[index]
    return position + d[..., :1] * t[:, None] + d[..., 1:] * b[:, None], disk.shape[1]


def _axis_v(lamp):
    """An area lamp's local +Y in world space (local -Z x local +X = +Y)."""
    return np.cross(lamp.direction, lamp.axis_u)


def _away(lamp, receivers):
    """Unit directions (P, 3) float32 from a point or spot lamp to each receiver (P, 3)."""
    axis = np.asarray(receivers, np.float32) - np.asarray(lamp.position, np.float32)
    return axis / np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-30)


def _facing_frame(lamp, receivers):
    """Tangent and bitangent (P, 3) float32 of the disk of a point or spot lamp facing each
    receiver: the engine's frame about the direction from the lamp."""
    return tuple(f.astype(np.float32) for f in cells.engine_frame(_away(lamp, receivers)))


def spot_mask(lamp, axis):
    """Cycles' spot attenuation for unit directions from the lamp (P, 3): smoothstep of
    (cos - cos(size / 2)) / ((1 - cos(size / 2)) x blend), a hard cone when blend is 0."""
    cos_half = np.cos(lamp.spot_size / 2)
    c = np.einsum("pd,d->p", axis, np.asarray(lamp.direction, np.float64))  # not `@`: see `samples`
    if lamp.spot_blend <= 0:
        return (c > cos_half).astype(np.float64)
    x = np.clip((c - cos_half) / ((1 - cos_half) * lamp.spot_blend), 0.0, 1.0)
    return x * x * (3 - 2 * x)


def lamp_light(scene, lamp, points, ng, lobes, index, offsets, lamp_points, offset, want_sh=False, sh_bands=2):
    """Irradiance / pi (P, L, 3) of one lamp on lobes (P, L, 3) of receiver samples at
    `points` with geometric normals `ng`, shadowed by the scene (exact segments), and its
    SH (P, sh_bands^2, 3) / pi (L1 by default; the probes ask for bands 0-2) or None."""
    pts, w, d2, factor = _sampled(lamp, points, index, offsets, lamp_points)
    p, n = factor.shape
    weight = factor / d2 * (np.einsum("pnd,pd->pn", w, np.asarray(ng, np.float32)) > 0)
    todo = weight > 0
    rows = np.flatnonzero(todo.any(axis=1))
    if len(rows):
        start = (np.asarray(points, np.float64) + np.asarray(ng, np.float64) * lift(scene, offset)).astype(np.float32)
        if n > 1:  # where nothing lies between a sample and the whole lamp, none of its segments is blocked
            polygon = _polygon(lamp, np.asarray(points, np.float32)[rows])
            rows = rows[~scene.beams_clear(start[rows], np.asarray(ng)[rows], polygon, offset=offset)]
        _shadow(scene, weight, todo, rows, start, pts, offset)
    cosine = np.maximum(np.einsum("pld,pnd->pln", np.asarray(lobes, np.float32), w), 0)
    maps = np.einsum("pln,pn->pl", cosine, weight)[..., None] * (lamp.power / np.pi)
    sh = None
    if want_sh:
        if sh_bands == 2:
            y = np.stack([np.full((p, n), basis.Y00, np.float32), -basis.C1 * w[..., 1], basis.C1 * w[..., 2],
                          -basis.C1 * w[..., 0]], -1)
        else:
            y = sh_basis(w.reshape(-1, 3), sh_bands).reshape(p, n, -1)
        sh = np.einsum("pnk,pn->pk", y, weight)[..., None] * (lamp.power / np.pi)
    return maps.astype(np.float32), (None if sh is None else sh.astype(np.float32))


def _shadow(scene, weight, todo, rows, start, pts, offset):
    """Zeroes in `weight` (P, n) the segments of `rows` that `todo` (P, n) asks for and a
    triangle blocks, from `start` (P, 3) to `pts` (P, n, 3)."""
    if not len(rows):
        return
    n = pts.shape[1]
    if todo[rows].mean() > 0.5:  # most segments count: test them all, without gathering the ones that do
        blocked = scene.occluded(np.repeat(start[rows], n, axis=0), pts[rows].reshape(-1, 3), offset=offset)
        weight[rows] *= ~blocked.reshape(len(rows), n)
    else:
        r, c = np.nonzero(todo[rows])
        weight[rows[r], c] *= ~scene.occluded(start[rows[r]], pts[rows[r], c], offset=offset)


def _polygon(lamp, receivers):
    """A convex polygon holding every point a sample at each of `receivers` (P, 3) sees on the
    lamp: an area lamp's rectangle (a disk's or ellipse's bounding one), (4, 3); the square
    around the disk of a point or spot lamp facing each receiver, (P, 4, 3)."""
    square = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float32) / 2
    if isinstance(lamp, Area):
        axes = np.array([lamp.axis_u * lamp.size, _axis_v(lamp) * lamp.size_y], np.float32)
        return np.asarray(lamp.position, np.float32) + np.einsum("kj,jd->kd", square, axes)  # einsum: see `_sampled`
    position = np.asarray(lamp.position, np.float32)
    t, b = _facing_frame(lamp, receivers)
    corners = 2 * lamp.radius * square  # the disk of radius r inside the square of side 2 r
    return position + corners[None, :, :1] * t[:, None] + corners[None, :, 1:] * b[:, None]


def lift(scene, offset):
    """The receivers' lift in world units (as the engine's masks lift them)."""
    return scene.size * (1e-4 if offset is None else offset)
