"""Dense products for code that runs beside the engine (the add-on's live path).

numpy hands a product above about 2.6e5 multiply-adds to OpenBLAS's threads, and each of
them then spins for about 0.1 s of CPU waiting for more work: on a 2-core machine that is a
core taken from the engine's next solve. Measured on the Blender demo (a 1,444-vertex cloth
whose transfer is turned to world space every frame): 100 ms a frame against 70 ms with
OpenBLAS held to one thread. These products run in the calling thread instead (ndarray's
matrixmultiply, in the engine's module), with the same numbers as numpy's to rounding.
"""

import numpy as np

from . import _native


def matmul(a, b):
    """a (N, K) @ b (K, M), float64 when either is, else float32."""
    a, b = np.asarray(a), np.asarray(b)
    if a.ndim != 2 or b.ndim != 2:
        raise ValueError(f"matmul takes two 2-D arrays, got shapes {a.shape} and {b.shape}")
    wide = np.float64 if np.float64 in (a.dtype, b.dtype) else np.float32
    multiply = _native.product_f64 if wide is np.float64 else _native.product_f32
    return multiply(np.ascontiguousarray(a, wide), np.ascontiguousarray(b, wide))
