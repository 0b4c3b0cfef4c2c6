"""Relightable panoramas of a Blender scene (issue 13): Blender data in, `hemishadow.panorama`
bake out, files written all or nothing.

`prepare` reads Blender (main thread): the viewpoint, Cycles' primary visibility
(panorama_hits), the engine scene of the visible meshes (probes.scene_geometry, live objects
included) and, for bounce light, the scene's lighting as the lightmap bake reads it (World SH,
suns, point/spot/area lamps). `compute` uses no bpy (a worker thread runs it): the optional
bounce term (the lightmap baker's vertex passes and ordered gather, at the pixels' surfaces,
times their albedo) and the engine's per-pixel transfer. `finish` writes FILE.exr and the
compact form (FILE/panorama.json with its 8-bit maps) beside it; a failure leaves neither.
"""

from __future__ import annotations

import dataclasses
import importlib
import os
import shutil
import tempfile

import bpy
import numpy as np

from . import lightmaps, panorama_hits

BANDS = {9: 3, 16: 4, 25: 5}  # coefficients -> bands, as `--bands {9,16,25}` elsewhere
MAX_SIZE = (4096, 2048)


@dataclasses.dataclass
class Prepared:
    """Everything the engine needs; `compute` reads no Blender data."""
    engine_scene: object
    hits: object
    surfaces: list
    origin: np.ndarray
    rotation: np.ndarray
    size: tuple
    bands: int
    bounces: int
    lighting: np.ndarray | None
    suns: list
    lamps: list


def checked_size(size):
    w, h = (int(v) for v in size)
    if not (1 <= w <= MAX_SIZE[0] and 1 <= h <= MAX_SIZE[1]):
        raise ValueError(f"panorama size must be between 1 x 1 and {MAX_SIZE[0]} x {MAX_SIZE[1]}, got {w} x {h}")
    return w, h


def bands_of(coefficients):
    if coefficients not in BANDS:
        raise ValueError(f"coefficients must be 9, 16 or 25, got {coefficients!r}")
    return BANDS[coefficients]


def compact_path(exr_path):
    """The compact form's JSON beside FILE.exr: FILE/panorama.json."""
    return os.path.join(os.path.splitext(exr_path)[0], "panorama.json")


def check_writable(path):
    """ValueError naming the folder when FILE.exr and its compact folder cannot be written
    there (checked before baking, so a long bake never ends in nothing)."""
    if not path.lower().endswith(".exr"):
        raise ValueError(f"{path}: the panorama is written as an .exr file (and its compact form beside it)")
    folder = os.path.dirname(os.path.abspath(path)) or "."
    existing = folder
    while not os.path.exists(existing) and os.path.dirname(existing) != existing:
        existing = os.path.dirname(existing)
    if not os.path.isdir(existing):
        raise ValueError(f"cannot write the panorama to {folder}: {existing} is a file, not a folder")
    try:  # a real file, not os.access: root passes every access check
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as error:
        raise ValueError(f"cannot write the panorama to {folder}: {existing} is not writable "
                         f"({error.strerror or error})") from None


def prepare(scene, *, camera=None, at=None, size=(1024, 512), coefficients=16, bounces=0, depsgraph=None):
    """Reads the scene (Cycles renders the primary visibility). Raises ValueError naming what
    is wrong: no mesh, a viewpoint inside one, bad sizes or counts."""
    size, bands = checked_size(size), bands_of(coefficients)
    if isinstance(bounces, bool) or not isinstance(bounces, (int, np.integer)) or bounces < 0:
        raise ValueError(f"bounces must be 0 or more, got {bounces!r}")
    origin, rotation = panorama_hits.viewpoint(scene, camera, at)
    hits, engine_scene, surfaces = panorama_hits.hits(scene, origin, rotation, size, depsgraph)
    if not hits.mask.any():
        raise ValueError(f"the panorama at ({', '.join(f'{v:.3g}' for v in origin)}) sees no mesh: "
                         "only the World would be baked")
    lit = bounces > 0
    return Prepared(engine_scene, hits, surfaces, origin, rotation, size, bands, int(bounces),
                    lightmaps.lighting_of(scene) if lit else None, lightmaps.suns_of(scene) if lit else [],
                    lightmaps.lamps_of(scene) if lit else [])


