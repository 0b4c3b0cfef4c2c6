"""The lightmap baker's engine part: texels in, maps out (issue 11).

`bake(scene, targets, resolution=...)` returns, per target, float32 maps of the outgoing
radiance of a white Lambertian surface (irradiance / pi; what Cycles' Diffuse bake gives
with Direct + Indirect and Color off): `flat` (interpolated shading normal), `b0`, `b1`, `b2`
(HL2 basis, basis="hl2") or `sh0`..`sh3` (L1 SH of the incident radiance / pi, world space,
basis="sh"), each (R, R, 3); `ao` (R, R), 1 = open; `coverage` (R, R), 1 where a texel
centre lies in a UV triangle (before padding); `valid` (R, R), texels with a valid receiver
before filling. See docs/lightmaps.md.
"""

import time
import warnings
from dataclasses import dataclass, fields, replace

import numpy as np

from .. import Cancelled
from . import basis as frames
from . import atlas as atlases
from . import bounce, cells, dilate, geometry, lamps as lamp_models, light, seams, sparse_gather, tent, texels, tilts
from . import refine as refinement
from .geometry import Surface, Target

BASES = ("hl2", "sh", "flat")

#: Refined texels whose samples disagree on a sun take this many times the samples (a sun's
#: shadow edge along a column of texels, between two samples, was 12-16 % off Cycles' with 4).
EDGE_SAMPLES = 4

#: Refined texels see each lamp with a size through this many times `lamp_points`: refinement
#: picks the texels where light changes fast, penumbrae among them, whose thin tails (a lamp's
#: corner past a table's edge) 16 points per sample miss. In the room of
#: bench/lightmap_cycles.py lit by an area lamp, sky and sun (64 x 64, direct light), the mean
#: error against Cycles went from 1.68 to 1.22 % for 0.35 -> 0.49 s (at 128 x 128: 1.54 -> 1.25 %,
#: 0.96 -> 1.25 s); 2x: 1.37 %, 0.40 s; 8x: 1.11 %, 0.71 s.
REFINED_LAMP_POINTS = 4

#: Texels whose samples disagree on a sun (and are all valid) then see each sun through this
#: many times the edge samples' points, by sun rays alone (no masks, no lamps): a hard shadow
#: edge across a texel is its share of points in the sun. The corner of
#: bench/lightmap_cycles.py, 64 x 64: direct light 0.21 -> 0.17 % off Cycles, with 2 bounces
#: 0.38 -> 0.35 %, for 0.01 s (64 full samples instead: 0.17 % and 0.35 % for 0.09 s more).
SUN_EDGE_POINTS = 4


def positive_int(value, what, minimum=1):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{what} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def checked_lighting(lighting):
    if lighting is None:
        return None
    array = geometry.finite(lighting, "lighting", (-1, 3))
    if len(array) not in (1, 4, 9, 16, 25):
        raise ValueError(f"lighting must have 1, 4, 9, 16 or 25 SH coefficients per colour, got {len(array)}")
    return array.astype(np.float32)


def checked_suns(suns):
    out = []
    for i, sun in enumerate(suns):
        d = geometry.finite(sun.direction, f"sun {i}: direction", (3,))
        if not np.linalg.norm(d) > 0:
            raise ValueError(f"sun {i}: direction is zero")
        strength = np.asarray(sun.strength, dtype=np.float64)
        if strength.size not in (1, 3) or not np.isfinite(strength).all():
            raise ValueError(f"sun {i}: strength must be a finite number or RGB triple")
        if not (np.isfinite(sun.angle) and 0 <= sun.angle < np.pi):
            raise ValueError(f"sun {i}: angle must be in [0, pi) radians, got {sun.angle!r}")
        out.append(light.Sun(d / np.linalg.norm(d), strength, float(sun.angle), bool(getattr(sun, 'indirect_only', False))))
    return out


_BITS_OF_BYTE = np.array([bin(b).count("1") for b in range(256)], np.uint8)


def blocked_cells(masks):
    """Set bits per packed mask (P, 16) uint64: np.bitwise_count (numpy 2, 10x faster), else a
    byte at a time (Blender 4.2 to 5.0 bundle numpy 1.26, which does not have it)."""
    if hasattr(np, "bitwise_count"):
        return np.bitwise_count(masks).sum(axis=1, dtype=np.int64)
    return _BITS_OF_BYTE[np.ascontiguousarray(masks).view(np.uint8)].sum(axis=1, dtype=np.int64)


class Steps:
    """Progress over `total` steps, reported to `callback` (the engine's convention: a
    fraction; False cancels, raising Cancelled naming `what`). `chunks` keeps the reports
    (and so a cancel's latency) near `INTERVAL` seconds of CPU time apart whatever the scene
    (CPU time: a machine busy with other work does not shrink the chunks)."""

    INTERVAL = 0.05  # CPU seconds between two reports (on 2 cores, 0.025 to 0.05 s): a cancel lands within 0.2 s

    def __init__(self, callback, total, what="lightmap bake"):
        self.callback, self.total, self.done, self.what = callback, max(total, 1), 0, what

    def step(self, amount=1):
        self.done += amount
        if self.callback is not None and self.callback(min(self.done / self.total, 1.0)) is False:
            raise Cancelled(f"{self.what} cancelled")

    def check(self):
        """A report without progress: lets a cancel through."""
        self.step(0)

    def chunks(self, count, weight=1, first=1024, least=256, most=1 << 16):
        """Slices over `count` items, each sized from the measured CPU time per item to take
        about INTERVAL (the first `first` items, never fewer than `least`: the engine's calls
        cost a few milliseconds each), with a report of `weight` per item after each."""
        start, size = 0, first
        while start < count:
            stop = min(start + size, count)
            t0 = time.process_time()
            yield slice(start, stop)
            elapsed = time.process_time() - t0
            self.step((stop - start) * weight)
            rate = (stop - start) / max(elapsed, 1e-6)
            size = int(min(max(rate * self.INTERVAL, least), 2 * size, most))
            start = stop


