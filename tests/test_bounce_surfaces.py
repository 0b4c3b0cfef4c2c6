"""Bounce light carried per vertex (`hemishadow.lightmap.bounce`): meshes split where their
faces meet at sharp edges (`split_sharp_vertices`), and vertices that cannot be lit where
they stand (inside solid geometry, no normal) taking their neighbours' radiance (`fill`)."""

import numpy as np
import pytest

hemishadow = pytest.importorskip("hemishadow")
from hemishadow.lightmap import bounce  # noqa: E402
from hemishadow.lightmap.geometry import split_sharp_vertices, subdivided, subdivision_levels  # noqa: E402


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


def test_subdivision_keeps_the_surface_and_its_interpolation():
    """Each split puts 4 triangles in place of 1 over the same area, shares midpoints between
    neighbours (a closed cube stays closed: V - E + F = 2), and interpolates per-corner and
    per-vertex values linearly: any point of a parent triangle gets the same value from its
    child as from the parent."""
    v, t = cube()
    corner = np.random.default_rng(1).normal(size=(len(t), 3, 2))
    colour = np.random.default_rng(2).uniform(size=(len(v), 3))
    v2, t2, (c2,), (col2,) = subdivided(v, t, 2, [corner], [colour])
    assert t2.shape == (16 * len(t), 3)
    area = lambda p, q: np.linalg.norm(np.cross(p[q[:, 1]] - p[q[:, 0]], p[q[:, 2]] - p[q[:, 0]]), axis=1).sum()
    assert area(v2, t2) == pytest.approx(area(v.astype(float), t))
    edges = np.unique(np.sort(t2[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1), axis=0)
    assert len(v2) - len(edges) + len(t2) == 2
    # Child k of parent p is row 16 p + k: its corners' values are the parent's, interpolated
    # at the corners' barycentric coordinates in the parent.
    for p in range(len(t)):
        a, b, c = v[t[p]].astype(float)
        m = np.stack([b - a, c - a], axis=1)
        for k in range(16):
            for j in range(3):
                x = v2[t2[16 * p + k, j]]
                beta, gamma = np.linalg.lstsq(m, x - a, rcond=None)[0]
                w = np.array([1 - beta - gamma, beta, gamma])
                np.testing.assert_allclose(c2[16 * p + k, j], w @ corner[p], atol=1e-12)
                np.testing.assert_allclose(col2[t2[16 * p + k, j]], w @ colour[t[p]], atol=1e-12)
    assert subdivided(v, t, 1, [], [np.array([0.8, 0.8, 0.8])])[3][0].shape == (3,)  # a constant stays


def test_subdivision_levels_follow_the_longest_edge_within_a_budget():
    v, t = cube()
    assert subdivision_levels(v, t, 2.0) == 0
    assert subdivision_levels(v, t, 0.5) == 2  # the faces' diagonals, sqrt 2, need two halvings
    assert subdivision_levels(v * 10, t, 0.5) == 5
    assert subdivision_levels(v * 10, t, 0.5, max_triangles=12 * 4 ** 3) == 3
    assert subdivision_levels(v, t, 0.0) == 0 and subdivision_levels(v, t[:0], 0.5) == 0
