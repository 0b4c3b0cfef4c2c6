"""Independent references for transfer vectors: plain numpy and Embree ray casting.

Nothing here shares code with the engine, so agreement between the two means something.
Conventions follow ../shared/DESIGN.md: real SH from the appendix of Wong, Or, Fu 2003
(Condon-Shortley phase, theta from +Z, phi from +X towards +Y, index l*(l+1)+m), diffuse
transfer T_i = integral of Y_i(s) V(s) max(0, n.s) ds, ambient occlusion = T_0 / 0.886227.
Glossy (Phong) transfer follows equation 3 of Kautz, Lehtinen, Aila 2004.
Used by the tests and, later, by the benchmarks: no pytest here.
"""

import math

import numpy as np
import trimesh
from trimesh.ray.ray_pyembree import RayMeshIntersector

AO_SCALE = 0.886227  # T_0 of an unoccluded receiver: pi * Y_00
# Unoccluded diffuse transfer is A_l Y_lm(n): the clamped cosine's zonal coefficients
# (Ramamoorthy and Hanrahan 2001), l = 0..4.
CLAMPED_COSINE_BANDS = (math.pi, 2.0 * math.pi / 3.0, math.pi / 4.0, 0.0, -math.pi / 24.0)
RAYS_PER_BATCH = 1 << 21  # bounds the float64 temporaries to a few hundred MB
MAX_RECASTS = 8


# --- spherical harmonics ------------------------------------------------------------------


def sh_basis_reference(dirs, bands=5):
    """Real SH basis at unit directions (..., 3) -> (..., bands*bands), float64.

    Written term by term from the appendix of Wong et al. 2003: Q by its recursion
    (the (1-2m) factor carries the Condon-Shortley phase), N_lm, cos(m phi) / sin(|m| phi),
    and m = 0 divided by sqrt(2).
    """
    dirs = np.asarray(dirs, dtype=np.float64)
    x, y, z = dirs[..., 0], dirs[..., 1], dirs[..., 2]
    cos_theta = np.clip(z, -1.0, 1.0)
    sin_theta = np.hypot(x, y)  # exact near the poles, unlike sqrt(1 - z^2)
    phi = np.arctan2(y, x)
    q = _legendre_q(cos_theta, sin_theta, bands)
    out = np.empty(dirs.shape[:-1] + (bands * bands,))
    for l in range(bands):
        for m in range(-l, l + 1):
            a = abs(m)
            norm = math.sqrt((2 * l + 1) / (2.0 * math.pi) * math.factorial(l - a) / math.factorial(l + a))
            if m > 0:
                value = norm * q[l, a] * np.cos(m * phi)
            elif m == 0:
                value = norm * q[l, 0] / math.sqrt(2.0)
            else:
                value = norm * q[l, a] * np.sin(a * phi)
            out[..., l * (l + 1) + m] = value
    return out


def _legendre_q(x, sin_theta, bands):
    """Q_{l,m}(x) for 0 <= m <= l < bands, by the appendix's four cases."""
    q = {(0, 0): np.ones_like(x)}
    for m in range(1, bands):
        q[m, m] = (1 - 2 * m) * sin_theta * q[m - 1, m - 1]
    for m in range(bands - 1):
        q[m + 1, m] = (2 * m + 1) * x * q[m, m]
    for m in range(bands):
        for l in range(m + 2, bands):
            q[l, m] = ((2 * l - 1) * x * q[l - 1, m] - (l + m - 1) * q[l - 2, m]) / (l - m)
    return q


def unoccluded_transfer(normals, bands=5):
    """Exact diffuse transfer with nothing in the way: A_l Y_lm(n)."""
    scale = np.repeat(CLAMPED_COSINE_BANDS[:bands], [2 * l + 1 for l in range(bands)])
    return sh_basis_reference(normals, bands) * scale


# --- sampling -----------------------------------------------------------------------------


