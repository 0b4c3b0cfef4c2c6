"""Bounce light carried per vertex (`hemishadow.lightmap.bounce`): meshes split where their
faces meet at sharp edges (`split_sharp_vertices`), and vertices that cannot be lit where
they stand (inside solid geometry, no normal) taking their neighbours' radiance (`fill`)."""

import numpy as np
import pytest

hemishadow = pytest.importorskip("hemishadow")
from hemishadow.lightmap import bounce  # noqa: E402
from hemishadow.lightmap.geometry import bisected, split_sharp_vertices  # noqa: E402


def cube():
    v = np.array([[x, y, z] for z in (0.0, 1.0) for y in (0.0, 1.0) for x in (0.0, 1.0)], np.float32)
    quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    return v, np.array([t for q in quads for t in ([q[0], q[1], q[2]], [q[0], q[2], q[3]])])


def face_normals(v, t):
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_a_flat_shaded_cube_gets_four_vertices_per_face():
    v, t = cube()
    corner_normals = np.repeat(face_normals(v, t)[:, None], 3, axis=1)
    tris, source = split_sharp_vertices(t, corner_normals)
    assert len(source) == 24 and tris.shape == t.shape
    np.testing.assert_array_equal(v[source][tris], v[t])  # the same triangles, corner by corner
    for face in range(6):  # each face's two triangles share their vertices, and no other face does
        own = set(tris[2 * face:2 * face + 2].ravel())
        assert len(own) == 4
        assert not own & set(np.delete(tris, [2 * face, 2 * face + 1], axis=0).ravel())


def test_smooth_corners_stay_one_vertex():
    v, t = cube()
    smooth = v[t] - 0.5
    smooth /= np.linalg.norm(smooth, axis=2, keepdims=True)  # one normal per vertex, as Blender gives
    tris, source = split_sharp_vertices(t, smooth)
    np.testing.assert_array_equal(source, np.arange(8))
    np.testing.assert_array_equal(tris, t)
    signed_zero = smooth.copy()
    signed_zero[smooth == 0.0] = -0.0
    assert len(split_sharp_vertices(t, signed_zero)[1]) == 8


def test_fill_grows_from_the_known_vertices():
    # A strip of quads: 0-1-2-3 along the bottom, 4-5-6-7 along the top.
    t = np.array([[0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [8, 9, 10]])
    values = np.arange(11, dtype=np.float32)[:, None].repeat(3, axis=1)
    known = np.array([True, True, False, False, True, True, False, False, False, False, False])
    out = bounce.fill(values, known, t)
    np.testing.assert_array_equal(out[[0, 1, 4, 5, 8, 9, 10]], values[[0, 1, 4, 5, 8, 9, 10]])  # known, unreached
    # Ring 1: 2 (neighbours 1, 3, 6, 7; known: 1) and 6 (1, 2, 5, 7; known: 1, 5).
    assert out[2, 0] == 1.0 and out[6, 0] == 3.0
    # Ring 2: 3 (2, 7; known now: 2) and 7 (2, 3, 6; known now: 2, 6).
    assert out[3, 0] == 1.0 and out[7, 0] == 2.0
    np.testing.assert_array_equal(bounce.fill(values, known, None), values)


def test_a_vertex_inside_a_wall_takes_its_neighbours_light():
    """A lit floor (4 x 4, subdivided) passing under a wall: the vertices inside the wall are
    not lit where they stand (inside solid geometry they would see the wall's inside); they
    take their neighbours' radiance, so the floor's light is not cut dark (or bright) at the
    wall, and the wall's inside is not what the floor passes on."""
    n = 8
    g = np.linspace(-2, 2, n + 1)
    x, y = np.meshgrid(g, g)
    floor = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1).astype(np.float32)
    quads = np.array([[i * (n + 1) + j, i * (n + 1) + j + 1, (i + 1) * (n + 1) + j + 1, (i + 1) * (n + 1) + j]
                      for i in range(n) for j in range(n)])
    floor_tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]).astype(np.uint32)
    wall, wall_tris = cube()
    wall = wall * [0.6, 5.0, 2.0] + [0.7, -2.5, -0.5]  # x 0.7..1.3: floor vertices at x = 1.0 are inside
    scene = hemishadow.Scene()
    ids = [scene.add_mesh(floor, floor_tris), scene.add_mesh(wall.astype(np.float32), wall_tris.astype(np.uint32))]
    for m in ids:
        scene.add_instance(m, np.eye(4))
    up = np.tile([0.0, 0.0, 1.0], (len(floor), 1)).astype(np.float32)
    receivers = [bounce.BounceSurface(ids[0], floor.astype(np.float64), up, np.ones(len(floor), bool),
                                      np.full((len(floor), 3), 0.5), np.zeros((len(floor), 3)), floor_tris)]
    glow = bounce.BounceSurface(ids[1], wall.astype(np.float64), wall - wall.mean(axis=0), np.ones(len(wall), bool),
                                np.zeros((len(wall), 3)), np.full((len(wall), 3), 10.0), wall_tris)
    receivers.append(glow)  # a glowing wall, inside too
    direct = [np.ones((len(floor), 3), np.float32), np.zeros((len(wall), 3), np.float32)]
    record = bounce.VertexRecord(scene, receivers)
    inside = np.isclose(floor[:, 0], 1.0)
    np.testing.assert_array_equal(~record.lit_of(0), inside)
    radiance = bounce.vertex_radiance(scene, receivers, direct, 1, record=record)[0]
    beside = np.isclose(floor[:, 0], 0.5) | np.isclose(floor[:, 0], 1.5)  # their neighbours
    assert radiance[beside].min() > 0.6  # lit, and lit by the glowing wall
    # Lit where they stand they would see the glowing inside all round: 0.5 x (1 + 10).
    assert np.all(radiance[inside] <= radiance[beside].max() + 1e-6)
    assert np.all(radiance[inside] >= radiance[beside].min() - 1e-6)


