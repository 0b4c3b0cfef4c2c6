"""Per-sample frames: the Half-Life 2 basis in the texel's tangent frame, and L1 SH helpers.

Binding (../shared/DESIGN.md): in the tangent frame (x = tangent, y = bitangent, z = shading
normal), in Valve's order b0 = (sqrt(2/3), 0, 1/sqrt(3)), b1 = (-1/sqrt(6), 1/sqrt(2),
1/sqrt(3)), b2 = (-1/sqrt(6), -1/sqrt(2), 1/sqrt(3)). Tangents come per triangle corner with
Blender's bitangent sign (MikkTSpace, mesh.calc_tangents): bitangent = sign * cross(n, t).
"""

import numpy as np

from .cells import engine_frame

HL2 = np.array([
    [np.sqrt(2.0 / 3.0), 0.0, 1.0 / np.sqrt(3.0)],
    [-1.0 / np.sqrt(6.0), 1.0 / np.sqrt(2.0), 1.0 / np.sqrt(3.0)],
    [-1.0 / np.sqrt(6.0), -1.0 / np.sqrt(2.0), 1.0 / np.sqrt(3.0)],
])

#: Y(1,-1) = -C y, Y(1,0) = C z, Y(1,1) = -C x (Condon-Shortley phase); Y(0,0) = Y00.
C1 = 0.4886025119029199
Y00 = 0.28209479177387814


def _normalize(v):
    length = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(length > 0, length, 1.0)


def uv_tangents(corners, uv, normals):
    """Fallback tangents (M, 3, 4) when the caller has no MikkTSpace ones: per triangle, the
    direction of increasing u (dP/du) and the sign of dP/dv against cross(n, t), the same
    for the three corners; not MikkTSpace (no averaging across triangles)."""
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    d1, d2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    r = np.where(np.abs(det) > 1e-20, 1.0 / np.where(det == 0, 1.0, det), 0.0)[:, None]
    dpdu = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * r
    dpdv = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * r
    n = normals.mean(axis=1)
    sign = np.where((np.cross(n, dpdu) * dpdv).sum(axis=1) < 0, -1.0, 1.0)
    tangent = np.concatenate([np.repeat(dpdu[:, None], 3, axis=1), np.repeat(sign[:, None, None], 3, axis=1)], axis=2)
    return tangent


def tangent_frames(normals, tangents):
    """Orthonormal (t, b, n) per sample from interpolated normals (S, 3) and tangents (S, 4);
    where the tangent is degenerate (parallel to n, zero), the engine's frame stands in."""
    n = _normalize(normals)
    t = tangents[:, :3] - n * (tangents[:, :3] * n).sum(axis=1, keepdims=True)
    length = np.linalg.norm(t, axis=1)
    t = _normalize(t)
    bad = ~(length > 1e-8 * np.maximum(np.linalg.norm(tangents[:, :3], axis=1), 1e-30))
    if bad.any():
        t[bad] = engine_frame(n[bad])[0]
    sign = np.where(tangents[:, 3] < 0, -1.0, 1.0)
    return t, sign[:, None] * np.cross(n, t), n


def hl2_world(t, b, n):
    """The three HL2 basis vectors in world space, (S, 3, 3), Valve's order."""
    return HL2[None, :, 0:1] * t[:, None] + HL2[None, :, 1:2] * b[:, None] + HL2[None, :, 2:3] * n[:, None]


def l1_to_world(local, t, b, n):
    """L1 SH (S, 4, C) given in each sample's frame (rows t, b, n) -> world space."""
    out = local.copy()
    m = np.stack([-local[:, 3], -local[:, 1], local[:, 2]], axis=1) / C1  # integral of f s, local
    world = t[:, :, None] * m[:, 0:1] + b[:, :, None] * m[:, 1:2] + n[:, :, None] * m[:, 2:3]
    out[:, 1], out[:, 2], out[:, 3] = -C1 * world[:, 1], C1 * world[:, 2], -C1 * world[:, 0]
    return out
