"""The peers hemishadow is measured against: Embree ray casting projected on SH, and Cycles'
ambient-occlusion bake to a color attribute."""

import math
import time

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

import hemishadow

CHUNK_RAYS = 1 << 21  # rays per batch: bounds the temporaries to ~100 MB

# Zonal coefficients of the clamped cosine, l = 0..4: unoccluded transfer = A_l Y_lm(n).
CLAMPED_COSINE = np.repeat([math.pi, 2 * math.pi / 3, math.pi / 4, 0.0, -math.pi / 24], [1, 3, 5, 7, 9]).astype(np.float32)


def hammersley(n):
    """n points of the 2D Hammersley set in [0, 1)^2."""
    i = np.arange(n, dtype=np.uint64)
    bits = i.copy()
    bits = ((bits << np.uint64(16)) | (bits >> np.uint64(16))) & np.uint64(0xFFFFFFFF)
    bits = ((bits & np.uint64(0x55555555)) << np.uint64(1)) | ((bits & np.uint64(0xAAAAAAAA)) >> np.uint64(1))
    bits = ((bits & np.uint64(0x33333333)) << np.uint64(2)) | ((bits & np.uint64(0xCCCCCCCC)) >> np.uint64(2))
    bits = ((bits & np.uint64(0x0F0F0F0F)) << np.uint64(4)) | ((bits & np.uint64(0xF0F0F0F0)) >> np.uint64(4))
    bits = ((bits & np.uint64(0x00FF00FF)) << np.uint64(8)) | ((bits & np.uint64(0xFF00FF00)) >> np.uint64(8))
    return np.stack([(i.astype(np.float64) + 0.5) / n, bits.astype(np.float64) / 2.0**32], axis=1)


def frames_of(n):
    """Duff et al. 2017 tangent frames (t, b) of unit normals (V, 3)."""
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    sign = np.where(z >= 0.0, 1.0, -1.0).astype(n.dtype)
    a = -1.0 / (sign + z)
    b = x * y * a
    t = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=1)
    s = np.stack([b, sign + y * y * a, -y], axis=1)
    return t, s