def direct_light(scene, points, ng, lobes, lighting, suns, index, offsets, want_sh, offset, progress, masks=None,
                 exact_suns=True, texel_grid=None, lamps=(), lamp_points=16):
    """Direct light (P, L, 3), ao (P,), L1 SH (P, 4, 3) or None, and whether each sun reaches
    each sample (P, S): `environment_light` plus `sun_and_lamp_light`. `masks` (P, 16):
    the samples' raw visibility masks when already known."""
    if masks is None:
        masks = scene.visibility(points, ng, offset=offset)
    maps, ao, sh = environment_light(masks, ng, lobes, lighting, want_sh, progress)
    more, more_sh, sun_lit = sun_and_lamp_light(scene, points, ng, lobes, suns, index, offsets, want_sh, offset, progress,
                                                exact_suns, texel_grid, lamps, lamp_points)
    return maps + more, ao, (sh + more_sh if want_sh else None), sun_lit


def environment_light(masks, ng, lobes, lighting, want_sh, progress):
    """The environment's light (P, L, 3), ao (P,) and L1 SH (P, 4, 3) or None at samples
    with geometric normals `ng` and raw masks (P, 16), read in the frame of `ng` a chunk at
    a time (1 KiB a sample unpacked)."""
    p = len(masks)
    t, b = cells.engine_frame(ng)
    maps = np.zeros(lobes.shape[:2] + (3,), np.float32)
    ao = np.ones(p, np.float32)
    sh = np.zeros((p, 4, 3), np.float32) if want_sh else None
    for s in progress.chunks(p):
        m, a, h = light.environment(masks[s], t[s], b[s], ng[s], lobes[s], lighting, want_sh)
        maps[s], ao[s] = m, a
        if want_sh:
            sh[s] = h
    return maps, ao, sh


def sun_and_lamp_light(scene, points, ng, lobes, suns, index, offsets, want_sh, offset, progress, exact_suns=True,
                       texel_grid=None, lamps=(), lamp_points=16):
    """The light of suns and lamps (P, L, 3), its L1 SH (P, 4, 3) (zeros without want_sh), and
    whether each sun reaches each sample (P, S). texel_grid: (texel ids (P,), grid shape
    (T, R, R)) for adaptive sun rays (`_sun_lit`), None for a ray per sample."""
    p = len(points)
    maps = np.zeros(lobes.shape[:2] + (3,), np.float32)
    sh = np.zeros((p, 4, 3), np.float32)
    sun_lit = np.zeros((p, len(suns)), np.float32)
    for k, sun in enumerate(suns):
        dirs = light.sun_directions(sun, p, index, offsets)
        lit = sun_lit[:, k]
        facing = (dirs * ng).sum(1) > 0  # below the horizon: no ray needed
        progress.check()
        if facing.any() and texel_grid is not None:
            lit[facing] = _sun_lit(scene, points[facing], ng[facing], dirs[facing], texel_grid[0][facing],
                                   texel_grid[1], offset, progress)
        elif facing.any():
            lit[facing] = _sun_rays(scene, points[facing], ng[facing], dirs[facing], offset, progress, exact_suns)
        for s in progress.chunks(p, weight=0, first=4096):
            m, h = light.sun_light(sun, lit[s], ng[s], lobes[s], dirs[s], want_sh)
            maps[s] += m
            if want_sh:
                sh[s] += h
    for lamp in lamps:
        for s in progress.chunks(p, weight=0, first=64, least=16):
            m, h = lamp_models.lamp_light(scene, lamp, points[s], ng[s], lobes[s], index[s], offsets, lamp_points,
                                          offset, want_sh)
            maps[s] += m
            if want_sh:
                sh[s] += h
    return maps, sh, sun_lit


def _sun_rays(scene, points, ng, dirs, offset, progress, exact=True):
    """`light.sun_visibility` a chunk at a time (a cancel gets through between chunks)."""
    lit = np.empty(len(points), np.float32)
    for s in progress.chunks(len(points), weight=0):
        lit[s] = light.sun_visibility(scene, points[s], ng[s], dirs[s], offset=offset, exact=exact)
    return lit


def _sun_lit(scene, points, ng, dirs, texel_id, shape, offset, progress=None):
    """Sun visibility per sample, adaptively (as VRAD refines luxels): one ray per texel
    first; every sample of a texel gets a ray of its own only where that texel or one of its
    8 neighbours disagrees. A shadow thinner than a texel that falls between the first rays
    can be missed."""
    progress = progress or Steps(None, 1)
    rep, of_sample = _representatives(texel_id, np.ones(len(texel_id), bool))
    progress.check()
    first = _sun_rays(scene, points[rep], ng[rep], dirs[rep], offset, progress)
    grid = np.full(int(np.prod(shape)), -1, np.int8)
    grid[texel_id[rep]] = first.astype(np.int8)
    grid = grid.reshape(shape)
    padded = np.pad(grid, ((0, 0), (1, 1), (1, 1)), constant_values=-1)
    mixed = np.zeros(shape, bool)
    r = shape[1]
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            other = padded[:, dy:dy + r, dx:dx + r]
            mixed |= (other >= 0) & (grid >= 0) & (other != grid)
    lit = first[of_sample]
    redo = mixed.reshape(-1)[texel_id]
    redo[rep] = False
    if redo.any():
        lit[redo] = _sun_rays(scene, points[redo], ng[redo], dirs[redo], offset, progress)
    return lit


