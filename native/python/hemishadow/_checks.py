"""Argument checks shared by the public API: clear ValueErrors before anything reaches Rust."""

import numpy as np


def float_array(values, name, shape):
    """`values` as a C-contiguous float32 array of `shape` (-1 = any length), finite."""
    try:
        array = np.asarray(values)
    except Exception as error:  # ragged lists and the like
        raise ValueError(f"{name} could not be read as an array: {error}") from None
    if array.dtype.kind not in "fiu" or array.dtype == np.bool_:
        raise ValueError(f"{name} must hold real numbers, got dtype {array.dtype}")
    if array.ndim != len(shape) or any(s not in (-1, a) for s, a in zip(shape, array.shape)):
        expected = "(" + ", ".join("N" if s == -1 else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {expected}, got {array.shape}")
    array = np.ascontiguousarray(array, dtype=np.float32)
    if not np.isfinite(array).all():
        bad = np.argwhere(~np.isfinite(array))[0]
        raise ValueError(f"{name} has a NaN or infinite value at index {tuple(int(i) for i in bad)}")
    return array


def points(values, name):
    return float_array(values, name, (-1, 3))


def triangle_indices(values, vertex_count):
    """Triangles as a C-contiguous uint32 (M, 3) array with every index below vertex_count."""
    array = np.asarray(values)
    if array.dtype.kind not in "iu":
        raise ValueError(f"triangles must hold integer vertex indices, got dtype {array.dtype}")
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"triangles must have shape (M, 3), got {array.shape}")
    if array.size and (array.min() < 0 or array.max() >= vertex_count):
        bad = int(array.min()) if array.min() < 0 else int(array.max())
        raise ValueError(f"triangles use vertex index {bad}, but the mesh has {vertex_count} vertices")
    return np.ascontiguousarray(array, dtype=np.uint32)


def mesh(vertices, triangles, name="vertices"):
    """Checked (vertices float32 (N, 3), triangles uint32 (M, 3)) of a non-empty mesh."""
    verts = points(vertices, name)
    tris = triangle_indices(triangles, len(verts))
    if len(verts) == 0 or len(tris) == 0:
        raise ValueError("the mesh is empty: it needs at least one vertex and one triangle")
    return verts, tris


def band_count(bands):
    if isinstance(bands, bool) or not isinstance(bands, (int, np.integer)) or not 1 <= bands <= 8:
        raise ValueError(f"bands must be an integer from 1 to 8 (3, 4, 5 give 9, 16, 25 coefficients), got {bands!r}")
    return int(bands)


def coefficient_matrix(values, name, rows=None):
    """A float32 (N, K) array whose K is a square number of SH coefficients."""
    array = float_array(values, name, (-1, -1))
    k = array.shape[1]
    if int(round(k ** 0.5)) ** 2 != k:
        raise ValueError(f"{name} must have a square number of SH coefficients per row (9, 16, 25), got {k}")
    if rows is not None and array.shape[0] != rows:
        raise ValueError(f"{name} must have {rows} rows, got {array.shape[0]}")
    return array


BRDFS = ("diffuse", "phong")


def brdf_exponent(brdf, exponent):
    """The Phong exponent as a float, or None for the diffuse BRDF."""
    if brdf not in BRDFS:
        raise ValueError(f"brdf must be one of {BRDFS}, got {brdf!r}")
    if brdf == "diffuse":
        if exponent is not None:
            raise ValueError("exponent applies to the phong BRDF only")
        return None
    if exponent is None or not np.isfinite(exponent) or exponent < 0:
        raise ValueError(f"the phong BRDF needs a finite, non-negative exponent, got {exponent!r}")
    return float(exponent)


def view_arrays(brdf, view, vertex_count):
    """(one view (3,), per-vertex views (N, 3)): at most one is set, both None for diffuse."""
    if brdf == "diffuse":
        return None, None
    if view is None:
        raise ValueError("the phong BRDF needs a view direction: (3,) or one per vertex (N, 3)")
    array = np.asarray(view)
    if array.ndim == 1:
        return float_array(array, "view", (3,)), None
    return None, float_array(array, "view", (vertex_count, 3))


def offset(value):
    """The receivers' offset as a float, or None for the engine's default."""
    if value is None:
        return None
    if not (np.isfinite(value) and value >= 0):
        raise ValueError(f"offset must be a finite, non-negative distance, got {value!r}")
    return float(value)


def progress(callback):
    """A progress callback: None or a callable."""
    if callback is not None and not callable(callback):
        raise ValueError(f"progress must be a callable or None, got {type(callback).__name__}")
    return callback


def indices(values, count, what):
    """None, or a 1-D array of indices below `count` as contiguous uint32."""
    if values is None:
        return None
    array = np.asarray(values)
    if array.ndim != 1 or not (np.issubdtype(array.dtype, np.integer) or array.size == 0):
        raise ValueError(f"{what} must be a 1-D array of vertex indices, got shape {array.shape} of {array.dtype}")
    if array.size and (array.min() < 0 or array.max() >= count):
        raise ValueError(f"{what} must be vertex indices in 0..{count - 1}, got {array.min()}..{array.max()}")
    return np.ascontiguousarray(array, dtype=np.uint32)