def stratified_cosine_directions(n_side, rng, count=None):
    """n_side^2 cosine-distributed directions in a local frame (+Z = normal).

    Jittered grid on the unit square -> Shirley-Chiu concentric map to the disk (keeps the
    strata compact) -> lifted to the hemisphere (Malley's method; the disk is the same
    projection the engine's visibility mask uses). Shape (n_side^2, 3), or
    (count, n_side^2, 3) with independent jitter per row when count is given.
    """
    lead = () if count is None else (count,)
    i, j = np.meshgrid(np.arange(n_side), np.arange(n_side), indexing="ij")
    u = (i.ravel() + rng.random(lead + (n_side * n_side,))) / n_side
    v = (j.ravel() + rng.random(lead + (n_side * n_side,))) / n_side
    x, y = _concentric_disk(2.0 * u - 1.0, 2.0 * v - 1.0)
    z = np.sqrt(np.maximum(0.0, 1.0 - x * x - y * y))
    return np.stack([x, y, z], axis=-1)


def _concentric_disk(a, b):
    """Shirley and Chiu 1997: square [-1,1]^2 -> unit disk, area preserving."""
    first = np.abs(a) > np.abs(b)
    r = np.where(first, a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        angle = np.where(first, (math.pi / 4.0) * (b / a), math.pi / 2.0 - (math.pi / 4.0) * (a / b))
    angle = np.where(r == 0.0, 0.0, angle)
    return r * np.cos(angle), r * np.sin(angle)


# --- mesh helpers -------------------------------------------------------------------------


def weld(vertices, triangles):
    """Merge vertices with exactly equal positions; drop unreferenced vertices and
    triangles that collapse. Returns (vertices, triangles, remap) with remap[old] = new
    index, -1 for vertices no triangle uses."""
    vertices = np.asarray(vertices)
    triangles = np.asarray(triangles, dtype=np.int64)
    used = np.unique(triangles)
    unique, inverse = np.unique(vertices[used], axis=0, return_inverse=True)
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = inverse.ravel()
    tris = remap[triangles]
    keep = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 2] != tris[:, 0])
    return unique, tris[keep], remap


def vertex_normals(vertices, triangles):
    """Area-weighted vertex normals: the sum of the incident faces' cross products."""
    v = np.asarray(vertices, dtype=np.float64)
    p0, p1, p2 = (v[triangles[:, k]] for k in range(3))
    face = np.cross(p1 - p0, p2 - p0)  # length = 2 * area, so the sum is area-weighted
    acc = np.zeros_like(v)
    for k in range(3):
        np.add.at(acc, triangles[:, k], face)
    length = np.linalg.norm(acc, axis=1, keepdims=True)
    return acc / np.where(length > 0.0, length, 1.0)


def mean_edge_length(vertices, triangles):
    v = np.asarray(vertices, dtype=np.float64)
    edges = v[np.roll(triangles, -1, axis=1)] - v[triangles]
    return float(np.linalg.norm(edges, axis=-1).mean())


def orthonormal_basis(n):
    """Tangent and bitangent for unit normals (..., 3); Duff et al. 2017, branchless and
    continuous except across z = 0, where only the (irrelevant) rotation about n jumps."""
    n = np.asarray(n, dtype=np.float64)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    sign = np.where(z >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    t = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=-1)
    s = np.stack([b, sign + y * y * a, -y], axis=-1)
    return t, s


# --- Monte-Carlo transfer -----------------------------------------------------------------