def _sample_geometry(target, resolution, samples, check=None, only=None):
    """Texels of a target and, per sample, world position, geometric normal, lobes' frame and
    a texel's world size; `only` (R * R,) bool: those texels' samples only
    (`texels.rasterize`)."""
    pos, ng, normals, tangents, uv, tris = geometry.target_corners(target)
    check = check or (lambda: None)
    tx = texels.rasterize(uv, resolution, samples, check, only)
    check()
    if only is None and not len(tx.texel):
        warnings.warn(f"{target.label}: its lightmap UVs cover no texel of the {resolution} x {resolution} map",
                      RuntimeWarning, stacklevel=3)
    if only is None and tx.overlapping:
        warnings.warn(f"{target.label}: its lightmap UV islands overlap ({tx.overlapping} samples in more than "
                      "one triangle); each texel keeps the first triangle", RuntimeWarning, stacklevel=3)
    w = tx.bary
    points = np.einsum("pkj,pk->pj", pos[tx.triangle], w)
    check()
    t, b, n = frames.tangent_frames(np.einsum("pkj,pk->pj", normals[tx.triangle], w),
                                    np.einsum("pkj,pk->pj", tangents[tx.triangle], w))
    return tx, points, ng[tx.triangle], (t, b, n), _texel_spacing(pos, uv, resolution)[tx.triangle], tris, uv


def _texel_spacing(pos, uv, resolution):
    """(K,): the world size of a texel on each triangle (corners `pos` (K, 3, 3), `uv`
    (K, 3, 2)), the square root of its world area over its area in texels."""
    world = np.linalg.norm(np.cross(pos[:, 1] - pos[:, 0], pos[:, 2] - pos[:, 0]), axis=1)
    e1, e2 = (uv[:, 1] - uv[:, 0]) * resolution, (uv[:, 2] - uv[:, 0]) * resolution
    in_texels = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    return np.sqrt(world / np.maximum(in_texels, 1e-300))


def _texel_maps(texel, resolution, values, valid):
    """Mean of the valid samples of each texel (`texel`: of each sample): (R, R, C) and the
    texels that had one."""
    r2 = resolution * resolution
    count = np.bincount(texel[valid], minlength=r2)
    out = np.stack([np.bincount(texel[valid], values[valid, c], r2) for c in range(values.shape[1])], axis=1)
    out = out / np.maximum(count, 1)[:, None]
    return out.reshape(resolution, resolution, -1).astype(np.float32), (count > 0).reshape(resolution, resolution)


