"""hemishadow: soft self-shadowing from environment lighting by hemispherical rasterization.

Kautz, Lehtinen, Aila, "Hemispherical Rasterization for Self-Shadowing of Dynamic Objects"
(EGSR 2004). Arrays in, arrays out; the engine is compiled (``hemishadow._native``) and releases
the GIL while it works. Conventions (SH basis, transfer vectors, directions) are those of the
project's design notes: real orthonormal SH with the Condon-Shortley phase, theta from +Z, phi
from +X towards +Y, index l*(l+1)+m; diffuse transfer T_i = integral of Y_i V max(0, n.s).
"""

import warnings

import numpy as np

from . import _checks, _native
from .products import matmul
from .sh import euler_to_matrix, rotate_sh, rotation_matrix, window_sh
from .scene import Scene
from .solver import TransferSolver

__all__ = [
    "AO_UNOCCLUDED",
    "Cancelled",
    "Scene",
    "TransferSolver",
    "ambient_occlusion",
    "disk_cells",
    "euler_to_matrix",
    "project_environment",
    "rasterize_local",
    "rotate_sh",
    "rotation_matrix",
    "shade",
    "sh_basis",
    "transfer",
    "visibility_mask",
    "window_sh",
]

#: T_0 of an unoccluded receiver (pi * Y_00); ambient occlusion is T_0 / AO_UNOCCLUDED.
AO_UNOCCLUDED = float(np.pi * 0.28209479177387814)

BRDFS = _checks.BRDFS

#: Raised by `transfer` and `TransferSolver.solve` when their progress callback returns False.
Cancelled = _native.Cancelled


def sh_basis(directions, bands=5):
    """Real SH basis values of unit directions (K, 3): float32 (K, bands*bands).

    Directions are normalised first; a zero direction raises ValueError.
    """
    dirs = _checks.points(directions, "directions")
    lengths = np.linalg.norm(dirs, axis=1)
    if (lengths == 0).any():
        raise ValueError(f"direction {int(np.argmin(lengths))} is zero")
    return _native.sh_basis(np.ascontiguousarray(dirs / lengths[:, None], dtype=np.float32), _checks.band_count(bands))


def transfer(vertices, triangles, normals=None, *, bands=5, brdf="diffuse", exponent=None, view=None, offset=None,
             downsample=None, table_resolution=_native.DEFAULT_TABLE_RESOLUTION, receivers=None, progress=None):
    """Per-vertex transfer vectors of a mesh: float32 (N, bands*bands).

    Every triangle is a potential blocker of every vertex (no hierarchy). Vertices that share
    a position are welded for the computation, so seams and split normals do not change the
    result; each receiver ignores its own incident triangles and sits `offset` along its
    normal (default 1e-3 x the mean edge length).

    vertices: (N, 3) positions. triangles: (M, 3) vertex indices.
    normals: (N, 3) or None for area-weighted normals of the welded mesh; copies of a welded
        vertex use the normalised mean of their normals.
    brdf: "diffuse" (T_i = integral of Y_i V max(0, n.s)) or "phong" (normalised Phong,
        (e+2)/(2 pi) max(0, r.s)^e with `exponent` e, r the view mirrored about n).
    view: for "phong", the direction towards the viewer, (3,) for all vertices or (N, 3).
    downsample: mask cells per side of an integration block (1, 2, 4 or 8); 4 is the paper's
        8x8 grey occlusion term, 2 and 1 integrate finer at a small cost (about half and a
        third of the error; see docs/algorithm.md). None: 4 for diffuse; for phong 2, or 1 above
        exponent 16.
    table_resolution: R of the 6 x R x R plane table (128 is the paper's table: 12 MiB, of which the positive half, 6 MiB, is stored).
    receivers: None for every vertex, or indices (R,) of the vertices to compute: the result is
        then (R, bands*bands), row i for vertex receivers[i] (the whole mesh still blocks).
    progress: None or a callable taking the fraction done (0..1), called on this thread between
        chunks of vertices; returning False stops the work with `Cancelled`. Ctrl-C is honoured
        between chunks either way.
    Vertices touched by no triangle and with no usable normal get zeros and a warning.
    """
    verts, tris = _checks.mesh(vertices, triangles)
    norms = None if normals is None else _checks.float_array(normals, "normals", (len(verts), 3))
    exponent = _checks.brdf_exponent(brdf, exponent)
    view_one, view_each = _checks.view_arrays(brdf, view, len(verts))
    result, missing = _native.transfer(verts, tris, norms, _checks.band_count(bands), exponent, view_one, view_each,
                                       _checks.offset(offset), int(table_resolution),
                                       None if downsample is None else int(downsample),
                                       _checks.indices(receivers, len(verts), "receivers"), _checks.progress(progress))
    if missing:
        warnings.warn(f"{missing} vertices touch no triangle of non-zero area and have no normal: their transfer is zero",
                      RuntimeWarning, stacklevel=2)
    return result


