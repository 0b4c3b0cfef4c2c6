"""What the baker is given: placed meshes (`Surface`) and the objects to bake (`Target`),
checked and brought to world space per triangle corner."""

from dataclasses import dataclass, field

import numpy as np

from . import basis


@dataclass
class Surface:
    """A mesh of the scene as the baker sees it: `mesh_id` in the `Scene`, its vertices (V, 3)
    and triangles (M, 3) as given to `Scene.add_mesh`, the world `matrix` (4x4, column vectors,
    identity when None) of the instance whose vertices act as bounce receivers, and its diffuse
    `albedo` and emitted radiance `emission` ((3,) or per vertex (V, 3)). Every instance of a
    mesh shows the same radiance (`Scene.set_radiance`)."""
    mesh_id: int
    vertices: np.ndarray
    triangles: np.ndarray
    matrix: np.ndarray = None
    albedo: object = 0.8
    emission: object = 0.0
    name: str = ""


@dataclass
class Target:
    """An object to bake: its `surface`, the lightmap `uv` ((M, 3, 2) per triangle corner, or
    (V, 2) per vertex) placing its texels, shading `normals` ((M, 3, 3) or (V, 3), object
    space; None: face normals, flat shading), `tangents` ((M, 3, 4) or (V, 4): xyz and the
    bitangent sign, object space, MikkTSpace of the normal-map UV in Blender; None: per
    triangle dP/du of `tangent_uv`, or of `uv` when that is None too)."""
    surface: Surface
    uv: np.ndarray
    normals: np.ndarray = None
    tangents: np.ndarray = None
    tangent_uv: np.ndarray = None
    name: str = field(default="")

    @property
    def label(self):
        return self.name or self.surface.name or f"mesh {self.surface.mesh_id}"


def finite(values, what, shape):
    """A float64 array of `shape` (-1: any) with only finite values, or a clear ValueError."""
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be numbers") from None
    if array.ndim != len(shape) or any(s not in (-1, a) for s, a in zip(shape, array.shape)):
        raise ValueError(f"{what} must have shape {tuple('N' if s == -1 else s for s in shape)}, got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{what} has a NaN or infinite value")
    return array


def per_vertex(value, count, what, label):
    """(3,) or (V, 3) colour -> (V, 3)."""
    array = np.asarray(value, dtype=np.float64)
    if array.ndim <= 1:
        array = np.broadcast_to(array, (3,)) if array.size in (1, 3) else array
        array = finite(array, f"{label}: {what}", (3,))
        return np.broadcast_to(array, (count, 3))
    return finite(array, f"{label}: {what}", (count, 3))


def placed(surface, label):
    """World vertices (V, 3), triangles (M, 3) int64, the matrix's 3x3 part and its normal matrix."""
    vertices = finite(surface.vertices, f"{label}: vertices", (-1, 3))
    triangles = np.asarray(surface.triangles)
    if triangles.ndim != 2 or triangles.shape[1] != 3 or triangles.dtype.kind not in "iu":
        raise ValueError(f"{label}: triangles must be integer (M, 3), got {triangles.shape} {triangles.dtype}")
    if not len(triangles):
        raise ValueError(f"{label}: the mesh has no faces")
    if triangles.min() < 0 or triangles.max() >= len(vertices):
        raise ValueError(f"{label}: triangle indices out of range 0..{len(vertices) - 1}")
    matrix = np.eye(4) if surface.matrix is None else finite(surface.matrix, f"{label}: matrix", (4, 4))
    linear = matrix[:3, :3]
    world = vertices @ linear.T + matrix[:3, 3]
    return world, triangles.astype(np.int64), linear, np.linalg.inv(linear).T


def corners(values, triangles, width, what, label):
    """Per-corner (M, 3, width) from per-corner or per-vertex input."""
    array = np.asarray(values)
    if array.ndim == 2:
        array = finite(array, f"{label}: {what}", (-1, width))
        if len(array) <= triangles.max():
            raise ValueError(f"{label}: {what} has {len(array)} rows, fewer than the mesh's vertices")
        return array[triangles]
    return finite(array, f"{label}: {what}", (len(triangles), 3, width))


