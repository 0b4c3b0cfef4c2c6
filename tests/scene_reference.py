"""Independent references for scene visibility: dense Embree ray casting of a whole scene
(world-space triangles, instances applied here with numpy) from arbitrary receiver points.

Nothing here shares code with the engine. Receivers see every triangle (no own-triangle rule,
unlike tests/reference.py's vertex receivers); they cast from p + offset * n.
"""

import math

import numpy as np
import trimesh
from trimesh.ray.ray_pyembree import RayMeshIntersector

import reference as ref

RAYS_PER_BATCH = 1 << 21


class WorldScene:
    """Meshes placed by 4x4 matrices, flattened into one world-space triangle soup."""

    def __init__(self):
        self.meshes = []  # (vertices, triangles)
        self.instances = []  # (mesh index, matrix)
        self.radiance = {}

    def add_mesh(self, vertices, triangles):
        self.meshes.append((np.asarray(vertices, dtype=np.float64), np.asarray(triangles, dtype=np.int64)))
        return len(self.meshes) - 1

    def add_instance(self, mesh, matrix):
        self.instances.append((mesh, np.asarray(matrix, dtype=np.float64)))
        return len(self.instances) - 1

    def flattened(self):
        """(vertices, triangles, per-vertex radiance or zeros) in world space."""
        verts, tris, colours, base = [], [], [], 0
        for mesh, m in self.instances:
            v, t = self.meshes[mesh]
            verts.append(v @ m[:3, :3].T + m[:3, 3])
            # a mirrored instance turns its winding over: keep world-space faces outward
            tris.append((t if np.linalg.det(m[:3, :3]) > 0 else t[:, ::-1]) + base)
            colours.append(self.radiance.get(mesh, np.zeros((len(v), 3))))
            base += len(v)
        return np.concatenate(verts), np.concatenate(tris), np.concatenate(colours)

    def engine(self, hemishadow, **kwargs):
        """The same scene in the engine, instances kept as instances."""
        scene = hemishadow.Scene(**kwargs)
        for v, t in self.meshes:
            scene.add_mesh(v.astype(np.float32), t)
        for mesh, m in self.instances:
            scene.add_instance(mesh, m)
        for mesh, rgb in self.radiance.items():
            scene.set_radiance(mesh, rgb)
        return scene


def transfer_reference(vertices, triangles, points, normals, *, offset, bands=5, n_side=64, seed=0):
    """Diffuse transfer (P, bands^2) and AO (P,) of receiver points by Embree, n_side^2
    stratified cosine-distributed rays each, with the exact open transfer as control variate."""
    intersector = RayMeshIntersector(trimesh.Trimesh(vertices, triangles, process=False))
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    rng = np.random.default_rng(seed)
    count = n_side * n_side
    batch = max(1, RAYS_PER_BATCH // count)
    out = np.empty((len(points), bands * bands))
    ao = np.empty(len(points))
    for start in range(0, len(points), batch):
        sl = slice(start, start + batch)
        n = normals[sl]
        t, s = ref.orthonormal_basis(n)
        local = ref.stratified_cosine_directions(n_side, rng, count=len(n))
        dirs = local[..., :1] * t[:, None] + local[..., 1:2] * s[:, None] + local[..., 2:] * n[:, None]
        dirs = (dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)).reshape(-1, 3)
        origins = np.repeat(points[sl] + offset * n, count, axis=0)
        blocked = intersector.intersects_any(origins, dirs)
        rows = np.repeat(np.arange(len(n)), count)
        ao[sl] = 1.0 - blocked.reshape(len(n), count).mean(axis=1)
        weight = np.full(blocked.sum(), math.pi / count)
        out[sl] = ref.unoccluded_transfer(n, bands) - ref._accumulate(rows[blocked], dirs[blocked], weight, len(n), bands)
    return out, ao


def gather_reference(vertices, triangles, radiance, points, normals=None, *, offset, bands=3, n_side=96, seed=0):
    """SH projection (P, bands^2, 3) of the radiance of the first surface hit (interpolated
    barycentrically), over the hemisphere of each normal or the whole sphere when normals is
    None; stratified uniform directions."""
    intersector = RayMeshIntersector(trimesh.Trimesh(vertices, triangles, process=False))
    rng = np.random.default_rng(seed)
    points = np.asarray(points, dtype=np.float64)
    out = np.zeros((len(points), bands * bands, 3))
    for r, p in enumerate(points):
        u = (np.arange(n_side)[:, None] + rng.random((n_side, n_side))) / n_side
        v = (np.arange(n_side)[None, :] + rng.random((n_side, n_side))) / n_side
        z = (1.0 - 2.0 * u).ravel()  # uniform on the sphere
        phi = 2.0 * math.pi * v.ravel()
        rho = np.sqrt(np.maximum(0.0, 1.0 - z * z))
        dirs = np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)
        solid = 4.0 * math.pi / len(dirs)
        origin = p
        if normals is not None:
            n = np.asarray(normals[r], dtype=np.float64)
            n = n / np.linalg.norm(n)
            dirs = dirs[dirs @ n > 0.0]
            origin = p + offset * n
        locations, ray_ids, tri_ids = intersector.intersects_location(np.repeat(origin[None], len(dirs), 0), dirs,
                                                                      multiple_hits=False)
        corners = vertices[triangles[tri_ids]]
        bary = trimesh.triangles.points_to_barycentric(corners, locations)
        colour = np.einsum("rk,rkc->rc", bary, radiance[triangles[tri_ids]])
        y = ref.sh_basis_reference(dirs[ray_ids], bands)
        out[r] = solid * y.T @ colour
    return out
