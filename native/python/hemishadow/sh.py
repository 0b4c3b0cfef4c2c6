"""SH utilities in numpy: rotation of coefficient vectors, windowing against ringing."""

import numpy as np


def rotation_matrix(axis, angle):
    """3x3 matrix rotating by `angle` radians about `axis` (right-handed)."""
    axis = np.asarray(axis, dtype=np.float64)
    norm = np.linalg.norm(axis)
    if axis.shape != (3,) or not np.isfinite(norm) or norm == 0:
        raise ValueError(f"axis must be a finite, non-zero 3-vector, got {axis!r}")
    x, y, z = axis / norm
    c, s = np.cos(angle), np.sin(angle)
    return np.array([
        [c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
        [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
        [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)],
    ])


def euler_to_matrix(angles):
    """XYZ Euler angles (radians) to a matrix as Blender composes them: Rz @ Ry @ Rx."""
    ax, ay, az = np.asarray(angles, dtype=np.float64)
    return rotation_matrix((0, 0, 1), az) @ rotation_matrix((0, 1, 0), ay) @ rotation_matrix((1, 0, 0), ax)


def fibonacci_directions(count):
    """`count` unit vectors spread evenly over the sphere (a Fibonacci lattice)."""
    k = np.arange(count) + 0.5
    z = 1 - 2 * k / count
    phi = k * np.pi * (3 - np.sqrt(5))
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def rotate_sh(coefficients, matrix):
    """Coefficients of the function rotated by `matrix`: g(d) = f(matrix^T d).

    coefficients: (K,) or (K, C) with K = bands^2. Rotation keeps each band separately, so
    the result is exact: it is fitted by least squares on directions spread over the sphere.
    """
    from . import sh_basis

    coeffs = np.asarray(coefficients, dtype=np.float64)
    k = coeffs.shape[0]
    bands = int(round(np.sqrt(k)))
    if bands * bands != k:
        raise ValueError(f"coefficients must have a square number of rows (9, 16, 25), got {k}")
    rotation = np.asarray(matrix, dtype=np.float64)
    if rotation.shape != (3, 3) or not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-5):
        raise ValueError("matrix must be a 3x3 rotation")
    dirs = fibonacci_directions(4 * k)
    basis = sh_basis(dirs, bands).astype(np.float64)
    rotated_basis = sh_basis(dirs @ rotation, bands).astype(np.float64)  # rows: Y(R^T d)
    solution, *_ = np.linalg.lstsq(basis, rotated_basis @ coeffs, rcond=None)
    return solution.astype(np.float32)


def window_sh(coefficients, kind="hanning", width=None):
    """Coefficients damped per band against ringing (Gibbs overshoot near bright sources).

    kind: "hanning" (sigma_l = (1 + cos(pi l / w)) / 2) or "lanczos" (sigma_l = sinc(l / w)),
    with w = `width`, by default the number of bands. (K,) or (K, C) in, same shape out.
    """
    coeffs = np.asarray(coefficients, dtype=np.float64)
    bands = int(round(np.sqrt(coeffs.shape[0])))
    if bands * bands != coeffs.shape[0]:
        raise ValueError("coefficients must have a square number of rows (9, 16, 25)")
    w = float(bands if width is None else width)
    if not w > 0:
        raise ValueError(f"width must be positive, got {width!r}")
    l = np.arange(bands)
    if kind == "hanning":
        sigma = np.where(l < w, (1 + np.cos(np.pi * l / w)) / 2, 0.0)
    elif kind == "lanczos":
        sigma = np.sinc(l / w)
    else:
        raise ValueError(f"kind must be 'hanning' or 'lanczos', got {kind!r}")
    per_coefficient = np.repeat(sigma, 2 * l + 1)
    shape = (-1,) + (1,) * (coeffs.ndim - 1)
    return (coeffs * per_coefficient.reshape(shape)).astype(np.float32)