class EmbreeTransfer:
    """Per-vertex diffuse transfer by Embree: `rays` cosine-distributed rays per vertex from
    p + offset n, a randomly shifted Hammersley set (Cranley-Patterson rotation per vertex)
    mapped to the disk by Shirley-Chiu and lifted (Malley), triangles incident to the
    receiver skipped by re-casting past them (as the engine and the reference do), and the
    control-variate estimator T = T_open(n) - pi/N sum over blocked rays of Y(d).

    One frame = BVH build + ray generation + intersection + projection, all vertices.
    embreex holds the GIL, so this runs on one core.
    """

    def __init__(self, triangles, rays, seed):
        self.tris = np.asarray(triangles, np.int64)
        self.rays = rays
        self.base = hammersley(rays).astype(np.float32)
        self.rng = np.random.default_rng(seed)

    def solve(self, vertices, normals, offset):
        v = np.asarray(vertices, np.float32)
        n = np.asarray(normals, np.float32)
        count, rays = len(v), self.rays
        scene = rtcore_scene.EmbreeScene()
        TriangleMesh(scene, v[self.tris])
        t_all, s_all = frames_of(n)
        chunk = max(1, CHUNK_RAYS // rays)
        blocked_sum = np.empty((count, 25))
        blocked_count = np.empty(count)
        for start in range(0, count, chunk):
            sl = slice(start, min(count, start + chunk))
            blocked_sum[sl], blocked_count[sl] = self._chunk(scene, v, n[sl], t_all[sl], s_all[sl],
                                                             np.arange(count)[sl], offset)
        open_transfer = hemishadow.sh_basis(n) * CLAMPED_COSINE
        T = open_transfer - (math.pi / rays) * blocked_sum
        return T.astype(np.float32), 1.0 - blocked_count / rays

    def _chunk(self, scene, v, n, t, s, ids, offset):
        count, rays = len(ids), self.rays
        # directions: shifted Hammersley -> concentric disk -> hemisphere -> world
        u = (self.base[None] + self.rng.random((count, 1, 2), dtype=np.float32)) % 1.0
        a, b = 2.0 * u[..., 0] - 1.0, 2.0 * u[..., 1] - 1.0
        first = np.abs(a) > np.abs(b)
        r = np.where(first, a, b)
        with np.errstate(divide="ignore", invalid="ignore"):
            phi = np.where(first, (math.pi / 4) * (b / a), math.pi / 2 - (math.pi / 4) * (a / b))
        phi = np.where(r == 0.0, 0.0, phi)
        x, y = r * np.cos(phi), r * np.sin(phi)
        z = np.sqrt(np.maximum(0.0, 1.0 - x * x - y * y))
        dirs = x[..., None] * t[:, None] + y[..., None] * s[:, None] + z[..., None] * n[:, None]
        dirs = dirs.reshape(-1, 3)
        origins = np.repeat(v[ids] + offset * n, rays, axis=0)
        receiver = np.repeat(ids, rays)
        hit = scene.run(origins, dirs).astype(np.int64)
        todo = np.nonzero(hit >= 0)[0]
        for _ in range(8):  # re-cast rays that hit a triangle incident to their receiver
            todo = todo[(self.tris[hit[todo]] == receiver[todo, None]).any(axis=1)]
            if len(todo) == 0:
                break
            p0, p1, p2 = (v[self.tris[hit[todo], k]] for k in range(3))
            normal = np.cross(p1 - p0, p2 - p0)
            with np.errstate(divide="ignore", invalid="ignore"):
                dist = np.einsum("ij,ij->i", p0 - origins[todo], normal) / np.einsum("ij,ij->i", dirs[todo], normal)
            dist = np.where(np.isfinite(dist), np.maximum(dist, 0.0), 0.0) + 0.1 * offset
            origins[todo] += dirs[todo] * dist[:, None]
            hit[todo] = scene.run(origins[todo], dirs[todo])
            todo = todo[hit[todo] >= 0]
        else:
            hit[todo] = -1  # still stuck on incident triangles: rare, counted as open
        blocked = hit >= 0
        rows = receiver[blocked] - ids[0]
        y_blocked = hemishadow.sh_basis(dirs[blocked]).astype(np.float64)
        csum = np.concatenate([np.zeros((1, y_blocked.shape[1])), np.cumsum(y_blocked, axis=0)])
        bounds = np.searchsorted(rows, np.arange(count + 1))
        return csum[bounds[1:]] - csum[bounds[:-1]], np.diff(bounds)


class CyclesAO:
    """Cycles (CPU) ambient occlusion baked to a point color attribute of a mesh made of these
    welded triangles, smooth shaded with the given vertex normals as custom normals (so Cycles
    shades with the same normals as everybody else). Cycles bakes every face corner and
    averages the corners of a vertex, so a vertex gets `samples` x valence AO rays.
    `bake(samples)` -> (seconds of the bake call, AO per vertex)."""

    def __init__(self, vertices, triangles, normals, distance):
        import bpy

        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        scene.render.engine = "CYCLES"
        scene.cycles.device = "CPU"
        scene.cycles.use_denoising = False
        scene.cycles.use_adaptive_sampling = False  # exactly `samples` per point
        scene.render.bake.target = "VERTEX_COLORS"
        scene.world = bpy.data.worlds.new("World")
        scene.world.light_settings.distance = distance  # AO rays reach across the whole mesh
        mesh = bpy.data.meshes.new("bench")
        mesh.from_pydata(np.asarray(vertices, np.float64).tolist(), [], np.asarray(triangles, np.int64).tolist())
        mesh.update()
        mesh.shade_smooth()
        mesh.normals_split_custom_set_from_vertices(np.asarray(normals, np.float64).tolist())
        mesh.materials.append(bpy.data.materials.new("bench"))
        self.attribute = mesh.color_attributes.new("ao", "FLOAT_COLOR", "POINT")
        mesh.color_attributes.active_color = self.attribute
        obj = bpy.data.objects.new("bench", mesh)
        scene.collection.objects.link(obj)
        bpy.context.view_layer.objects.active = obj
        obj.select_set(True)
        self.scene, self.mesh = scene, mesh
        self.bake(1)  # warm-up: kernels, first sync

    def bake(self, samples):
        import bpy

        self.scene.cycles.samples = samples
        start = time.perf_counter()
        result = bpy.ops.object.bake(type="AO")
        seconds = time.perf_counter() - start
        if result != {"FINISHED"}:
            raise RuntimeError(f"Cycles bake returned {result}")
        color = np.empty(len(self.mesh.vertices) * 4, np.float32)
        self.attribute.data.foreach_get("color", color)
        return seconds, color.reshape(-1, 4)[:, 0].astype(np.float64)
