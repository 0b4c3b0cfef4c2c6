"""A per-mesh transfer solver for deforming meshes: built once from the topology, solved
every frame with new positions."""

import numpy as np

from . import _checks, _native
from .scene import Scene, _matrix

# Largest vertex displacement from a sampled pose (fraction of the rest pose's half size) up
# to which a frame uses the potentially visible sets; measured in docs/algorithm.md.
DEFAULT_PVS_TOLERANCE = 0.03


class TransferSolver:
    """Transfer vectors of one mesh topology over many frames (poses, simulation steps).

    Built once from the triangles and a rest pose, it keeps what does not change while the
    mesh deforms: the weld map, the two-level mesh hierarchy of the paper (the receiver's
    `ring`-ring of fine triangles, a coarse mesh of about `coarse_triangles` triangles made of
    a subset of the fine vertices by meshoptimizer for the rest), the clusters and the offset.
    Each `solve` refreshes cluster bounds, culls clusters below a receiver's horizon and
    reuses the last result of receivers whose blockers did not move. Lighting never enters:
    shade the result with `hemishadow.shade`.

    rest_vertices: (N, 3); triangles: (M, 3). bands, brdf, exponent, offset, downsample and
    table_resolution are those of `hemishadow.transfer` (the offset defaults to 1e-3 x the
    rest pose's mean edge length and then stays fixed).
    near_scale: clusters (a coarse triangle and the fine triangles it owns) whose centre lies
    within near_scale x their radius of a receiver are seen at full resolution as well,
    whatever the surface distance (a coarse triangle that close cuts through the real
    surface and would shadow falsely); 0 uses the ring only. The default, 2.5, keeps every
    vertex of the shared meshes and characters as given within 0.1 AO of the exact path
    (a turned copy of the teapot reaches 0.101 on one vertex: docs/solver_trust.md).
    far_lod: groups of coarse triangles whose bounds' radius is below far_lod x their
    distance from a receiver are drawn through a coarser proxy (a third level, so that the
    cost per receiver does not grow with the mesh) when that proxy's error also subtends
    less than about a cell of the mask; 0 draws every coarse triangle, as the paper's two
    levels do.
    Positions are moved and scaled into a unit box internally (by the rest pose's centre and
    size), so results do not depend on the mesh's size or place.
    hierarchy=False makes every fine triangle a blocker (the exact path of `transfer`, with
    culling and reuse); cull and reuse switch those optimisations.
    """

    def __init__(self, rest_vertices, triangles, *, bands=5, brdf="diffuse", exponent=None, offset=None,
                 downsample=None, table_resolution=_native.DEFAULT_TABLE_RESOLUTION, hierarchy=True,
                 coarse_triangles=None, ring=2, near_scale=2.5, far_lod=_native.DEFAULT_FAR_LOD, cull=True,
                 reuse=True):
        rest, tris = _checks.mesh(rest_vertices, triangles, "rest_vertices")
        exponent = _checks.brdf_exponent(brdf, exponent)
        if not (np.isfinite(near_scale) and near_scale >= 0):
            raise ValueError(f"near_scale must be a finite, non-negative number, got {near_scale!r}")
        if not (np.isfinite(far_lod) and 0 <= far_lod < 1):
            raise ValueError(f"far_lod must be a number in [0, 1), got {far_lod!r}")
        if coarse_triangles is not None and (int(coarse_triangles) != coarse_triangles or coarse_triangles < 1):
            raise ValueError(f"coarse_triangles must be a positive integer, got {coarse_triangles!r}")
        self.bands = _checks.band_count(bands)
        self.brdf = brdf
        self._solver = _native.Solver(rest, tris, self.bands, exponent, _checks.offset(offset),
                                      int(table_resolution), None if downsample is None else int(downsample),
                                      bool(hierarchy), None if coarse_triangles is None else int(coarse_triangles),
                                      int(ring), bool(cull), bool(reuse), float(near_scale),
                                      float(far_lod))

    @property
    def vertex_count(self):
        return self._solver.vertex_count

    @property
    def coarse_triangles(self):
        """Triangles of the coarse mesh (clusters)."""
        return self._solver.coarse_triangles

    @property
    def memory_bytes(self):
        """Bytes kept between frames (topology, hierarchy, last frame), the shared 6 MiB
        plane table excepted."""
        return self._solver.memory_bytes

    @property
    def stats(self):
        """Last solve: {'blockers_per_vertex', 'computed', 'reused', 'pvs'} ('pvs': whether the
        frame was close enough to the sampled poses to use the potentially visible sets)."""
        blockers, computed, reused, used_pvs = self._solver.stats()
        return {"blockers_per_vertex": blockers, "computed": computed, "reused": reused, "pvs": used_pvs}

    def build_pvs(self, poses, normals=None, *, tolerance=DEFAULT_PVS_TOLERANCE, progress=None):
        """Potentially visible sets (the paper's section 3.2), opt-in: it needs poses of the
        animation. poses: (F, N, 3) vertex positions of a few sampled frames (the bake range,
        or poses you pick). For each receiver the solver keeps the clusters, and the distant
        parts of the mesh it draws through proxies, that contribute to its mask in some
        sampled pose (nearest first, those that add cells the nearer ones have not covered);
        later solves rasterize only those while the frame's pose stays
        within `tolerance` of a sampled one: the largest vertex displacement, as a fraction of
        the rest pose's half size (its largest half-extent). Farther poses fall back to the
        full hierarchy (`stats['pvs']` says which was used). normals: (F, N, 3), the normals
        `solve` will be given for those poses (None: the mesh's own, as `solve` without
        normals). Replaces earlier sets. A sampled pose gives exactly the result it gives
        without the sets."""
        poses = np.ascontiguousarray(poses, dtype=np.float32)
        if poses.ndim != 3 or poses.shape[1:] != (self.vertex_count, 3):
            raise ValueError(f"poses must have shape (F, {self.vertex_count}, 3), got {poses.shape}")
        if len(poses) == 0:
            raise ValueError("build_pvs needs at least one pose")
        if not np.isfinite(poses).all():
            raise ValueError("poses must be finite")
        if not (np.isfinite(tolerance) and tolerance >= 0):
            raise ValueError(f"tolerance must be a finite, non-negative number, got {tolerance!r}")
        if normals is not None:
            normals = np.ascontiguousarray(normals, dtype=np.float32)
            if normals.shape != poses.shape:
                raise ValueError(f"normals must have the shape of poses {poses.shape}, got {normals.shape}")
        self._solver.build_pvs(poses, normals, float(tolerance), _checks.progress(progress))

    def clear_pvs(self):
        """Drops the potentially visible sets: every solve uses the full hierarchy again."""
        self._solver.clear_pvs()

    @property
    def pvs(self):
        """{'poses', 'clusters_per_vertex', 'tolerance'} of the current sets, or None."""
        info = self._solver.pvs_info()
        return None if info is None else dict(zip(("poses", "clusters_per_vertex", "tolerance"), info))

    def solve(self, vertices, normals=None, view=None, *, progress=None, casters=None, to_world=None, exclude=()):
        """Transfer (N, bands^2) float32 for this frame's positions (N, 3); normals, view and
        progress as in `hemishadow.transfer`. The GIL is released while receivers are computed,
        so a solve may run in a worker thread; use one solver from one thread at a time. A
        cancelled solve leaves the solver as it was.

        Shadows from other objects: `casters`, a `hemishadow.Scene`, whose blockers are
        rasterized into each receiver's mask after the mesh's own; `to_world` (4, 4), a rigid
        matrix (orthogonal 3x3 part, a mirror allowed) placing `vertices` in the scene's world
        (None: they are in it already); `exclude`, ids of the scene's instances left out (this
        mesh's own, which the solver shadows itself). Solvers of several objects may read one
        scene at the same time; editing it while a solve reads it raises RuntimeError. The
        last result is reused only while the scene, `to_world` and `exclude` stay the same."""
        verts = _checks.points(vertices, "vertices")
        if len(verts) != self.vertex_count:
            raise ValueError(f"the solver was built for {self.vertex_count} vertices, got {len(verts)}: "
                             "the topology changed, build a new solver")
        norms = None if normals is None else _checks.float_array(normals, "normals", (len(verts), 3))
        view_one, view_each = _checks.view_arrays(self.brdf, view, len(verts))
        scene, place, skip = _casters(casters, to_world, exclude)
        return self._solver.solve(verts, norms, view_one, view_each, _checks.progress(progress), scene, place, skip)


def _casters(casters, to_world, exclude):
    """(native scene or None, float64 (4, 4) or None, uint32 ids or None) for `solve`."""
    if casters is None:
        if to_world is not None or len(exclude):
            raise ValueError("to_world and exclude need casters (a hemishadow.Scene)")
        return None, None, None
    if not isinstance(casters, Scene):
        raise TypeError(f"casters must be a hemishadow.Scene, got {type(casters).__name__}")
    place = None if to_world is None else _matrix(to_world, "to_world")
    ids = np.asarray(exclude if exclude is not None else (), dtype=np.int64).reshape(-1)
    if (ids < 0).any():
        raise ValueError(f"exclude holds instance ids, got {int(ids.min())}")
    return casters._native, place, np.ascontiguousarray(ids, dtype=np.uint32)
