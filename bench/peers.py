"""The peer hemishadow is measured against: Embree ray casting projected on SH, on all cores.

embreex holds the GIL, so one Python process traces on one core. `EmbreePool` therefore
runs os.cpu_count() worker processes (started once, outside the timings); each frame, every
worker builds its own BVH of the frame's triangles and traces a share of the receivers.
`embree_transfer` is the same computation in this process: the jitter of each block of
BLOCK receivers comes from its own seed, and sums run per receiver, so the result does not
depend on how the receivers are shared out.
"""

import math
import multiprocessing
import os

import numpy as np
from embreex import rtcore, rtcore_scene
from embreex.mesh_construction import TriangleMesh

import hemishadow

BLOCK = 32  # receivers per random stream: the unit of sharing between workers
CHUNK_RAYS = 1 << 20  # rays per Embree call: bounds the temporaries to ~100 MB
MAX_RECASTS = 8

# Zonal coefficients of the clamped cosine, l = 0..4: unoccluded transfer = A_l Y_lm(n).
CLAMPED_COSINE = np.repeat([math.pi, 2 * math.pi / 3, math.pi / 4, 0.0, -math.pi / 24], [1, 3, 5, 7, 9])


def frames_of(n):
    """Duff et al. 2017 tangent frames (t, b) of unit normals (V, 3)."""
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    sign = np.where(z >= 0.0, 1.0, -1.0).astype(n.dtype)
    a = -1.0 / (sign + z)
    b = x * y * a
    t = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=1)
    s = np.stack([b, sign + y * y * a, -y], axis=1)
    return t, s


