"""Bounce light through the scene's ordered mode (`Scene.gather`).

Each mesh's vertices are receivers too: their outgoing radiance, emission + albedo x
(direct + the previous pass's gathered light), is what `set_radiance` shows to the next pass.
`bounces` passes leave the radiance that texels gather for their indirect light; with
bounces = 0 only emission is gathered. Gathered light is SH bands 0-2 (world) over the
receiver's geometric hemisphere; irradiance for a lobe direction v is sum A_l G_lm Y_lm(v)
(A = pi, 2pi/3, pi/4), clamped at 0.
"""

import numpy as np

from .. import sh_basis

_A = np.repeat([np.pi, 2 * np.pi / 3, np.pi / 4], [1, 3, 5]).astype(np.float32)
BANDS = 3


def lobe_irradiance(gathered, lobes):
    """Irradiance / pi (P, L, 3) for lobes (P, L, 3) from gathered SH (P, 9, 3)."""
    p, l = lobes.shape[:2]
    y = sh_basis(lobes.reshape(-1, 3), BANDS).reshape(p, l, -1) * _A
    return np.maximum(np.einsum("plk,pkc->plc", y, gathered) / np.float32(np.pi), 0.0).astype(np.float32)


def vertex_radiance(scene, receivers, direct, bounces, offset=None, progress=None, steps=None):
    """Sets each surface's vertex radiance after `bounces` passes and returns it.
    steps: a `bake.Steps` given a step per vertex and pass, in chunks short enough for a
    cancel to get through (else `progress` goes to the engine's gather).

    receivers: per surface (mesh_id, points (V, 3), normals (V, 3), usable (V,) bool, albedo
    (V, 3), emission (V, 3)); direct: per surface, the direct irradiance / pi (V, 3) at its
    vertices.
    """
    radiance = [emission.astype(np.float32) for (_, _, _, _, _, emission) in receivers]
    for _ in range(int(bounces)):
        _show(scene, receivers, radiance)
        shown = any(r.any() for r in radiance)
        new = []
        for (mesh_id, points, normals, usable, albedo, emission), d in zip(receivers, direct):
            light = d.copy()
            if shown and usable.any():
                light[usable] += _gathered(scene, points[usable], normals[usable], offset, progress, steps)
            new.append((emission + albedo * light).astype(np.float32))
        radiance = new
    _show(scene, receivers, radiance)
    return radiance


def _gathered(scene, points, normals, offset, progress, steps):
    """Irradiance / pi (V, 3) gathered at vertices along their normals."""
    if steps is None:
        g = scene.gather(points, normals, bands=BANDS, offset=offset, progress=progress)
        return lobe_irradiance(g, normals[:, None])[:, 0]
    out = np.empty((len(points), 3), np.float32)
    for s in steps.chunks(len(points), least=1024):
        g = scene.gather(points[s], normals[s], bands=BANDS, offset=offset)
        out[s] = lobe_irradiance(g, normals[s][:, None])[:, 0]
    return out


def _show(scene, receivers, radiance):
    for (mesh_id, *_), rgb in zip(receivers, radiance):
        scene.set_radiance(mesh_id, rgb)
