"""Scene visibility: many meshes and their instances shadow each other and any receiver point.

Receivers are arbitrary points with a normal (lightmap texels, probes, panorama pixels), not
mesh vertices; see `Scene`.
"""

import math
from typing import NamedTuple

import numpy as np

from . import _checks, _native


def _matrix(matrix, name="matrix"):
    """A finite 4x4 affine world matrix (row-major, column vectors) as float64."""
    array = np.asarray(matrix)
    if array.dtype.kind not in "fiu" or array.dtype == np.bool_:
        raise ValueError(f"{name} must hold real numbers, got dtype {array.dtype}")
    if array.shape != (4, 4):
        raise ValueError(f"{name} must be a 4x4 matrix, got shape {array.shape}")
    array = np.ascontiguousarray(array, dtype=np.float64)
    if not np.isfinite(array).all():
        raise ValueError(f"{name} has a NaN or infinite value")
    if not np.allclose(array[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError(f"{name} must be affine: its last row must be (0, 0, 0, 1), got {array[3].tolist()}")
    if abs(np.linalg.det(array[:3, :3])) <= 1e-12 * max(np.abs(array[:3, :3]).max(), 1e-300) ** 3:
        raise ValueError(f"{name} is singular: its 3x3 part has a zero determinant")
    return array


def _normals(values, count):
    normals = _checks.float_array(values, "normals", (count, 3))
    lengths = np.linalg.norm(normals, axis=1)
    if count and (lengths == 0).any():
        raise ValueError(f"normal {int(np.argmin(lengths))} is zero")
    return normals


class Scene:
    """Visibility of a whole scene from arbitrary receivers (issue 10).

    Meshes are added once (`add_mesh`) and placed by instances (`add_instance`) with a 4x4
    world matrix: row-major, column vectors, p_world = M @ [p, 1]; a negative determinant
    mirrors the mesh and turns its facing over. Instances share their mesh's geometry and
    hierarchy; a mesh with no instance blocks nothing. Meshes that move per frame take new
    positions with `set_vertices` (their hierarchy is refitted, not rebuilt, and the rest of
    the scene is untouched); moved instances take `set_matrix`.

    Each mesh gets a cluster hierarchy: clusters of nearby triangles with bounds and a
    simplified proxy per node; a receiver culls what lies below its horizon, draws what
    subtends less than `lod` (radius / distance) through its proxy and the rest at full
    resolution (docs/scene_hierarchy.md). lod=0 draws every triangle.

    Receivers: points (P, 3) with normals (P, 3) (normalised here), lifted along the normal by
    `offset` x the scene's size (its bounding-box diagonal; default 1e-4), never an absolute
    distance; no triangle is left out, so the offset is what keeps the surface a receiver
    lies on below its horizon.
    """

    def __init__(self, *, lod=None):
        self._native = _native.Scene()
        self._meshes = []  # vertex count per mesh
        self._instances = []  # mesh id per instance
        if lod is not None:
            self.lod = lod

    @property
    def lod(self):
        """Radius / distance below which a cluster (or group) is drawn through its proxy."""
        return self._native.lod

    @lod.setter
    def lod(self, value):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
                or not np.isfinite(value) or not 0 <= value <= 1:
            raise ValueError(f"lod must be a number from 0 to 1, got {value!r}")
        self._native.set_lod(float(value))

    @property
    def size(self):
        """The diagonal of the scene's world bounding box."""
        return self._native.size

    @property
    def table_resolution(self):
        """The plane table resolution of scene queries: 256, finer than the meshes' 128, because
        scene receivers see many small distant triangles whose edge planes it rounds."""
        return self._native.table_resolution

    @property
    def triangle_count(self):
        """Triangles in the scene, each instance counted."""
        return self._native.triangle_count

    @property
    def blockers_per_receiver(self):
        """Triangles rasterized per receiver in the last `transfer` (after culling and proxies)."""
        return self._native.blockers_per_receiver

    def add_mesh(self, vertices, triangles):
        """Adds a mesh (V, 3) / (M, 3) and returns its id; place it with `add_instance`."""
        verts, tris = _checks.mesh(vertices, triangles)
        mesh_id = self._native.add_mesh(verts, tris)
        self._meshes.append(len(verts))
        return mesh_id

    def add_instance(self, mesh_id, matrix=None):
        """Places mesh `mesh_id` with a 4x4 world matrix (identity when None); returns the
        instance's id."""
        mesh_id = self._mesh_id(mesh_id)
        instance_id = self._native.add_instance(mesh_id, _matrix(np.eye(4) if matrix is None else matrix))
        self._instances.append(mesh_id)
        return instance_id

    def set_vertices(self, mesh_id, vertices):
        """New positions (V, 3) for a mesh that moves; same vertex count and triangles."""
        mesh_id = self._mesh_id(mesh_id)
        self._native.set_vertices(mesh_id, _checks.float_array(vertices, "vertices", (self._meshes[mesh_id], 3)))

    def set_matrix(self, instance_id, matrix):
        """A new world matrix for an instance."""
        self._native.set_matrix(self._instance_id(instance_id), _matrix(matrix))

    def set_radiance(self, mesh_id, rgb, *, instance_id=None):
        """Outgoing radiance per vertex (V, 3) of a mesh, seen by `gather` (black until set).
        Every instance of the mesh shows it, except those given their own: with `instance_id`
        (an instance of this mesh), only that instance shows `rgb`, instead of the mesh's."""
        mesh_id = self._mesh_id(mesh_id)
        rgb = _checks.float_array(rgb, "rgb", (self._meshes[mesh_id], 3))
        if instance_id is None:
            self._native.set_radiance(mesh_id, rgb)
            return
        instance_id = self._instance_id(instance_id)
        if self._instances[instance_id] != mesh_id:
            raise ValueError(f"instance {instance_id} places mesh {self._instances[instance_id]}, not mesh {mesh_id}")
        self._native.set_instance_radiance(instance_id, rgb)

    def prepare(self):
        """Builds the hierarchy now (otherwise the first query does)."""
        self._native.prepare()

    def transfer(self, points, normals, *, bands=5, brdf="diffuse", exponent=None, view=None, offset=None,
                 downsample=None, table_resolution=None, progress=None):
        """Transfer vectors float32 (P, bands*bands) of receivers, with the definition and SH
        convention of `hemishadow.transfer` (diffuse: T_i = integral of Y_i V max(0, n.s)).

        view: for brdf="phong", the direction towards the viewer, (3,) or (P, 3).
        offset: fraction of the scene's size (default 1e-4). progress: as in `hemishadow.transfer`.
        table_resolution: the plane table's (default: the scene's, 256; see `table_resolution`).
        """
        pts, norms = self._receivers(points, normals)
        exponent = _checks.brdf_exponent(brdf, exponent)
        view_one, view_each = _checks.view_arrays(brdf, view, len(pts))
        return self._native.transfer(pts, norms, _checks.band_count(bands), exponent, view_one, view_each,
                                     _checks.offset(offset),
                                     self.table_resolution if table_resolution is None else int(table_resolution),
                                     None if downsample is None else int(downsample), _checks.progress(progress))

    def irradiance(self, points, normals, lighting, *, offset=None, progress=None):
        """Irradiance float32 (P, 3) under distant lighting given as radiance SH (K, 3) in the
        binding convention (K = bands^2, as `hemishadow.shade` takes it): transfer . lighting,
        the integral of L(s) V(s) max(0, n.s) over the hemisphere."""
        light = _checks.float_array(lighting, "lighting", (-1, 3))
        bands = math.isqrt(len(light))
        if bands * bands != len(light) or not 1 <= bands <= 8:
            raise ValueError(f"lighting must hold bands^2 rows of SH coefficients (1 to 8 bands), got {len(light)} rows")
        return (self.transfer(points, normals, bands=bands, offset=offset, progress=progress) @ light).astype(np.float32)

    def ambient_occlusion(self, points, normals, *, offset=None):
        """Ambient occlusion (P,) float32: T_0 / 0.886227, 1 when nothing is in the way."""
        t = self.transfer(points, normals, bands=1, offset=offset)
        return (t[:, 0] / np.float32(np.pi * 0.28209479177387814)).astype(np.float32)

    def valid(self, points, normals, *, offset=None):
        """bool (P,): False for receivers inside solid geometry, whose nearest blockers show
        their back faces over more than half of the hemisphere (a mirrored instance's faces
        count with their facing turned over). Open concave corners stay valid."""
        pts, norms = self._receivers(points, normals)
        return self._native.valid(pts, norms, _checks.offset(offset))

    def visibility(self, points, normals, *, offset=None):
        """Raw visibility masks (P, 16) uint64: bit r*32+c of the 1024 (word = bit // 64) is set
        when cell (r, c) of the 32x32 disk is blocked, in the tangent frame the engine builds
        from each normal (as `hemishadow.visibility_mask`)."""
        pts, norms = self._receivers(points, normals)
        return self._native.visibility(pts, norms, _checks.offset(offset))

    def occluded(self, points, targets, *, offset=None):
        """bool (P,): True where any triangle crosses the segment from points[i] to
        targets[i] (lamps at a finite distance); exact tests on every triangle, never the
        hierarchy's proxies. `offset` (a fraction of the scene's size, as for receivers) is
        left out at both ends: the surface a point lies on and the lamp's own surface."""
        pts = _checks.points(points, "points")
        tgts = _checks.points(targets, "targets")
        if len(tgts) != len(pts):
            raise ValueError(f"targets has {len(tgts)} rows but points has {len(pts)}")
        return self._native.occluded(pts, tgts, _checks.offset(offset))

    def beams_clear(self, points, normals, polygons, *, offset=None):
        """bool (P,): True where no triangle lies between points[i] and any point of a convex
        polygon above its tangent plane (normal normals[i]): polygons (K, 3), corners in order,
        shared by all points, or (P, K, 3), 3 <= K <= 8. Conservative: False may still be
        clear, True never hides a blocker of a segment to the polygon (lamps: `occluded` is
        needed only where this is False). `offset` is left out at the polygon's end."""
        pts, norms = self._receivers(points, normals)
        poly = np.asarray(polygons, dtype=np.float32)
        if poly.ndim not in (2, 3) or poly.shape[-1] != 3 or (poly.ndim == 3 and len(poly) != len(pts)):
            raise ValueError(f"polygons must have shape (K, 3) or ({len(pts)}, K, 3), got {poly.shape}")
        corners = poly.shape[-2]
        flat = _checks.points(poly.reshape(-1, 3), "polygons")
        return self._native.beams_clear(pts, norms, flat, corners, _checks.offset(offset))

    def visibility_valid(self, points, normals, *, offset=None):
        """(`visibility`, `valid`), the same values, from one walk per receiver with the
        blockers split by facing (the ordered walk only where more than half of the disk
        shows back faces): cheaper than both calls where most receivers need the validity."""
        pts, norms = self._receivers(points, normals)
        return self._native.visibility_valid(pts, norms, _checks.offset(offset))

    def gather(self, points, normals=None, *, bands=3, offset=None, progress=None):
        """Ordered mode: SH projection float32 (P, bands*bands, 3) of the radiance arriving
        from the nearest blocker in each direction (`set_radiance`, interpolated
        barycentrically at the cell's direction), integral of L(s) Y_i(s) ds over the
        receiver's hemisphere, or over the whole sphere when normals is None (probes).
        Directions where nothing is seen add nothing."""
        pts = _checks.points(points, "points")
        norms = None if normals is None else _normals(normals, len(pts))
        return self._native.gather(pts, norms, _checks.band_count(bands), _checks.offset(offset),
                                   _checks.progress(progress))

    def gather_views(self, points, normals=None, *, bands=3, offset=None, progress=None):
        """`gather`, with what the same walks say of each hemisphere walked (the normal's, or
        +Z then -Z without normals, H = 1 or 2): a `GatherViews` of the SH (P, bands^2, 3),
        masks (H, P, 16) uint64 as `visibility` gives them, back (H, P) float32: the fraction
        of the disk's cells whose nearest blocker shows its back, which `valid` allows up to
        one half, and distance (H, P) float32: the harmonic mean distance to what the cells
        see, cosine-weighted, over the cells that see something (irradiance caching's R;
        inf where nothing is seen). Probes take their masks and validity from
        their gather's walks; lightmaps interpolate bounce light where the distance is large."""
        pts = _checks.points(points, "points")
        norms = None if normals is None else _normals(normals, len(pts))
        sh, masks, back, distance = self._native.gather_views(pts, norms, _checks.band_count(bands),
                                                              _checks.offset(offset), _checks.progress(progress))
        return GatherViews(sh, np.ascontiguousarray(masks.transpose(1, 0, 2)), np.ascontiguousarray(back.T),
                           np.ascontiguousarray(distance.T))

    def bounce_weights(self, points, normals, *, offset=None, progress=None):
        """Records, per receiver, the weight of every vertex it sees in `gather`'s ordered mode,
        so that bounce passes, which change only the radiance, need no walk through the scene:
        `BounceWeights.irradiance()` then equals `gather(points, normals, bands=3)` evaluated
        along each normal (irradiance / pi, clamped at 0; `lightmap.bounce.lobe_irradiance`)
        under whatever radiance the scene shows at that time; `BounceWeights.masks` and
        `.valid` are the receivers' `visibility` masks and validity from the same walk. Once
        the scene's geometry or instances change, `irradiance()` raises ValueError (what the
        receivers see may have changed)."""
        pts, norms = self._receivers(points, normals)
        native = self._native.bounce_weights(pts, norms, _checks.offset(offset), _checks.progress(progress))
        return BounceWeights(self, native)

    def _receivers(self, points, normals):
        pts = _checks.points(points, "points")
        return pts, _normals(normals, len(pts))

    def _instance_id(self, instance_id):
        count = len(self._instances)
        if isinstance(instance_id, bool) or not isinstance(instance_id, (int, np.integer)) or not 0 <= instance_id < count:
            raise ValueError(f"instance id must be an integer in 0..{count - 1}, got {instance_id!r}")
        return int(instance_id)

    def _mesh_id(self, mesh_id):
        if isinstance(mesh_id, bool) or not isinstance(mesh_id, (int, np.integer)) or not 0 <= mesh_id < len(self._meshes):
            raise ValueError(f"mesh id must be an integer in 0..{len(self._meshes) - 1}, got {mesh_id!r}")
        return int(mesh_id)


class GatherViews(NamedTuple):
    """`Scene.gather_views`' results."""
    sh: np.ndarray
    masks: np.ndarray
    back: np.ndarray
    distance: np.ndarray


class BounceWeights:
    """Receivers' recorded gather weights (`Scene.bounce_weights`)."""

    def __init__(self, scene, native):
        self._scene = scene
        self._native = native

    def __len__(self):
        return len(self._native)

    @property
    def entries(self):
        """(vertex, weight) pairs stored over all receivers (8 bytes each)."""
        return self._native.entries

    @property
    def masks(self):
        """The receivers' raw visibility masks (P, 16) uint64 from the same walk, as
        `Scene.visibility` gives them."""
        return self._native.masks

    @property
    def valid(self):
        """(P,) bool: whether each receiver is outside solid geometry, from the same walk, as
        `Scene.valid` decides it."""
        return self._native.valid

    def irradiance(self):
        """Irradiance / pi float32 (P, 3) along each receiver's normal, gathered from the
        radiance the scene shows now, clamped at 0."""
        return np.maximum(self._scene._native.apply_bounce_weights(self._native), np.float32(0.0))