def bake(scene, targets, *, resolution, lighting=None, suns=(), lamps=(), surfaces=(), bounces=2, samples=4, margin=2,
         basis="hl2", offset=None, stitch_seams=True, adaptive=True, contrast=refinement.CONTRAST, adaptive_suns=False,
         lamp_points=16, atlas=False, bounce_scene=None, edge_samples=None, progress=None):
    """Bakes lightmaps of `targets` (`Target`s) in `scene` (a `hemishadow.Scene` holding every
    blocker); returns one dict of maps per target (see the module docstring), or with
    atlas=True a list of one dict: the map all targets share (`atlas.py`).

    resolution: texels per side, one int for all targets or one per target (atlas: one int).
    atlas: the targets' lightmap UVs place their islands in slots of one map (they must not
        overlap): each is filled, padded and stitched as if baked alone, and padding never
        crosses into another target's islands.
    lighting: environment SH (K, 3), K = 1, 4, 9, 16 or 25, radiance in the project's convention
        (`hemishadow.project_environment`, the add-on's World); None: no environment.
    suns: `Sun`s (direction towards the light, strength in W/m^2, angular diameter).
    lamps: `Point`, `Spot` and `Area` lamps (`lamps.py`; DESIGN.md's power conventions).
        Suns and lamps with `indirect_only` light the bounce surfaces but not the maps.
    lamp_points: points per receiver sample on each lamp with a size (soft shadows; a g x g
        grid, g = round(sqrt(lamp_points))); lamps without size use one. Refined texels take
        `REFINED_LAMP_POINTS` times as many.
    surfaces: `Surface`s of the meshes that reflect or emit light besides the targets' own
        (bounce receivers at their vertices); meshes not described stay black (block only).
    bounces: diffuse bounces (0: direct light only). samples: supersamples per texel, in total
        (a g x g grid when a square, else a low-discrepancy sequence).
    adaptive: light every texel at its centre first and give all `samples` only to texels
        where that is not enough (`refine.py`: shadow and contact edges, light curving across
        the texel, rims of UV islands, texels inside or beside solid geometry, where the
        light departs from its neighbours' by more than `contrast`); False: every sample of
        every texel.
    edge_samples: supersamples of refined texels whose samples disagree on whether a sun
        reaches them (a hard shadow edge: `_sun_edges`); None: `EDGE_SAMPLES` x samples; at
        most `samples`: none. Only with adaptive supersampling.
    margin: texels of padding around islands. basis: "hl2" (flat, b0-b2, ao), "sh" (flat,
        sh0-sh3, ao) or "flat" (flat, ao). offset: the receivers' lift (`Scene`'s default).
    adaptive_suns: with adaptive=False, a sun ray per texel first, then per sample where
        neighbours disagree (`_sun_lit`: an edge between two texels' first rays is missed);
        False (the default): a ray per sample. stitch_seams: match texels across UV seams.
    bounce_scene: a `hemishadow.Scene` of the same surfaces, mesh for mesh (same ids), with
        more vertices to carry bounce light (the add-on splits long edges, `geometry.bisected`);
        None: `scene`.
        `scene` then serves direct light only: its coarser meshes make those walks cheaper.
    progress: None or a callable taking the fraction done; returning False raises
        `hemishadow.Cancelled` and nothing is returned.
    """
    targets, sizes = _targets_and_sizes(targets, resolution)
    if atlas and len(set(sizes)) != 1:
        raise ValueError(f"an atlas has one resolution, got {sorted(set(sizes))}")
    samples = positive_int(samples, "samples")
    edge_samples = EDGE_SAMPLES * samples if edge_samples is None else positive_int(edge_samples, "edge_samples")
    if not (np.isfinite(contrast) and contrast > 0):
        raise ValueError(f"contrast must be a positive number, got {contrast!r}")
    margin = positive_int(margin, "margin", 0)
    bounces = positive_int(bounces, "bounces", 0)
    if basis not in BASES:
        raise ValueError(f"basis must be one of {BASES}, got {basis!r}")
    lighting, suns = checked_lighting(lighting), checked_suns(suns)
    lamps = [lamp_models.check(lamp, i) for i, lamp in enumerate(lamps)]
    lamp_points = positive_int(lamp_points, "lamp_points")
    direct_suns = [s for s in suns if not s.indirect_only]
    direct_lamps = [lamp for lamp in lamps if not lamp.indirect_only]
    want_sh = basis == "sh"
    offs = texels.offsets(samples)

    setup = Steps(progress, 1)  # before the totals are known: reports of nothing done, for a cancel
    geo = [_sample_geometry(tg, r, samples, setup.check) for tg, r in zip(targets, sizes)]
    full = _Samples.of(geo, sizes, atlas, basis)
    if not len(full.points):
        raise ValueError(f"the lightmap UVs cover no texel of the {max(sizes)} x {max(sizes)} map: "
                         "nothing to bake")
    if samples == 1:  # one sample a texel, nothing to average its mask's turn with (`tilts.py`)
        full = replace(full, tilt=np.full(len(full.tilt), -1))
    centres = None
    if adaptive and samples > 1:
        centres = _Samples.of([_sample_geometry(tg, r, 1, setup.check) for tg, r in zip(targets, sizes)], sizes,
                              atlas, basis)
    cells.moments(setup.check)  # cached: computed once per process
    bounce_scene = scene if bounce_scene is None else bounce_scene
    for built in {id(scene): scene, id(bounce_scene): bounce_scene}.values():
        built.prepare()  # the engine's scene build (once per scene; it cannot be interrupted)
        setup.check()

    receivers = bounce_receivers(targets, surfaces) if (bounces or emitters(targets, surfaces)) else []
    vertex_count = sum(len(r[1]) for r in receivers)
    first = 0 if centres is None else len(centres.points)
    steps = Steps(progress, 2 * (first + len(full.points)) + vertex_count * (1 + bounces)
                  + len(full.points) * bool(receivers))
    light_args = dict(lighting=lighting, suns=direct_suns, lamps=direct_lamps, lamp_points=lamp_points, want_sh=want_sh,
                      offset=offset, steps=steps)
    if centres is None:
        lit = _light(scene, full, offs, adaptive_suns=adaptive_suns, **light_args)
    else:
        finer = _edge_sampler(targets, sizes, atlas, basis, steps.check)
        lit = _refined(scene, centres, full, offs, contrast, steps, light_args, finer,
                       edge_samples if edge_samples > samples else None)
    if receivers:
        gathered = _indirect(bounce_scene, receivers, lit, lighting, suns, lamps, bounces, offset, steps)
        if gathered is not None:
            for s in steps.chunks(len(lit.points), weight=0):
                lit.maps[s] += bounce.lobe_irradiance(gathered[s], lit.lobes[s])
                if want_sh:
                    lit.sh[s] += gathered[s, :4] / np.float32(np.pi)

    names = ["flat"] + (["b0", "b1", "b2"] if basis == "hl2" else []) + (["sh0", "sh1", "sh2", "sh3"] if want_sh else [])
    values = _value_rows(lit.maps, lit.sh, lit.ao)
    parts = [(lit.target == k, tx, tris, uv) for k, (tx, *_rest, tris, uv) in enumerate(geo)]
    if atlas:
        return [_finish_atlas([(lit.texel[of], tx, values[of], lit.valid[of], tris, uv) for of, tx, tris, uv in parts],
                              sizes[0], names, margin, stitch_seams, steps)]
    return [_finish(lit.texel[of], tx, r, values[of], lit.valid[of], tris, uv, names, margin, stitch_seams, steps)
            for r, (of, tx, tris, uv) in zip(sizes, parts)]