def target_corners(target):
    """World-space corner data of a target: positions, geometric normals, shading normals,
    tangents (xyz + sign), lightmap UVs."""
    label = target.label
    if target.uv is None:
        raise ValueError(f"{label}: no lightmap UVs given")
    world, tris, linear, normal_matrix = placed(target.surface, label)
    pos = world[tris]
    local = finite(target.surface.vertices, f"{label}: vertices", (-1, 3))[tris]
    ng_local = np.cross(local[:, 1] - local[:, 0], local[:, 2] - local[:, 0])
    ng = ng_local @ normal_matrix.T
    ng /= np.maximum(np.linalg.norm(ng, axis=1, keepdims=True), 1e-300)
    uv = corners(target.uv, tris, 2, "uv", label)
    if target.normals is None:
        normals = np.repeat(ng[:, None], 3, axis=1)
    else:
        normals = corners(target.normals, tris, 3, "normals", label) @ normal_matrix.T
    if target.tangents is None:
        tuv = uv if target.tangent_uv is None else corners(target.tangent_uv, tris, 2, "tangent_uv", label)
        tangents = basis.uv_tangents(pos, tuv, normals)
    else:
        tangents = corners(target.tangents, tris, 4, "tangents", label).copy()
        tangents[..., :3] = tangents[..., :3] @ linear.T
        tangents[..., 3] *= np.sign(np.linalg.det(linear))  # a mirrored object turns its handedness over
    return pos, ng, normals, tangents, uv, tris


def split_sharp_vertices(triangles, corner_normals):
    """Triangles (M, 3) re-indexed so that corners of one vertex with different shading
    normals (sharp edges, flat shading) become vertices of their own, and per new vertex the
    index of the vertex it copies (V',): bounce light is carried per vertex, and a box's corner
    shared by its faces would pass the light of one face on to the others (the bottom of a
    cabinet standing on a floor sees the sky under the floor and lit the cabinet's sides).
    Corners with bit-equal normals stay one vertex, as Blender gives a smooth fan's corners."""
    tris = np.asarray(triangles, dtype=np.int64)
    normals = np.asarray(corner_normals, dtype=np.float32).reshape(-1, 3) + np.float32(0.0)  # -0.0 -> 0.0
    keys = np.concatenate([tris.reshape(-1, 1), normals.view(np.int32).astype(np.int64)], axis=1)
    unique, inverse = np.unique(keys, axis=0, return_inverse=True)
    return inverse.reshape(tris.shape), unique[:, 0]