def _edges(t):
    return np.unique(np.sort(t[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1), axis=0)


def test_bisection_keeps_the_surface_closed_and_its_interpolation():
    """Longest-edge bisection of a closed cube until no edge is longer than 0.3: the same area,
    still closed (V - E + F = 2, every edge in two triangles) and wound alike, and per-corner and
    per-vertex values interpolated linearly: each child's corners get their parent's values at
    their barycentric coordinates in the parent."""
    v, t = cube()
    corner = np.random.default_rng(1).normal(size=(len(t), 3, 2))
    colour = np.random.default_rng(2).uniform(size=(len(v), 3))
    v2, t2, (c2,), (col2,), parent = bisected(v, t, 0.3, None, [corner], [colour])
    area = lambda p, q: np.cross(p[q[:, 1]] - p[q[:, 0]], p[q[:, 2]] - p[q[:, 0]])
    assert np.linalg.norm(area(v2, t2), axis=1).sum() == pytest.approx(np.linalg.norm(area(v.astype(float), t), axis=1).sum())
    edges = _edges(t2)
    assert len(v2) - len(edges) + len(t2) == 2
    assert np.linalg.norm(v2[edges[:, 0]] - v2[edges[:, 1]], axis=1).max() <= 0.3
    directed = t2[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2)
    assert len(np.unique(directed, axis=0)) == len(directed)  # each edge once each way: consistent winding
    np.testing.assert_array_less(0, (area(v2, t2) * area(v.astype(float), t)[parent]).sum(axis=1))
    for child in range(len(t2)):
        p = parent[child]
        a, b, c = v[t[p]].astype(float)
        m = np.stack([b - a, c - a], axis=1)
        for j in range(3):
            beta, gamma = np.linalg.lstsq(m, v2[t2[child, j]] - a, rcond=None)[0]
            w = np.array([1 - beta - gamma, beta, gamma])
            np.testing.assert_allclose(c2[child, j], w @ corner[p], atol=1e-12)
            np.testing.assert_allclose(col2[t2[child, j]], w @ colour[t[p]], atol=1e-12)
    assert bisected(v, t, 0.5, None, [], [np.array([0.8, 0.8, 0.8])])[3][0].shape == (3,)  # a constant stays


def test_each_triangle_splits_as_much_as_its_own_edges_need():
    """A large and a small triangle of one mesh, apart: the small one (edges up to 0.42) stays
    whole under max edge 0.5 while the large one splits until its edges are short enough
    (splitting a mesh a number of times set by its longest edge split both). Lengths are in
    world units: scaled 2x, the small one splits too."""
    v = np.array([[0.0, 0, 0], [4, 0, 0], [0, 4, 0], [10, 0, 0], [10.3, 0, 0], [10, 0.3, 0]])
    t = np.array([[0, 1, 2], [3, 4, 5]])
    v2, t2, _, _, parent = bisected(v, t, 0.5)
    assert np.count_nonzero(parent == 1) == 1 and np.count_nonzero(parent == 0) > 64
    assert np.linalg.norm(np.diff(v2[t2[parent == 0]][:, [0, 1, 2, 0]], axis=1), axis=2).max() <= 0.5
    assert np.count_nonzero(bisected(v, t, 0.5, world=2 * v)[4] == 1) > 1


def test_bisection_stops_within_its_budget_and_without_a_length():
    v, t = cube()
    assert len(bisected(v, t, 0.01, max_triangles=500)[1]) <= 500
    same = bisected(v, t, 0.0)
    assert np.array_equal(same[1], t) and np.array_equal(same[0], v)
    assert len(bisected(v, t, 2.0)[1]) == len(t)  # the longest edge, a face's diagonal sqrt 2, is short enough