@dataclass
class _Samples:
    """Receiver samples of every target, in target order: world position, geometric normal,
    shading frame and lobes, the pattern it sees suns and lamps by (`index`: its position in
    the texel, permuted per texel by `texels.light_patterns`), its
    `target`, its texel in the target's map (`texel`) and in the bake's (layers, R, R) grid
    (`cell`), whether that texel's centre lies in a UV triangle (`covered`), whether its
    triangle has a normal (`usable`: zero-area ones take the shading normal), the direction
    its mask tilts to (`tilt`, `tilts.py`) and a texel's world size there (`spacing`). Once lit
    (`_light`), also `valid`, `maps`, `ao`, `sh`, `sun` (1 where each sun reaches it) and
    `environment` (P, C): the environment's share of maps and sh, and ao, as the bake's
    value rows."""
    points: np.ndarray
    ng: np.ndarray
    t: np.ndarray
    b: np.ndarray
    n: np.ndarray
    lobes: np.ndarray
    index: np.ndarray
    target: np.ndarray
    texel: np.ndarray
    cell: np.ndarray
    covered: np.ndarray
    usable: np.ndarray
    tilt: np.ndarray
    spacing: np.ndarray
    shape: tuple
    valid: np.ndarray = None
    maps: np.ndarray = None
    ao: np.ndarray = None
    sh: np.ndarray = None
    sun: np.ndarray = None
    environment: np.ndarray = None

    @classmethod
    def of(cls, geo, sizes, atlas, basis):
        """The samples of `_sample_geometry`'s results (one per target)."""
        r = max(sizes)
        t, b, n = (np.concatenate([g[3][k] for g in geo]) for k in range(3))
        ng = np.concatenate([g[2] for g in geo])
        usable = np.linalg.norm(ng, axis=1) > 0.5
        ng = np.where(usable[:, None], ng, n)
        lobes = n[:, None] if basis != "hl2" else np.concatenate([n[:, None], frames.hl2_world(t, b, n)], axis=1)
        texel = np.concatenate([g[0].texel for g in geo])
        target = np.concatenate([np.full(len(g[0].texel), k) for k, g in enumerate(geo)])
        if atlas:  # one map: (row, col) of the shared grid
            cell, layers = texel, 1
        else:  # (target, row, col) in a T x r x r grid
            size = np.asarray(sizes)[target]
            cell, layers = (target * r + texel // size) * r + texel % size, len(geo)
        covered = np.concatenate([g[0].coverage.reshape(-1)[g[0].texel] for g in geo])
        return cls(np.concatenate([g[1] for g in geo]), ng, t, b, n, lobes, np.concatenate([g[0].light for g in geo]),
                   target, texel, cell, covered, usable, np.concatenate([g[0].tilt for g in geo]),
                   np.concatenate([g[4] for g in geo]), (layers, r, r))

    def take(self, keep):
        return replace(self, **{f.name: getattr(self, f.name)[keep] for f in fields(self)
                                if isinstance(getattr(self, f.name), np.ndarray)})

    def joined(self, other):
        return replace(self, **{f.name: np.concatenate([getattr(self, f.name), getattr(other, f.name)])
                                for f in fields(self) if isinstance(getattr(self, f.name), np.ndarray)})


def _light(scene, samples, offsets, *, lighting, suns, lamps, lamp_points, want_sh, offset, steps, adaptive_suns=False,
           known_valid=None):
    """The samples lit by direct light: `valid` (inside solid geometry or not), `maps`, `ao`, `sh`,
    `environment` (the environment's share, `_Samples`), each mask taken through its tilted
    lattice (`tilts.py`); `known_valid` (P,) bool: samples known to be valid
    (`_reached_from_centres`)."""
    tilted = tilts.tilted_normals(samples.ng, samples.tilt)  # masks through a turned lattice, read unturned
    masks, valid = _masks_and_valid(scene, samples.points, tilted, offset, steps, known_valid)
    valid &= samples.usable
    maps, ao, sh = environment_light(masks, samples.ng, samples.lobes, lighting, want_sh, steps)
    environment = _value_rows(maps, sh, ao)
    grid = (samples.cell, samples.shape) if adaptive_suns else None
    more, more_sh, sun_lit = sun_and_lamp_light(scene, samples.points, samples.ng, samples.lobes, suns, samples.index,
                                                offsets, want_sh, offset, steps, texel_grid=grid, lamps=lamps,
                                                lamp_points=lamp_points)
    return replace(samples, valid=valid, maps=maps + more, ao=ao, sh=sh + more_sh if want_sh else None, sun=sun_lit,
                   environment=environment)


def _value_rows(maps, sh, ao):
    """(P, C): each sample's maps (P, L, 3), L1 SH (P, 4, 3; None: none) and ao (P,) side by
    side, the bake's value rows (`_Samples.environment` too)."""
    return np.concatenate([maps.reshape(len(ao), -1)] + ([] if sh is None else [sh.reshape(len(ao), -1)])
                          + [ao[:, None]], axis=1)


def _refined(scene, centres, full, offsets, contrast, steps, light_args, finer=None, edge_samples=None):
    """Adaptive supersampling (`refine.py`): every texel lit at its centre, then all the
    samples of the texels where that is not enough, exactly as without refinement, then
    `finer(texels, edge_samples)` (`_Samples` with that many samples of the texels
    (layers, R, R) asked, and their offsets) where those samples disagree on a sun
    (`_sun_edges`), and `SUN_EDGE_POINTS` times as many sun rays there
    (`_sun_edges_resampled`); one set of samples per texel. edge_samples None: no edge
    supersampling."""
    lit = _lit_centres(scene, centres, light_args)
    lit = _smoothed_environment(lit, lit.valid)
    cells_count = int(np.prod(centres.shape))
    values = np.zeros((cells_count, lit.maps[0].size + 1), np.float32)
    values[lit.cell] = np.concatenate([lit.maps.reshape(len(lit.ao), -1), lit.ao[:, None]], axis=1)
    usable = np.zeros(cells_count, bool)
    usable[lit.cell] = lit.covered & lit.valid
    full_value = np.r_[np.full(values.shape[1] - 1, np.nan), 1.0]  # the light: its brightest texel (NaN); AO: 1
    least = np.r_[np.zeros(values.shape[1] - 1), refinement.AO_CELLS * cells.largest_cell_ao()]
    refine = refinement.texels_to_refine(values.reshape(centres.shape + (-1,)), usable.reshape(centres.shape),
                                         contrast, full_value, least).reshape(-1)
    more = refine[full.cell]
    steps.step(2 * int((~more).sum()))  # the samples of texels that keep their centre's light
    if not more.any():
        return lit
    light_args = dict(light_args, lamp_points=light_args["lamp_points"] * REFINED_LAMP_POINTS)
    refined = full.take(more)
    refined = _light(scene, refined, offsets, known_valid=_reached_from_centres(scene, lit, refined, light_args["offset"]),
                     **light_args)
    if edge_samples is not None and light_args["suns"]:
        edges = _sun_edges(refined, centres.shape)
        if edges.any():
            extra, extra_offsets = finer(edges.reshape(centres.shape), edge_samples)
            steps.total += 2 * len(extra.points)
            reached = _reached_from_centres(scene, lit, extra, light_args["offset"])
            refined = refined.take(~edges[refined.cell]).joined(_light(scene, extra, extra_offsets, known_valid=reached,
                                                                       **light_args))
            refined = _sun_edges_resampled(scene, refined, edges, finer, SUN_EDGE_POINTS * edge_samples, light_args)
    return lit.take(~refine[lit.cell]).joined(refined)


def _sun_edges_resampled(scene, lit, edges, finer, points, light_args):
    """`lit` with the sun light of the texels `edges` (flat grid bool) whose samples are all
    valid taken from `points` per texel (`finer`), by sun rays alone: each sample's share of a
    sun becomes its texel's share of points in the sun (a point of a texel with an invalid
    sample could lie inside solid geometry, and those texels keep their samples')."""
    edges = edges.copy()
    edges[lit.cell[~lit.valid]] = False
    mine = edges[lit.cell]
    if not mine.any():
        return lit
    dense, offsets = finer(edges.reshape(lit.shape), points)
    steps, want_sh = light_args["steps"], light_args["want_sh"]
    maps, sun_lit = lit.maps.copy(), lit.sun.copy()
    sh = None if lit.sh is None else lit.sh.copy()
    count = np.maximum(np.bincount(dense.cell, minlength=len(edges)), 1)
    for k, sun in enumerate(light_args["suns"]):
        dirs = light.sun_directions(sun, len(dense.points), dense.index, offsets)
        facing = (dirs * dense.ng).sum(1) > 0
        seen = np.zeros(len(dense.points), np.float32)
        seen[facing] = _sun_rays(scene, dense.points[facing], dense.ng[facing], dirs[facing], light_args["offset"], steps)
        share = (np.bincount(dense.cell, seen, len(edges)) / count)[lit.cell[mine]].astype(np.float32)
        centre = light.sun_directions(replace(sun, angle=0.0), int(mine.sum()), None, None)
        unit, unit_sh = light.sun_light(sun, np.ones(len(centre), np.float32), lit.ng[mine], lit.lobes[mine], centre,
                                        want_sh)
        change = share - sun_lit[mine, k]
        maps[mine] += change[:, None, None] * unit
        if want_sh:
            sh[mine] += change[:, None, None] * unit_sh
        sun_lit[mine, k] = share
    return replace(lit, maps=maps, sh=sh, sun=sun_lit)


def _smoothed_environment(lit, smooth):
    """`lit` (a sample per texel) with the environment light of the samples `smooth` (P,)
    bool tent-filtered over theirs and their smooth neighbours' (`tent.smoothed`: the four
    turned lattices averaged, `tilts.py`)."""
    if not smooth.any():
        return lit
    grid = sparse_gather.Grid(lit.cell, lit.valid, lit.shape, group=lit.target)
    environment = tent.smoothed(lit.environment, grid, lit.points, lit.ng, lit.spacing, smooth)
    change = environment - lit.environment
    size = lit.maps[0].size
    maps = lit.maps + change[:, :size].reshape(lit.maps.shape)
    sh = None if lit.sh is None else lit.sh + change[:, size:size + lit.sh[0].size].reshape(lit.sh.shape)
    return replace(lit, maps=maps, sh=sh, ao=lit.ao + change[:, -1], environment=environment)


def _lit_centres(scene, centres, light_args):
    """The texels' centre samples lit (`_light`): those of every other row and column first,
    then the rest, each valid without a validity walk where it reaches the first of those
    around it (`_reached_from_centres`; a quarter of the walks in a closed room)."""
    layer, rest = np.divmod(centres.cell, centres.shape[1] * centres.shape[2])
    row, col = np.divmod(rest, centres.shape[2])
    origin = _lattice_origins(centres)
    step_row, step_col = (row - origin[:, 0]) % 2, (col - origin[:, 1]) % 2
    lattice = (step_row == 0) & (step_col == 0)
    lit = _light(scene, centres.take(lattice), texels.offsets(1), **light_args)
    others = centres.take(~lattice)
    if not len(others.cell):
        return lit
    corner = ((layer * centres.shape[1] + row - step_row) * centres.shape[2] + col - step_col)[~lattice]
    reached = _reached_from_centres(scene, lit, others, light_args["offset"], cells=corner)
    return lit.joined(_light(scene, others, texels.offsets(1), known_valid=reached, **light_args))


def _lattice_origins(samples):
    """(P, 2): the first row and column of each sample's target in the bake's grid, where its
    lattices start (`_lit_centres`, `sparse_gather`): an atlas slot moves both with the target,
    so a target bakes the same in an atlas as alone."""
    row, col = samples.cell // samples.shape[2] % samples.shape[1], samples.cell % samples.shape[2]
    first = np.full((int(samples.target.max(initial=0)) + 1, 2), np.iinfo(np.int64).max)
    np.minimum.at(first[:, 0], samples.target, row)
    np.minimum.at(first[:, 1], samples.target, col)
    return first[samples.target]


def _reached_from_centres(scene, centres, samples, offset, cells=None):
    """(P,) bool: samples whose texel's centre sample (of `centres`, lit; or that of texel
    `cells` (P,) instead of their own) is valid and which a straight segment from it reaches
    without crossing a surface. Those lie in the same open space as the centre, so are valid
    too, and need no validity walk: in a closed room every sample needs one otherwise (most
    of each hemisphere is blocked), and the walks cost a third of a direct-light bake (the
    room of bench/lightmap_cycles.py, 128 x 128)."""
    of_cell = np.full(int(np.prod(centres.shape)), -1)
    of_cell[centres.cell] = np.arange(len(centres.cell))
    centre = of_cell[samples.cell if cells is None else cells]
    known = centre >= 0
    known[known] = centres.valid[centre[known]]
    if not known.any():
        return known
    lift = lamp_models.lift(scene, offset)
    start = centres.points[centre[known]] + centres.ng[centre[known]] * lift
    end = samples.points[known] + samples.ng[known] * lift
    # nothing left out at the ends (`occluded`'s offset): both lie above their surface by the
    # lift already, and a centre a hair outside a wall would reach a sample inside it
    known[known] = ~scene.occluded(start, end, offset=0.0)
    return known


def _edge_sampler(targets, sizes, atlas, basis, check):
    """`_refined`'s `finer`: `samples` per texel of the texels a (layers, R, R) grid asks for
    (`_Samples` and their offsets), rasterized for those texels only."""
    def finer(grid, samples):
        wanted = [grid[0].ravel() if atlas else grid[k, :r, :r].ravel() for k, r in enumerate(sizes)]
        geo = [_sample_geometry(tg, r, samples, check, only=w) for tg, r, w in zip(targets, sizes, wanted)]
        return _Samples.of(geo, sizes, atlas, basis), texels.offsets(samples)

    return finer


def _sun_edges(samples, shape):
    """(layers * R * R,) bool: texels (of the grid `shape`) whose valid samples (lit) disagree
    on whether a sun reaches them (`sun`: the rays `direct_light` cast), or agree but not with
    a side neighbour's (the edge runs between their samples): a hard shadow edge, which a
    few samples cut coarsely. Soft light (sky, lamps with a size) varies within a texel too,
    but smoothly: there the samples' mean is good."""
    edges = refinement.disagreeing(samples.cell, samples.valid, samples.sun, int(np.prod(shape)))
    return edges | refinement.differs_from_a_neighbour(samples.cell, samples.valid, samples.sun, shape)


def _targets_and_sizes(targets, resolution):
    targets = list(targets)
    if not targets:
        raise ValueError("no targets to bake")
    if isinstance(resolution, (list, tuple, np.ndarray)):
        if len(resolution) != len(targets):
            raise ValueError(f"{len(resolution)} resolutions for {len(targets)} targets")
        return targets, [positive_int(r, "resolution") for r in resolution]
    return targets, [positive_int(resolution, "resolution")] * len(targets)


def vertex_bounce(scene, receivers, lighting, suns, lamps, bounces, offset, steps):
    """Each bounce surface's vertex radiance after `bounces` passes, shown to the scene
    (`bounce.vertex_radiance`), from the direct light at its usable vertices along their
    normals: one walk per vertex (`bounce.VertexRecord`) gives both the masks of that light
    and the weights of every pass. Sun rays go towards the disk's centre, exact
    (`Scene.occluded`: 11 ms for 14,000 vertices of bench/probes_cycles.py's scene, against
    0.55 s for tilted mask queries); lamps are sampled at one point. With no pass the
    surfaces show their emission only."""
    if not bounces:
        return bounce.vertex_radiance(scene, receivers, [np.zeros((len(r[1]), 3), np.float32) for r in receivers], 0)
    record = bounce.VertexRecord(scene, receivers, offset, steps=steps)
    direct = []
    for i, (_, pts, nrm, ok, *_) in enumerate(receivers):
        d = np.zeros((len(pts), 3), np.float32)
        if ok.any():
            d[ok] = direct_light(scene, pts[ok], nrm[ok], nrm[ok][:, None], lighting, suns, np.zeros(ok.sum(), np.int64),
                                 texels.offsets(1), False, offset, steps, masks=record.masks_of(i), lamps=lamps,
                                 lamp_points=1)[0][:, 0]
        direct.append(d)
    return bounce.vertex_radiance(scene, receivers, direct, bounces, offset, steps=steps, record=record)


def _indirect(scene, receivers, lit, lighting, suns, lamps, bounces, offset, steps):
    """Gathered SH (P, 9, 3) of the light the samples `lit` (`_Samples` with their direct
    light) receive from the surfaces after `bounces` passes, once per texel, and at every
    other texel where it is smooth against the texel's whole light (`sparse_gather`), then
    tent-filtered (`tent.py`); None when every surface is black."""
    radiance = vertex_bounce(scene, receivers, lighting, suns, lamps, bounces, offset, steps)
    if not any(r.any() for r in radiance):
        steps.step(len(lit.points))
        return None
    rep, of_sample = _representatives(lit.cell, lit.valid)
    points, ng = lit.points[rep], lit.ng[rep]
    direct = lit.maps[rep, 0] / bounce.FLAT_PER_BAND0  # the flat map's light in band-0 units

    def gather_at(i):
        views = scene.gather_views(points[i], ng[i], bands=bounce.BANDS, offset=offset)
        return views.sh, views.distance[0]

    grid = sparse_gather.Grid(lit.cell[rep], lit.valid[rep], lit.shape, _lattice_origins(lit)[rep], lit.target[rep])
    out = sparse_gather.gather(gather_at, bounce.BANDS ** 2, points, ng, grid, steps,
                               weight=len(lit.points) / max(len(rep), 1), floor=direct)
    out = tent.smoothed(out.reshape(len(out), -1), grid, points, ng, lit.spacing[rep], lit.valid[rep])
    return out.reshape(len(out), bounce.BANDS ** 2, 3)[of_sample]


def _masks_and_valid(scene, points, ng, offset, steps=None, known_valid=None):
    """Raw masks (P, 16) and validity (P,) of the samples. `Scene.valid` is asked only where
    more than 45 % of a mask is blocked (it cannot fail below half), a second rasterization;
    in chunks where most samples need it (closed rooms), one `Scene.visibility_valid` call
    gives both. Chunks follow texel order, so each chunk's need predicts the next one's.
    Samples `known_valid` (P,) bool take a mask walk only."""
    if known_valid is not None and known_valid.any():
        masks = np.empty((len(points), 16), np.uint64)
        valid = np.ones(len(points), bool)
        where, kp, kn = np.flatnonzero(known_valid), points[known_valid], ng[known_valid]
        for s in (steps or Steps(None, 1)).chunks(len(where)):
            masks[where[s]] = scene.visibility(kp[s], kn[s], offset=offset)
        rest = ~known_valid
        if rest.any():
            masks[rest], valid[rest] = _masks_and_valid(scene, points[rest], ng[rest], offset, steps)
        return masks, valid
    masks = np.empty((len(points), 16), np.uint64)
    valid = np.ones(len(points), bool)
    limit = 0.45 * cells.directions().any(axis=1).sum()
    combined = False
    for s in (steps or Steps(None, 1)).chunks(len(points)):
        if combined:
            masks[s], valid[s] = scene.visibility_valid(points[s], ng[s], offset=offset)
            maybe = blocked_cells(masks[s]) > limit
        else:
            masks[s] = scene.visibility(points[s], ng[s], offset=offset)
            maybe = blocked_cells(masks[s]) > limit
            if maybe.any():
                valid[s][maybe] = scene.valid(points[s][maybe], ng[s][maybe], offset=offset)
        combined = maybe.mean() > 0.5
    return masks, valid


def _representatives(texel_id, valid):
    """One sample per texel (a valid one where there is one) and, per sample, the index of
    its texel's representative among them: indirect light is gathered once per texel."""
    order = np.lexsort((~valid, texel_id))
    first = np.r_[True, texel_id[order][1:] != texel_id[order][:-1]]
    rep = order[first]
    group = np.cumsum(first) - 1
    of_sample = np.empty(len(texel_id), np.int64)
    of_sample[order] = group
    return rep, of_sample


def _finish(texel, tx, resolution, values, valid, tris, uv, names, margin, stitch_seams, steps=None):
    """Texel means of the samples (`texel`: of each), invalid texels filled, padding, seams
    (islands and coverage from `tx`); the dict of named maps."""
    check = steps.check if steps is not None else None
    image, known = _texel_maps(texel, resolution, values, valid)
    had_valid = known.copy()
    dilate.fill(image, known, tx.island, check)
    dilate.dilate(image, known, margin, check)
    if stitch_seams:
        a, b = seams.seam_points(tris, uv, resolution)
        seams.stitch(image, known, a, b, check=check)
    return _named(image, names, tx.coverage, had_valid)


def _finish_atlas(parts, resolution, names, margin, stitch_seams, steps):
    """`_finish` for targets sharing one map (`atlas.compose`); `valid` and `coverage` are
    the union of the targets'."""
    pieces, had_valid, coverage = [], np.zeros((resolution,) * 2, bool), np.zeros((resolution,) * 2, bool)
    for texel, tx, values, valid, _, _ in parts:
        image, known = _texel_maps(texel, resolution, values, valid)
        pieces.append((image, known, tx.island))
        had_valid |= known
        coverage |= tx.coverage
        steps.step(0)
    image, known, _ = atlases.compose(pieces, resolution, pieces[0][0].shape[2], margin, steps.check)
    if stitch_seams:
        for *_, tris, uv in parts:
            seams.stitch(image, known, *seams.seam_points(tris, uv, resolution), check=steps.check)
    return _named(image, names, coverage, had_valid)


def _named(image, names, coverage, had_valid):
    out = {name: np.ascontiguousarray(image[..., 3 * i:3 * i + 3]) for i, name in enumerate(names)}
    out["ao"] = np.ascontiguousarray(image[..., -1])
    out["coverage"] = coverage.astype(np.float32)
    out["valid"] = had_valid
    return out


def emitters(targets, surfaces):
    return any(np.any(np.asarray(s.emission) != 0) for s in list(surfaces) + [t.surface for t in targets])


def bounce_receivers(targets, surfaces):
    """A `bounce.BounceSurface` per distinct mesh."""
    seen, out = set(), []
    for surface in list(surfaces) + [t.surface for t in targets]:
        if surface.mesh_id in seen:
            continue
        seen.add(surface.mesh_id)
        label = surface.name or f"mesh {surface.mesh_id}"
        pts, nrm = geometry.vertex_receivers(surface)
        length = np.linalg.norm(nrm, axis=1)
        usable = length > 0
        nrm = nrm / np.where(usable, length, 1.0)[:, None]
        albedo = geometry.per_vertex(surface.albedo, len(pts), "albedo", label)
        emission = geometry.per_vertex(surface.emission, len(pts), "emission", label)
        out.append(bounce.BounceSurface(surface.mesh_id, pts, nrm, usable, albedo, emission,
                                        np.asarray(surface.triangles, dtype=np.int64)))
    return out


__all__ = ["BASES", "Surface", "Target", "bake"]
