"""Primary visibility of a panorama: per pixel, the first surface seen through its centre.

The engine casts one ray per pixel through a BVH of the scene's world triangles (closest
hit, f64 triangle tests): exact at pixel centres, with no resampling (a rasterized cube map
would resample) and fast (about a second for 1024 x 512). Blender's side may pass hits from
Cycles' passes to `bake` instead.
"""

from dataclasses import dataclass

import numpy as np

from .. import _native
from .directions import panorama_size, rotation_matrix

DEFAULT_ALBEDO = 0.8  # Blender's default material grey


@dataclass
class Hits:
    """Arrays (H, W, 3) float32 except object_id (H, W) int32 (-1 background) and mask (H, W)
    bool (True where a surface was hit). geometric_normal is the triangle's modelled front;
    shading_normal faces the viewpoint (the side the pixel shows)."""
    position: np.ndarray
    geometric_normal: np.ndarray
    shading_normal: np.ndarray
    albedo: np.ndarray
    object_id: np.ndarray
    mask: np.ndarray

    @property
    def size(self):
        return self.mask.shape[1], self.mask.shape[0]


def origin_vector(origin):
    o = np.asarray(origin, dtype=np.float64)
    if o.shape != (3,) or not np.isfinite(o).all():
        raise ValueError(f"the viewpoint must be a finite (x, y, z), got {origin!r}")
    return o


def albedo_table(albedo, meshes):
    """(meshes, 3) float32 from None (0.8 grey), one RGB or one RGB per mesh id."""
    if albedo is None:
        return np.full((max(meshes, 1), 3), DEFAULT_ALBEDO, np.float32)
    a = np.asarray(albedo, dtype=np.float32)
    if a.shape == (3,):
        return np.tile(a, (max(meshes, 1), 1))
    if a.shape != (meshes, 3) or not np.isfinite(a).all():
        raise ValueError(f"albedo must be one RGB or one RGB per mesh ({meshes}, 3), got shape {a.shape}")
    return a


def primary_hits(scene, origin, *, size=(1024, 512), rotation=None, albedo=None):
    """The engine's primary visibility from `origin` through a `hemishadow.Scene`.

    size: (width, height). rotation: the viewpoint's frame (None: the identity, `--at`).
    albedo: None (0.8 grey), one RGB, or an RGB per mesh id (meshes, 3).
    Raises ValueError for an empty scene or a viewpoint inside geometry (it sees the back
    faces of most surfaces around it, the test `Scene.valid` uses for receivers).
    """
    width, height = panorama_size(size)
    o = origin_vector(origin)
    r = rotation_matrix(rotation)
    _t, position, normal, instance, mesh, back = _native.panorama_hits(
        scene._native, np.ascontiguousarray(o), np.ascontiguousarray(r), width, height)
    mask = instance >= 0
    seen = int(mask.sum())
    if seen and back.sum() > 0.5 * seen:
        raise ValueError(
            f"the viewpoint ({o[0]:g}, {o[1]:g}, {o[2]:g}) is inside geometry: {100 * back.sum() / seen:.0f} % of the "
            "surfaces it sees show their back faces; move it into open space (a room must face inwards: flip its "
            "normals or give its walls a thickness)")
    # Show the side facing the viewpoint: flip normals seen from behind.
    shading = np.where(back[..., None], -normal, normal).astype(np.float32)
    table = albedo_table(albedo, len(scene._meshes))
    colours = np.zeros((height, width, 3), np.float32)
    colours[mask] = table[mesh[mask]]
    return Hits(position=position, geometric_normal=normal, shading_normal=shading, albedo=colours,
                object_id=instance.astype(np.int32), mask=mask)