def bisected(vertices, triangles, max_edge, world=None, corner_values=(), vertex_values=(), max_triangles=200_000):
    """The mesh with its edges longer than `max_edge` split at their midpoints, conformingly:
    longest-edge bisection (Rivara 1984). Each round, every triangle whose longest edge is too
    long splits it; a triangle sharing a split edge that is not its own longest splits its
    longest too (so no vertex lands on an edge it does not end; the closure), and a triangle
    then splits into 2, 3 or 4 along its marked edges. Each triangle splits as much as its own
    edges need, where halving the whole mesh a number of times set by its longest edge split
    a box's small faces as often as its large ones (the test room's bounce vertices: 1,685
    against 3,597 at the same length). A thin strip gains nothing: a 4.4 x 0.2 face split to
    0.55 gets 150 triangles, three halvings of every edge 128.
    Bounce light is carried per vertex: a room's walls of a few large triangles carried a sun
    patch, or a lamp's pool of light, by their corners only.

    Edge lengths are measured in `world` (V, 3) positions (None: `vertices`); midpoints are
    made once per edge (vertex ids: a mesh split at sharp edges stays split). Returns the
    vertices (V', 3), triangles (M', 3), each array of `corner_values` ((M, 3, ...): per
    triangle corner) and of `vertex_values` ((V, ...); a (3,) colour is left as it is)
    interpolated linearly, so interpolating across a child gives what its parent gave (UVs,
    shading normals, tangents: the same texels), and each child's parent (M',). Rounds stop
    before the triangles would pass `max_triangles`."""
    v = np.asarray(vertices, dtype=np.float64)
    w = v if world is None else np.asarray(world, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    corners = [np.asarray(c) for c in corner_values]
    per_vertex = [np.asarray(a, dtype=np.float64) if np.ndim(a) == 2 else a for a in vertex_values]
    parent = np.arange(len(t))
    while max_edge > 0 and len(t):
        idx, unique, longest, longest_length = _edges_and_longest(t, w)
        marked = np.zeros(len(unique), bool)
        marked[longest[longest_length > max_edge]] = True
        if not marked.any():
            break
        while True:  # the closure: a triangle with a marked edge splits its longest one too
            need = marked[idx].any(axis=1) & ~marked[longest]
            if not need.any():
                break
            marked[longest[need]] = True
        if len(t) + int(marked[idx].sum()) > max_triangles:
            break
        mid = np.full(len(unique), -1, np.int64)
        mid[marked] = len(v) + np.arange(int(marked.sum()))
        ends = unique[marked]
        v, w = np.concatenate([v, v[ends].mean(axis=1)]), np.concatenate([w, w[ends].mean(axis=1)])
        per_vertex = [np.concatenate([a, a[ends].mean(axis=1)]) if np.ndim(a) == 2 else a for a in per_vertex]
        t, corners, parent = _split(t, idx, longest, marked, mid, corners, parent)
    return v, t, corners, per_vertex, parent


def _edges_and_longest(t, w):
    """Per triangle its edges' ids (M, 3) (edge k joins corners k and k + 1), the unique edges
    (E, 2), and each triangle's longest edge id (ties go to the lowest id, the same choice on
    both sides of an edge) and length."""
    pairs = np.sort(t[:, [[0, 1], [1, 2], [2, 0]]], axis=2).reshape(-1, 2)
    stride = int(t.max()) + 1 if len(t) else 1
    keys, inverse = np.unique(pairs[:, 0] * stride + pairs[:, 1], return_inverse=True)  # 1-D: 5x np.unique(axis=0)
    unique = np.stack(np.divmod(keys, stride), axis=1)
    idx = inverse.reshape(-1, 3)
    length = np.linalg.norm(w[unique[:, 0]] - w[unique[:, 1]], axis=1)[idx]
    longest = length.max(axis=1)
    rank = np.where(length >= longest[:, None] * (1 - 1e-12), idx, len(unique))
    return idx, unique, idx[np.arange(len(t)), rank.argmin(axis=1)], longest


def _split(t, idx, longest, marked, mid, corners, parent):
    """Each triangle with a marked edge (its longest among them) into 2, 3 or 4 children:
    halves at its longest edge ab (a, m_ab, c), (m_ab, b, c), each halved again at its own
    marked edge ca or bc. Children follow their parent, in order, windings kept."""
    rows = np.arange(len(t))
    k = np.argmax(idx == longest[:, None], axis=1)      # the longest edge's slot: corners k, k + 1
    rot = (k[:, None] + np.arange(3)) % 3
    a, b, c = (t[rows, rot[:, j]] for j in range(3))
    m_ab, m_bc, m_ca = (mid[idx[rows, rot[:, j]]] for j in range(3))
    split = marked[longest]
    first, second = split & (m_ca >= 0), split & (m_bc >= 0)
    # children as corner choices: 0 a, 1 b, 2 c, 3 m_ab, 4 m_bc, 5 m_ca
    choice = np.array([[0, 1, 2], [0, 3, 2], [0, 3, 5], [3, 2, 5], [3, 1, 2], [3, 1, 4], [3, 4, 2]])
    which = np.stack([np.where(split, np.where(first, 2, 1), 0), np.where(first, 3, -1),
                      np.where(split, np.where(second, 5, 4), -1), np.where(second, 6, -1)], axis=1)
    keep = which >= 0
    pick = choice[np.maximum(which, 0)]                  # (M, 4, 3)
    ids = np.stack([a, b, c, m_ab, m_bc, m_ca], axis=1)
    children = np.take_along_axis(ids[:, None, :].repeat(4, axis=1), pick, axis=2)[keep]

    def values(cv):
        va, vb, vc = (cv[rows, rot[:, j]] for j in range(3))
        six = np.stack([va, vb, vc, (va + vb) / 2, (vb + vc) / 2, (vc + va) / 2], axis=1).astype(cv.dtype)
        return np.stack([six[rows[:, None], pick[:, :, j]] for j in range(3)], axis=2)[keep]

    return children, [values(cv) for cv in corners], np.repeat(parent, keep.sum(axis=1))


#: Vertex receivers move this fraction of the way towards the mean centroid of their
#: triangles: a vertex where a floor meets a wall would otherwise see half its hemisphere
#: through the junction (outside the room) and pass on half the light.
VERTEX_INSET = 0.02


def vertex_receivers(surface):
    """World positions (V, 3), nudged off junctions (`VERTEX_INSET`), and area-weighted
    normals (V, 3) of a surface's vertices."""
    world, tris, linear, normal_matrix = placed(surface, surface.name or f"mesh {surface.mesh_id}")
    local = np.asarray(surface.vertices, dtype=np.float64)[tris]
    face = np.cross(local[:, 1] - local[:, 0], local[:, 2] - local[:, 0]) @ normal_matrix.T
    area = np.linalg.norm(np.cross(world[tris][:, 1] - world[tris][:, 0], world[tris][:, 2] - world[tris][:, 0]), axis=1)
    face = face / np.maximum(np.linalg.norm(face, axis=1, keepdims=True), 1e-300) * area[:, None]
    normals = np.zeros_like(world)
    centroids = np.zeros_like(world)
    centroid = world[tris].mean(axis=1)
    for k in range(3):
        np.add.at(normals, tris[:, k], face)
        np.add.at(centroids, tris[:, k], centroid)
    count = np.bincount(tris.ravel(), minlength=len(world))[:, None]
    inset = np.where(count > 0, centroids / np.maximum(count, 1) - world, 0.0)
    return world + VERTEX_INSET * inset, normals
