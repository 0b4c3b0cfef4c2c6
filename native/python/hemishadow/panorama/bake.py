"""Baking a panorama: per pixel, the transfer of the surface it sees,
f(w) = albedo V(w) max(0, n.w) / pi projected on SH, so that the pixel's outgoing radiance
under incident light with SH L_i is sum_i c_i L_i (Wong et al.'s SH maps, computed directly
by hemispherical rasterization at the surface point instead of from many renders).
"""

import numpy as np

from .directions import panorama_size, rotation_matrix
from .hits import Hits, origin_vector, primary_hits
from .panorama import Panorama


def _checked_hits(hits, width, height):
    if not isinstance(hits, Hits):
        raise ValueError(f"hits must be a hemishadow.panorama.Hits, got {type(hits).__name__}")
    for name in ("position", "geometric_normal", "shading_normal", "albedo"):
        a = getattr(hits, name)
        if np.shape(a) != (height, width, 3):
            raise ValueError(f"hits.{name} must have shape ({height}, {width}, 3), got {np.shape(a)}")
    if np.shape(hits.mask) != (height, width) or np.shape(hits.object_id) != (height, width):
        raise ValueError(f"hits.mask and hits.object_id must have shape ({height}, {width})")
    mask = np.asarray(hits.mask, dtype=bool)
    for name in ("position", "shading_normal", "albedo"):
        if not np.isfinite(np.asarray(getattr(hits, name))[mask]).all():
            raise ValueError(f"hits.{name} has a NaN or infinite value at a hit pixel")
    return mask


def bake(scene, origin, *, size=(1024, 512), bands=4, rotation=None, hits=None, albedo=None, bounce=None,
         offset=None, progress=None):
    """A `Panorama` of `scene` (a hemishadow.Scene) seen from `origin`.

    bands: 3, 4 or 5 (9, 16, 25 coefficients). hits: primary visibility from Blender (Cycles
    passes) or None for `primary_hits`. albedo: for `primary_hits` (ignored with hits).
    bounce: optional (H, W, 3) extra radiance for one given environment, kept separately.
    offset: receivers' lift along the normal, a fraction of the scene's size (Scene.transfer).
    progress(fraction) returning False cancels with hemishadow.Cancelled.
    """
    from .. import _checks

    width, height = panorama_size(size)
    bands = _checks.band_count(bands)
    if not 1 <= bands <= 5:
        raise ValueError(f"panoramas take bands 1 to 5 (9, 16, 25 coefficients are bands 3, 4, 5), got {bands}")
    o = origin_vector(origin)
    r = rotation_matrix(rotation)
    if hits is None:
        hits = primary_hits(scene, o, size=(width, height), rotation=r, albedo=albedo)
    mask = _checked_hits(hits, width, height)
    if bounce is not None:
        bounce = _checks.float_array(bounce, "bounce", (height, width, 3))
    k = bands * bands
    coefficients = np.zeros((height, width, k, 3), np.float32)
    points = np.ascontiguousarray(np.asarray(hits.position, np.float32)[mask])
    normals = np.ascontiguousarray(np.asarray(hits.shading_normal, np.float32)[mask])
    if len(points):
        transfer = scene.transfer(points, normals, bands=bands, offset=offset, progress=progress)
        colour = np.asarray(hits.albedo, np.float32)[mask] / np.float32(np.pi)
        coefficients[mask] = transfer[:, :, None] * colour[:, None, :]
    elif progress is not None:
        progress(1.0)
    position = np.where(mask[..., None], hits.position, 0).astype(np.float32)
    depth = np.where(mask, np.linalg.norm(position - o.astype(np.float32), axis=-1), np.inf).astype(np.float32)
    normal = np.where(mask[..., None], hits.shading_normal, 0).astype(np.float32)
    return Panorama(coefficients=coefficients, position=position, normal=normal, depth=depth,
                    alpha=mask.astype(np.float32), origin=o, rotation=r, bands=bands, bounce=bounce)
