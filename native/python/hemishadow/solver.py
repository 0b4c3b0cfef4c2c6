"""A per-mesh transfer solver for deforming meshes: built once from the topology, solved
every frame with new positions."""

import numpy as np

from . import _checks


class TransferSolver:
    """Transfer vectors of one mesh topology over many frames (poses, simulation steps).

    Build it once per mesh (topology and a rest pose); call `solve` every frame with the
    deformed positions. Lighting never enters: shade the result with `hemishadow.shade`.

    triangles: (M, 3) vertex indices; rest_vertices: (N, 3) positions of a rest pose.
    The keyword arguments are those of `hemishadow.transfer`.
    """

    def __init__(self, rest_vertices, triangles, *, bands=5, brdf="diffuse", exponent=None, offset=None,
                 downsample=None):
        rest = _checks.points(rest_vertices, "rest_vertices")
        self.triangles = _checks.triangle_indices(triangles, len(rest))
        if len(rest) == 0 or len(self.triangles) == 0:
            raise ValueError("the mesh is empty: it needs at least one vertex and one triangle")
        self.vertex_count = len(rest)
        self.options = dict(bands=_checks.band_count(bands), brdf=brdf, exponent=exponent, offset=offset,
                            downsample=downsample)

    @property
    def coefficients(self):
        return self.options["bands"] ** 2

    def solve(self, vertices, normals=None, view=None):
        """Transfer (N, bands^2) float32 for the positions of this frame."""
        from . import transfer

        verts = _checks.points(vertices, "vertices")
        if len(verts) != self.vertex_count:
            raise ValueError(f"the solver was built for {self.vertex_count} vertices, got {len(verts)}: "
                             "the topology changed, build a new solver")
        return transfer(verts, self.triangles, normals, view=view, **self.options)