def stratified_jitter(first, count, n_side, seed):
    """(count, n_side^2, 2) points in [0, 1)^2, one jittered point per cell of an n_side x
    n_side grid, for receivers first .. first + count - 1 (first a multiple of BLOCK): each
    block of BLOCK receivers draws from its own stream (seed, block), whoever computes it."""
    i, j = np.meshgrid(np.arange(n_side), np.arange(n_side), indexing="ij")
    cells = np.stack([i.ravel(), j.ravel()], axis=1).astype(np.float32)
    out = []
    for block in range(first // BLOCK, -(-(first + count) // BLOCK)):
        rng = np.random.default_rng((seed, block))
        out.append(rng.random((BLOCK, n_side * n_side, 2), dtype=np.float32))
    jitter = np.concatenate(out)[first % BLOCK:first % BLOCK + count]
    return (cells + jitter) / n_side


def cosine_directions(u, n, t, s):
    """Points u (R, K, 2) of the unit square -> cosine-distributed world directions (R*K, 3)
    about normals n (R, 3): concentric map to the disk (Shirley-Chiu), lifted (Malley)."""
    a, b = 2.0 * u[..., 0] - 1.0, 2.0 * u[..., 1] - 1.0
    first = np.abs(a) > np.abs(b)
    r = np.where(first, a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(first, (math.pi / 4) * (b / a), math.pi / 2 - (math.pi / 4) * (a / b))
    phi = np.where(r == 0.0, 0.0, phi)
    x, y = r * np.cos(phi), r * np.sin(phi)
    z = np.sqrt(np.maximum(0.0, 1.0 - x * x - y * y))
    dirs = x[..., None] * t[:, None] + y[..., None] * s[:, None] + z[..., None] * n[:, None]
    return dirs.reshape(-1, 3).astype(np.float32)


_DEVICE = []


def _device():
    """One Embree device per process: a new one per scene would add milliseconds per frame."""
    if not _DEVICE:
        _DEVICE.append(rtcore.EmbreeDevice())
    return _DEVICE[0]


def embree_transfer(vertices, triangles, normals, offset, n_side, seed, first=0, count=None):
    """Transfer (count, 25) float32 and AO (count,) of receivers first .. first + count - 1 by
    n_side^2 stratified cosine rays each from p + offset n: BVH build, first-hit queries, rays
    that hit a triangle incident to their receiver re-cast past it (the engine's and the
    reference's rule), and the control variate T = T_open(n) - pi/N sum over blocked rays Y(d)."""
    v = np.asarray(vertices, np.float32)
    tris = np.asarray(triangles, np.int64)
    count = len(v) - first if count is None else count
    scene = rtcore_scene.EmbreeScene(_device())
    TriangleMesh(scene, v[tris])
    rays = n_side * n_side
    n_all = np.asarray(normals, np.float32)[first:first + count]
    blocked_sum = np.empty((count, 25))
    blocked_count = np.empty(count)
    step = max(BLOCK, CHUNK_RAYS // rays // BLOCK * BLOCK)
    for start in range(0, count, step):
        stop = min(count, start + step)
        ids = np.arange(first + start, first + stop)
        u = stratified_jitter(first + start, stop - start, n_side, seed)
        blocked_sum[start:stop], blocked_count[start:stop] = _trace(scene, v, tris, n_all[start:stop], ids, u, offset)
    open_transfer = hemishadow.sh_basis(n_all).astype(np.float64) * CLAMPED_COSINE
    T = open_transfer - (math.pi / rays) * blocked_sum
    return T.astype(np.float32), 1.0 - blocked_count / rays


def _trace(scene, v, tris, n, ids, u, offset):
    count, rays = len(ids), u.shape[1]
    t, s = frames_of(n)
    dirs = cosine_directions(u, n, t, s)
    origins = np.repeat(v[ids] + offset * n, rays, axis=0)
    receiver = np.repeat(ids, rays)
    hit = scene.run(origins, dirs).astype(np.int64)
    todo = np.nonzero(hit >= 0)[0]
    for _ in range(MAX_RECASTS):
        todo = todo[(tris[hit[todo]] == receiver[todo, None]).any(axis=1)]
        if len(todo) == 0:
            break
        p0, p1, p2 = (v[tris[hit[todo], k]] for k in range(3))
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
    y = hemishadow.sh_basis(dirs[blocked]).astype(np.float64)
    # per-receiver sums over each receiver's own run of rows (sorted): independent of the chunking
    bounds = np.searchsorted(rows, np.arange(count + 1))
    n_blocked = np.diff(bounds)
    sums = np.zeros((count, y.shape[1]))
    some = n_blocked > 0
    if some.any():
        sums[some] = np.add.reduceat(y, bounds[:-1][some], axis=0)
    return sums, n_blocked


def shares(count, workers):
    """(first, count) of each worker: contiguous runs of whole BLOCKs, as even as possible."""
    blocks = -(-count // BLOCK)
    edges = [min(count, BLOCK * (blocks * k // workers)) for k in range(workers + 1)]
    return [(a, b - a) for a, b in zip(edges[:-1], edges[1:]) if b > a]


def _worker_solve(args):
    return embree_transfer(*args)


class EmbreePool:
    """os.cpu_count() spawned worker processes tracing shares of the receivers of a frame."""

    def __init__(self, workers=None):
        self.workers = workers or os.cpu_count()
        self.pool = multiprocessing.get_context("spawn").Pool(self.workers)
        self.pool.map(_worker_solve, [(np.zeros((3, 3), np.float32), np.array([[0, 1, 2]]),
                                       np.tile(np.float32([0, 0, 1]), (3, 1)), 1e-3, 2, 0)] * self.workers)

    def solve(self, vertices, triangles, normals, offset, n_side, seed):
        """(T (V, 25) float32, AO (V,)) of every vertex: what `embree_transfer` gives."""
        jobs = [(vertices, triangles, normals, offset, n_side, seed, first, count)
                for first, count in shares(len(vertices), self.workers)]
        parts = self.pool.map(_worker_solve, jobs, chunksize=1)
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])

    def reference(self, vertices, triangles, normals, offset, n_side, seed, ids):
        """tests/reference.py's transfer_reference of receivers `ids`, shared out over the workers
        (each share with its own seed) -> (T (len(ids), 25), AO)."""
        jobs = [(vertices, triangles, normals, offset, n_side, seed + k, ids[k::self.workers])
                for k in range(self.workers)]
        parts = self.pool.map(_worker_reference, jobs, chunksize=1)
        T, ao = np.empty((len(ids), 25)), np.empty(len(ids))
        for k, (t, a) in enumerate(parts):
            T[k::self.workers], ao[k::self.workers] = t, a
        return T, ao

    def close(self):
        self.pool.close()
        self.pool.join()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _worker_reference(args):
    import reference  # tests/reference.py: the workers inherit sys.path

    vertices, triangles, normals, offset, n_side, seed, ids = args
    return reference.transfer_reference(vertices, triangles, normals, n_side=n_side, offset=offset,
                                        vertex_ids=ids, seed=seed, return_ao=True)
