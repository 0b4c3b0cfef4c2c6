"""A baked panorama in memory: SH maps per pixel plus what relighting needs (positions for
point lights, the hit mask), saved as a float EXR or as the paper's compact 8-bit maps."""

import os

import numpy as np


class Panorama:
    """coefficients (H, W, k, 3) float32, albedo / pi included (outgoing radiance =
    sum_i c_i L_i); position (H, W, 3) world; normal (H, W, 3) shading normal; depth (H, W)
    distance from the origin (inf for background); alpha (H, W) 1 hit, 0 background;
    origin (3,), rotation (3, 3), bands; bounce (H, W, 3) or None.

    Loaded from the compact form, `quantized` holds the 8-bit maps as stored (relight reads
    them directly) and `coefficients` their dequantized values.
    """

    def __init__(self, *, coefficients, position, normal, depth, alpha, origin, rotation, bands, bounce=None,
                 quantized=None):
        self.coefficients = coefficients
        self.position = position
        self.normal = normal
        self.depth = depth
        self.alpha = alpha
        self.origin = np.asarray(origin, dtype=np.float64)
        self.rotation = np.asarray(rotation, dtype=np.float64)
        self.bands = int(bands)
        self.bounce = bounce
        self.quantized = quantized
        self._relighters = {}

    @property
    def width(self):
        return self.coefficients.shape[1]

    @property
    def height(self):
        return self.coefficients.shape[0]

    @property
    def coefficient_count(self):
        return self.coefficients.shape[2]

    @property
    def mask(self):
        return self.alpha > 0.5

    def save(self, path):
        """`*.exr`: the float EXR (HALF maps, FLOAT position/normal/depth); `*.json`: the compact
        form in that file's folder. Returns a dict of what was written (sizes, 8-bit error)."""
        ext = os.path.splitext(os.fspath(path))[1].lower()
        if ext == ".exr":
            from .exr_file import write

            return write(path, self)
        if ext == ".json":
            from .compact import write

            return write(path, self)
        raise ValueError(f"{path}: a panorama is saved as .exr or .json (the compact 8-bit form)")

    @classmethod
    def load(cls, path):
        """Reads a file written by `save` (.exr or the compact form's .json)."""
        ext = os.path.splitext(os.fspath(path))[1].lower()
        if ext == ".exr":
            from .exr_file import read

            return read(path)
        if ext == ".json":
            from .compact import read

            return read(path)
        raise ValueError(f"{path}: not a panorama file (.exr or .json)")

    def relighter(self, maps):
        """The engine's relighter over the 8-bit ("8bit") or float16 ("float16") maps, built once."""
        if maps not in self._relighters:
            from .relight import make_relighter

            self._relighters[maps] = make_relighter(self, maps)
        return self._relighters[maps]