def transfer_reference(vertices, triangles, normals, *, bands=5, n_side=64, offset,
                       brdf="diffuse", exponent=None, view=None, vertex_ids=None, seed=0,
                       return_ao=False):
    """Dense Monte-Carlo transfer vectors by Embree ray casting, (len(vertex_ids), bands^2).

    Each receiver casts n_side^2 stratified cosine-distributed rays from p + offset * n.
    Triangles incident to the receiver never block (as in the engine). Diffuse uses the
    exact unoccluded transfer as a control variate, so only blocked rays add noise.
    Glossy is Phong: f_r = (e+2)/(2 pi) max(0, r.s)^e, r = 2(n.v)n - v, v towards the
    viewer; `view` is one direction (3,) or one per vertex (len(vertices), 3).
    With return_ao, also returns the estimated ambient occlusion (1 = unoccluded).
    """
    if brdf not in ("diffuse", "phong"):
        raise ValueError(f"brdf must be 'diffuse' or 'phong', not {brdf!r}")
    if brdf == "phong" and (exponent is None or view is None):
        raise ValueError("phong needs exponent and view")
    vertices = np.asarray(vertices, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64)
    normals = np.asarray(normals, dtype=np.float64)
    ids = np.arange(len(vertices)) if vertex_ids is None else np.asarray(vertex_ids)
    views = None if view is None else _per_vertex_views(view, len(vertices))[ids]
    caster = _OccluderCaster(vertices, triangles, eps=1e-4 * mean_edge_length(vertices, triangles))
    rng = np.random.default_rng(seed)
    batch = max(1, RAYS_PER_BATCH // (n_side * n_side))
    out = np.empty((len(ids), bands * bands))
    ao = np.empty(len(ids))
    for start in range(0, len(ids), batch):
        sl = slice(start, start + batch)
        out[sl], ao[sl] = _transfer_batch(caster, vertices, normals, ids[sl], n_side, rng, offset,
                                          bands, exponent, None if views is None else views[sl])
    return (out, ao) if return_ao else out


def _per_vertex_views(view, n):
    view = np.asarray(view, dtype=np.float64)
    view = np.broadcast_to(view, (n, 3)) if view.shape == (3,) else view
    return view / np.linalg.norm(view, axis=-1, keepdims=True)


def _transfer_batch(caster, vertices, normals, ids, n_side, rng, offset, bands, exponent, views):
    n = normals[ids]
    t, s = orthonormal_basis(n)
    local = stratified_cosine_directions(n_side, rng, count=len(ids))
    dirs = local[..., :1] * t[:, None] + local[..., 1:2] * s[:, None] + local[..., 2:] * n[:, None]
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    origins = vertices[ids] + offset * n
    count = n_side * n_side
    receiver = np.repeat(np.arange(len(ids)), count)
    blocked = caster.blocked(np.repeat(origins, count, axis=0), dirs.reshape(-1, 3), ids[receiver])
    ao = 1.0 - blocked.reshape(len(ids), count).mean(axis=1)
    weight = np.full(receiver.shape, math.pi / count)  # cosine pdf cancels the cosine
    if views is None:
        # control variate: exact open transfer minus the blocked rays' share
        rows, flat = receiver[blocked], dirs.reshape(-1, 3)[blocked]
        return unoccluded_transfer(n, bands) - _accumulate(rows, flat, weight[blocked], len(ids), bands), ao
    v = views
    r = 2.0 * np.sum(n * v, axis=1, keepdims=True) * n - v
    lobe = np.maximum(0.0, np.einsum("bkj,bj->bk", dirs, r)).ravel() ** exponent
    weight *= (exponent + 2.0) / (2.0 * math.pi) * lobe
    keep = ~blocked & (weight > 0.0)  # skips SH evaluation where nothing is added
    return _accumulate(receiver[keep], dirs.reshape(-1, 3)[keep], weight[keep], len(ids), bands), ao


def _accumulate(rows, dirs, weight, n_rows, bands):
    """Sum weight * Y(dir) per receiver row."""
    y = sh_basis_reference(dirs, bands) * weight[:, None]
    return np.stack([np.bincount(rows, weights=y[:, i], minlength=n_rows) for i in range(bands * bands)], axis=1)


class _OccluderCaster:
    """First-hit queries through Embree, skipping triangles incident to the receiver."""

    def __init__(self, vertices, triangles, eps):
        mesh = trimesh.Trimesh(vertices, triangles, process=False)
        self.intersector = RayMeshIntersector(mesh)
        self.vertices, self.triangles, self.eps = vertices, triangles, eps

    def blocked(self, origins, dirs, receiver_vertex):
        """Bool per ray: does it hit a triangle not incident to its receiver vertex?"""
        origins = origins.copy()
        hit = np.full(len(dirs), -1, dtype=np.int64)
        todo = np.arange(len(dirs))
        for _ in range(MAX_RECASTS):
            prim = self.intersector.intersects_first(origins[todo], dirs[todo])
            hit[todo] = prim
            incident = prim >= 0
            incident[incident] = (self.triangles[prim[incident]] == receiver_vertex[todo[incident], None]).any(axis=1)
            todo = todo[incident]
            if len(todo) == 0:
                break
            # re-cast from just past the incident triangle's plane
            origins[todo] += dirs[todo] * (self._plane_distance(origins[todo], dirs[todo], hit[todo]) + self.eps)[:, None]
        hit[todo] = -1  # rays still stuck on incident triangles: rare; count as open
        return hit >= 0

    def _plane_distance(self, origins, dirs, prim):
        p0, p1, p2 = (self.vertices[self.triangles[prim, k]] for k in range(3))
        normal = np.cross(p1 - p0, p2 - p0)
        denom = np.einsum("ij,ij->i", dirs, normal)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.einsum("ij,ij->i", p0 - origins, normal) / denom
        return np.where(np.isfinite(t), np.maximum(t, 0.0), 0.0)


# --- error measures -----------------------------------------------------------------------


def relative_l2_errors(T, T_ref):
    """Per-vertex ||T - T_ref|| / ||T_ref|| (Table 1 of Kautz et al. 2004)."""
    T = np.asarray(T, dtype=np.float64)
    T_ref = np.asarray(T_ref, dtype=np.float64)
    ref_norm = np.linalg.norm(T_ref, axis=1)
    return np.linalg.norm(T - T_ref, axis=1) / np.maximum(ref_norm, 1e-12)


def error_summary(T, T_ref, ao_ref=None):
    """Per-vertex relative L2 errors summarised as the issue and Table 1 of the paper ask.

    - median: over all vertices;
    - mean: over vertices whose ambient occlusion is at least 0.1 (AO_ref >= 0.1); below
      that the transfer is near zero, so relative errors there measure little;
    - occluded_mean: over those of them that are at least 10 % occluded (1 - AO_ref >= 0.1),
      where the rasterizer does its work;
    - dark_*: the vertices with AO_ref < 0.1, reported separately, with their error relative
      to the norm of an unoccluded transfer vector (pi Y00 = 0.886 in band 0 and more).
    AO_ref defaults to T_ref[:, 0] / 0.886227, which holds for diffuse transfer only: pass it
    for glossy.
    """
    T = np.asarray(T, dtype=np.float64)
    T_ref = np.asarray(T_ref, dtype=np.float64)
    ao = T_ref[:, 0] / AO_SCALE if ao_ref is None else np.asarray(ao_ref)
    err = relative_l2_errors(T, T_ref)
    lit = ao >= 0.1
    occluded = lit & ((1.0 - ao) >= 0.1)
    open_norm = np.linalg.norm(unoccluded_transfer(np.array([[0.0, 0.0, 1.0]]), int(round(T.shape[1] ** 0.5)))[0])
    dark_abs = np.linalg.norm(T - T_ref, axis=1)[~lit] / open_norm
    mean_of = lambda values: float(values.mean()) if len(values) else float("nan")  # noqa: E731
    return {
        "median": float(np.median(err)),
        "mean": mean_of(err[lit]),
        "occluded_mean": mean_of(err[occluded]),
        "p95": float(np.percentile(err, 95)),
        "n_vertices": int(len(err)),
        "n_lit": int(lit.sum()),
        "n_occluded": int(occluded.sum()),
        "n_dark": int((~lit).sum()),
        "dark_abs_error_mean": mean_of(dark_abs),
    }