def bounce_light(prepared, progress=None):
    """(H, W, 3) outgoing radiance of bounced light at the pixels' surfaces under the scene's
    own lighting: the lightmap baker's vertex passes (`bounces` of them), gathered once per
    pixel over its geometric hemisphere, times the pixel's albedo."""
    from hemishadow.lightmap import bounce, lamps

    lb = importlib.import_module("hemishadow.lightmap.bake")  # the module: the package exports its `bake`

    scene, h = prepared.engine_scene, prepared.hits
    receivers = lb.bounce_receivers([], prepared.surfaces)
    steps = lb.Steps(progress, sum(len(r[1]) for r in receivers) * (1 + prepared.bounces), "panorama bounce")
    lighting, suns = lb.checked_lighting(prepared.lighting), lb.checked_suns(prepared.suns)
    lamp_list = [lamps.check(lamp, i) for i, lamp in enumerate(prepared.lamps)]
    lb.vertex_bounce(scene, receivers, lighting, suns, lamp_list, prepared.bounces, None, steps)
    out = np.zeros(h.mask.shape + (3,), np.float32)
    gathered = scene.gather(h.position[h.mask], h.geometric_normal[h.mask], bands=bounce.BANDS)
    irradiance = bounce.lobe_irradiance(gathered, h.shading_normal[h.mask][:, None])[:, 0]
    out[h.mask] = h.albedo[h.mask] * irradiance
    return out


def compute(prepared, progress=None):
    """The engine's bake (no bpy): a `hemishadow.panorama.Panorama`. `progress(fraction)`
    returning False raises hemishadow.Cancelled."""
    import hemishadow.panorama as hp

    split = 0.3 if prepared.bounces else 0.0  # the share of the progress bar the bounce gets

    def part(lo, hi):
        return None if progress is None else (lambda f: progress(lo + (hi - lo) * f))

    bounce = bounce_light(prepared, part(0.0, split)) if prepared.bounces else None
    return hp.bake(prepared.engine_scene, prepared.origin, size=prepared.size, bands=prepared.bands,
                   rotation=prepared.rotation, hits=prepared.hits, bounce=bounce, progress=part(split, 1.0))


def write(panorama, path):
    """FILE.exr and FILE/panorama.json (compact form), both or neither; returns both paths."""
    check_writable(path)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    compact = compact_path(path)
    had_compact = os.path.exists(compact)
    panorama.save(compact)
    try:
        panorama.save(path)
    except BaseException:
        if not had_compact:
            shutil.rmtree(os.path.dirname(compact), ignore_errors=True)
        raise
    return path, compact


def output_path(camera_name=None, out=None):
    """`out`, or //panoramas/<viewpoint>.exr beside a saved .blend; None otherwise."""
    if out:
        return bpy.path.abspath(out)
    if bpy.data.filepath:
        return bpy.path.abspath(f"//panoramas/{lightmaps._safe(camera_name or 'panorama')}.exr")
    return None


def bake_panorama(scene, *, camera=None, at=None, size=(1024, 512), coefficients=16, bounces=0, out=None,
                  progress=None):
    """Bakes and writes a panorama; returns (Panorama, (exr, json) paths or None). The plain
    path of the modal operator and of the command line."""
    if out is not None:
        check_writable(bpy.path.abspath(out))
    prepared = prepare(scene, camera=camera, at=at, size=size, coefficients=coefficients, bounces=bounces)
    panorama = compute(prepared, progress)
    path = output_path(getattr(camera, "name", camera), out)
    return panorama, (write(panorama, path) if path else None)
