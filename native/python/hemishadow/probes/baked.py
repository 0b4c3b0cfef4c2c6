"""Bounce light from baked lightmaps: a surface whose lightmap is baked already shows the
probes the radiance it holds (emission + albedo x its `flat` map, the irradiance / pi of a
white surface) instead of bounce passes computed again at its vertices.

`Scene.gather` interpolates radiance between vertices, so the map is read at the vertices:
bilinearly at each corner's lightmap UV (texel centres as `lightmap.texels` places them, rows
top to bottom), averaged over the corners of a vertex (a vertex on a UV seam has several).
"""

import numpy as np

from ..lightmap import geometry


def vertex_light(flat, uv, triangles, vertex_count):
    """(V, 3) float32: the map `flat` (R, R', 3) read at the vertices of `triangles` (M, 3)
    through their corners' lightmap `uv` (M, 3, 2), averaged per vertex; vertices no triangle
    uses stay 0."""
    image = geometry.finite(flat, "lightmap", (-1, -1, 3))
    uv = geometry.finite(uv, "lightmap UVs", (-1, 3, 2)).reshape(-1, 2)
    tri = np.asarray(triangles, np.int64).reshape(-1)
    if len(tri) != len(uv):
        raise ValueError(f"{len(uv) // 3} triangles of lightmap UVs for {len(tri) // 3} triangles")
    values = _bilinear(image, uv)
    total = np.zeros((vertex_count, 3))
    np.add.at(total, tri, values)
    count = np.bincount(tri, minlength=vertex_count)[:, None]
    return (total / np.maximum(count, 1)).astype(np.float32)


def _bilinear(image, uv):
    h, w = image.shape[:2]
    x = uv[:, 0] * w - 0.5  # texel (r, c) has its centre at u = (c + 0.5) / w, v = 1 - (r + 0.5) / h
    y = (1.0 - uv[:, 1]) * h - 0.5
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    c0, c1 = np.clip(x0, 0, w - 1), np.clip(x0 + 1, 0, w - 1)
    r0, r1 = np.clip(y0, 0, h - 1), np.clip(y0 + 1, 0, h - 1)
    top = image[r0, c0] * (1 - fx) + image[r0, c1] * fx
    bottom = image[r1, c0] * (1 - fx) + image[r1, c1] * fx
    return top * (1 - fy) + bottom * fy


def radiance(receivers, lightmaps):
    """{mesh_id: outgoing radiance (V, 3)} of the bounce receivers (`bounce_receivers`) that
    have a lightmap in `lightmaps` ({mesh_id: irradiance / pi at its vertices (V, 3)})."""
    out = {}
    for mesh_id, pts, _, _, albedo, emission, _ in receivers:
        if not lightmaps or mesh_id not in lightmaps:
            continue
        light = geometry.finite(lightmaps[mesh_id], f"lightmap light of mesh {mesh_id}", (len(pts), 3))
        out[mesh_id] = (emission + albedo * light).astype(np.float32)
    return out