def project_environment(image_or_path, bands=5, rotation=None):
    """SH coefficients (bands*bands, 3) of an equirectangular environment's radiance.

    image_or_path: a float array (H, W, 3 or 4), top row first as in image files, or the path of
    an EXR file. Pixels map to directions as Blender's Environment Texture node maps them and
    are weighted by their solid angle.
    rotation: None, a 3x3 matrix or XYZ Euler angles in radians, meaning what the World's
    Mapping node (type Point) does: the lookup vector is rotated before the image is sampled.
    """
    if isinstance(image_or_path, (str, bytes)) or hasattr(image_or_path, "__fspath__"):
        from .environment import read_exr

        image = read_exr(image_or_path)
    else:
        image = image_or_path
    image = _checks.float_array(image, "image", (-1, -1, -1))
    # The Mapping node samples the image at R d; the radiance arriving from d is image(R d),
    # so project with the pixel directions taken back through R^T.
    matrix = _rotation_argument(rotation)
    return _native.project_equirectangular(image, _checks.band_count(bands), np.ascontiguousarray(matrix.T))


def _rotation_argument(rotation):
    if rotation is None:
        return np.eye(3, dtype=np.float32)
    array = np.asarray(rotation, dtype=np.float64)
    if array.shape == (3,):
        return euler_to_matrix(array).astype(np.float32)
    if array.shape != (3, 3) or not np.isfinite(array).all():
        raise ValueError(f"rotation must be XYZ Euler angles (3,) or a 3x3 matrix, got shape {array.shape}")
    if not np.allclose(array @ array.T, np.eye(3), atol=1e-4) or np.linalg.det(array) < 0:
        raise ValueError("rotation must be a proper rotation matrix (orthonormal, determinant +1)")
    return array.astype(np.float32)


def shade(transfer, lighting, albedo=None):
    """Irradiance (N, 3) = transfer (N, K) . lighting (K, 3); with `albedo` ((3,) or (N, 3)),
    diffuse exitant radiance albedo / pi * irradiance."""
    t = _checks.coefficient_matrix(transfer, "transfer")
    light = _checks.float_array(lighting, "lighting", (t.shape[1], 3))
    result = matmul(t, light)
    if albedo is None:
        return result
    a = np.asarray(albedo)
    a = _checks.float_array(a, "albedo", (3,) if a.ndim == 1 else (len(t), 3))
    return (result * (a / np.float32(np.pi))).astype(np.float32)


def ambient_occlusion(transfer):
    """Ambient occlusion per vertex from diffuse transfer: T_0 / (pi Y_00), 1 when unoccluded."""
    t = _checks.coefficient_matrix(transfer, "transfer")
    return (t[:, 0] / np.float32(AO_UNOCCLUDED)).astype(np.float32)


def rasterize_local(triangles, table_resolution=_native.DEFAULT_TABLE_RESOLUTION):
    """The 32x32 visibility mask (bool) of triangles (M, 3, 3) given relative to the receiver in
    its tangent frame (+Z = normal). Row r, column c is the cell at x = -1 + (c + 0.5) / 16,
    y = -1 + (r + 0.5) / 16 of the unit disk."""
    tris = _checks.float_array(triangles, "triangles", (-1, 3, 3)).reshape(-1, 9)
    return _native.rasterize_local(tris, int(table_resolution))


def visibility_mask(point, normal, vertices, triangles, table_resolution=_native.DEFAULT_TABLE_RESOLUTION):
    """The 32x32 visibility mask (bool) seen from `point` with `normal` over a mesh, no triangle
    excluded; rows and columns as in `rasterize_local`, in the frame the engine builds from the
    normal."""
    verts = _checks.points(vertices, "vertices")
    tris = _checks.triangle_indices(triangles, len(verts))
    return _native.visibility_mask(_checks.float_array(point, "point", (3,)), _checks.float_array(normal, "normal", (3,)),
                                   verts, tris, int(table_resolution))


def disk_cells():
    """The 32x32 cells (bool) that belong to the unit disk."""
    return _native.disk_cells()
