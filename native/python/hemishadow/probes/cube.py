"""Ambient cubes (../shared/DESIGN.md): six sides +X, -X, +Y, -Y, +Z, -Z, each the
irradiance / pi of a white Lambertian surface facing that axis; n-squared sampling; and the
conversions between a cube and SH of the incident radiance (the project's convention).

SH -> cube: side_j = (1/pi) sum_lm A_l L_lm Y_lm(a_j), A = pi, 2pi/3, pi/4, 0, -pi/24 for
l = 0..4 (Ramamoorthi and Hanrahan 2001): exact for band-limited light.

cube -> SH9: on the six axes the functions xy, yz, zx (coefficients 4, 5, 7) vanish, so the
six sides fix exactly the six coefficients 0, 1, 2, 3, 6, 8; `cube_to_sh` solves that 6 x 6
system and leaves 4, 5, 7 at zero. So cube_to_sh(sh_to_cube(L)) = L without 4, 5, 7, and
sh_to_cube(cube_to_sh(C)) = C exactly. In closed form (C+x = side 0, C-x = side 1, ...):
    L0 = (C+x + C-x + C+y + C-y + C+z + C-z) / (6 Y00)                = 0.59082 x sum
    L1 = (C-y - C+y) / (2 (2/3) Y1),  L2 = (C+z - C-z) / (2 (2/3) Y1),  L3 = (C-x - C+x) / (2 (2/3) Y1)
                                                        (1 / (2 (2/3) 0.488603) = 1.53499)
    L6 = 1.05689 (2 (C+z + C-z) - (C+x + C-x + C+y + C-y)),  L8 = 1.83058 (C+x + C-x - C+y - C-y)
    L4 = L5 = L7 = 0
"""

import functools

import numpy as np

from .. import sh_basis

AXES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float64)
A_BANDS = np.array([np.pi, 2 * np.pi / 3, np.pi / 4, 0.0, -np.pi / 24])
_FIXED = [0, 1, 2, 3, 6, 8]


def band_weights(k):
    bands = int(round(np.sqrt(k)))
    if bands * bands != k or not 1 <= bands <= 5:
        raise ValueError(f"SH must have 1, 4, 9, 16 or 25 coefficients, got {k}")
    return np.repeat(A_BANDS[:bands], 2 * np.arange(bands) + 1)


def lobe_matrix(directions, k):
    """(D, K): irradiance / pi for unit directions from K radiance SH coefficients."""
    bands = int(round(np.sqrt(k)))
    return sh_basis(np.asarray(directions, np.float64), bands).astype(np.float64) * band_weights(k) / np.pi


def sh_to_cube(sh):
    """Radiance SH (..., K, 3) -> cube (..., 6, 3)."""
    sh = np.asarray(sh, dtype=np.float64)
    return np.einsum("jk,...kc->...jc", lobe_matrix(AXES, sh.shape[-2]), sh)


@functools.cache
def _solve():
    """(6, 6): the SH coefficients 0, 1, 2, 3, 6, 8 from the six sides."""
    return np.linalg.inv(lobe_matrix(AXES, 9)[:, _FIXED])


def cube_to_sh(cube):
    """Cube (..., 6, 3) -> radiance SH9 (..., 9, 3) whose irradiance on the six axes is the cube."""
    cube = np.asarray(cube, dtype=np.float64)
    out = np.zeros(cube.shape[:-2] + (9, cube.shape[-1]))
    out[..., _FIXED, :] = np.einsum("kj,...jc->...kc", _solve(), cube)
    return out


def sample(cube, normals):
    """n-squared sampling: C(n) = nx^2 C[x<0 ? 1 : 0] + ny^2 C[y<0 ? 3 : 2] + nz^2 C[z<0 ? 5 : 4];
    cube (Q, 6, 3), unit normals (Q, 3) -> (Q, 3)."""
    cube = np.asarray(cube)
    n = np.asarray(normals, dtype=np.float64)
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    rows = np.arange(len(n))
    out = np.zeros((len(n), cube.shape[-1]))
    for axis in range(3):
        side = 2 * axis + (n[:, axis] < 0)
        out += n[:, axis, None] ** 2 * cube[rows, side]
    return out
