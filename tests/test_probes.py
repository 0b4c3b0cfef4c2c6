"""Probe grids, the engine part (issue 12): ambient cubes and SH9 at points, without Blender.

Units: irradiance / pi per cube side (a white Lambertian surface facing the axis); sh9 is the
projection of the incident radiance (not divided by pi). Every check looks at the worst
probe. Run from a worktree with PYTHONPATH=native/python when the installed package is
another checkout's.
"""

import math

import numpy as np
import pytest
import trimesh
from trimesh.ray.ray_pyembree import RayMeshIntersector

hemishadow = pytest.importorskip("hemishadow")
import hemishadow.probes as hp  # noqa: E402  (fails, not skips, where it is missing)
from hemishadow.lightmap import Sun, Surface  # noqa: E402


def box(lo, hi, inward=False):
    b = trimesh.creation.box(bounds=[lo, hi])
    faces = np.asarray(b.faces)
    return np.asarray(b.vertices, np.float64), (faces[:, ::-1].copy() if inward else faces)


def scene_of(*meshes):
    scene = hemishadow.Scene()
    ids = []
    for v, t in meshes:
        ids.append(scene.add_mesh(v, t))
        scene.add_instance(ids[-1])
    return scene, ids


def speck():
    """A scene whose only geometry is a 1 mm triangle 1 km away: an open sky."""
    return scene_of((np.array([[1e3, 1e3, -1e3], [1e3 + 1e-3, 1e3, -1e3], [1e3, 1e3 + 1e-3, -1e3]]),
                     np.array([[0, 1, 2]])))[0]


def sky_sh(bands=3, seed=0):
    """A random positive sky: 1 + smaller random higher bands, radiance SH (bands^2, 3)."""
    rng = np.random.default_rng(seed)
    sh = rng.normal(scale=0.25, size=(bands * bands, 3))
    sh[0] = math.sqrt(4 * math.pi)
    return sh


def radiance(sh, directions):
    bands = int(round(math.sqrt(len(sh))))
    return hemishadow.sh_basis(directions.astype(np.float32), bands).astype(np.float64) @ sh


def exact_side(sh, axes):
    """(1/pi) integral of L max(0, w.a) with L band-limited: sum A_l L_lm Y_lm(a) / pi."""
    a = np.repeat([math.pi, 2 * math.pi / 3, math.pi / 4, 0.0, -math.pi / 24][:int(math.sqrt(len(sh)))],
                  2 * np.arange(int(math.sqrt(len(sh)))) + 1)
    return (hemishadow.sh_basis(axes.astype(np.float32), int(math.sqrt(len(sh)))) * a) @ sh / math.pi


# --- units, SH, conversions ----------------------------------------------------------------


def test_uniform_white_sky_gives_one_on_every_side():
    sh = np.zeros((9, 3))
    sh[0] = math.sqrt(4 * math.pi)  # the projection of radiance 1
    pts = np.random.default_rng(1).uniform(-2, 2, (64, 3))
    out = hp.bake(speck(), pts, lighting=sh)
    assert out["valid"].all() and not out["moved"].any()
    assert np.abs(out["cube"] - 1.0).max() < 1e-5
    assert np.abs(out["sh9"] - sh).max() < 1e-5


def test_open_sky_sides_and_sh9_match_band_limited_light():
    sh = sky_sh(bands=5)
    out = hp.bake(speck(), np.zeros((4, 3)), lighting=sh)
    expected = exact_side(sh, hp.AXES)
    assert np.abs(out["cube"] - expected).max() < 2e-3 * np.abs(expected).max()
    # sh9 is the projection of the radiance: the first 9 coefficients of the SH25 sky
    assert np.abs(out["sh9"] - sh[:9]).max() < 1e-3 * np.abs(sh).max()


def test_cube_sh_conversions():
    rng = np.random.default_rng(2)
    sh = rng.normal(size=(5, 9, 3))
    cube = hp.sh_to_cube(sh)
    assert np.allclose(cube, np.stack([exact_side(s, hp.AXES) for s in sh]), atol=1e-6)
    assert np.allclose(hp.sh_to_cube(hp.cube_to_sh(cube)), cube, atol=1e-12)  # exact inverse on cubes
    back = hp.cube_to_sh(cube)
    keep = [0, 1, 2, 3, 6, 8]
    assert np.allclose(back[:, keep], sh[:, keep], atol=1e-12) and not back[:, [4, 5, 7]].any()


def test_n_squared_reconstruction_error_floor():
    """The basis itself: random positive SH9 skies, exact irradiance / pi for random normals
    against n-squared sampling of the exact cube. Floor measured: 15.8 % worst, 3.0 % mean
    relative to the mean irradiance (printed)."""
    rng = np.random.default_rng(3)
    worst, mean = 0.0, []
    for seed in range(20):
        sh = sky_sh(3, seed)
        n = rng.normal(size=(2000, 3))
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        exact = exact_side(sh, n)
        approx = hp.sample(np.broadcast_to(hp.sh_to_cube(sh), (len(n), 6, 3)), n)
        err = np.abs(approx - exact) / exact.mean()
        worst, mean = max(worst, err.max()), mean + [err.mean()]
        # exact on the six axes
        assert np.allclose(hp.sample(np.broadcast_to(hp.sh_to_cube(sh), (6, 6, 3)), hp.AXES),
                           exact_side(sh, hp.AXES), atol=1e-9)
    print(f"n-squared basis floor: worst {worst:.4f}, mean {np.mean(mean):.4f}")
    assert 0.05 < worst < 0.2 and np.mean(mean) < 0.05


# --- visibility against Embree ---------------------------------------------------------------


def embree_probe(vertices, triangles, sh, point, n_side=96, seed=0):
    """Six sides by cosine-distributed rays per axis, and SH9 by uniform rays, with Embree."""
    import reference as ref
    rng = np.random.default_rng(seed)
    caster = RayMeshIntersector(trimesh.Trimesh(vertices, triangles, process=False))
    sides = []
    for a in hp.AXES:
        t, b = ref.orthonormal_basis(a)
        local = ref.stratified_cosine_directions(n_side, rng)
        d = local[:, :1] * t + local[:, 1:2] * b + local[:, 2:3] * a
        hit = caster.intersects_any(np.broadcast_to(point, d.shape), d)
        sides.append((radiance(sh, d) * ~hit[:, None]).mean(0))  # cos/pi pdf: the mean is the side
    d = rng.normal(size=(200000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    hit = caster.intersects_any(np.broadcast_to(point, d.shape), d)
    y = hemishadow.sh_basis(d.astype(np.float32), 3).astype(np.float64)
    sh9 = 4 * math.pi * (y[:, :, None] * (radiance(sh, d) * ~hit[:, None])[:, None]).mean(0)
    return np.array(sides), sh9


def test_probe_beside_a_wall_sees_the_wall():
    """Probes 0.15 to 1 m from a 4 m wall on an open sky: the side facing the wall is darker,
    and all six sides match Embree ray casting of the cosine lobes (worst 1.5 %)."""
    wall = box([0.0, -2.0, -2.0], [0.2, 2.0, 2.0])
    scene, _ = scene_of(wall)
    sh = sky_sh(3, seed=4)
    pts = np.array([[-0.15, 0.0, 0.0], [-0.4, 0.3, -0.5], [-1.0, -0.7, 1.2]])
    out = hp.bake(scene, pts, lighting=sh)
    worst = 0.0
    for k, p in enumerate(pts):
        sides, sh9 = embree_probe(*wall, sh, p, seed=k)
        assert (out["cube"][k, 0] < 0.7 * out["cube"][k, 1]).all()  # +X faces the wall
        worst = max(worst, (np.abs(out["cube"][k] - sides) / sides.mean()).max())
        assert np.abs(out["sh9"][k] - sh9).max() < 0.03 * abs(sh9[0]).max()
    print(f"worst side error against Embree: {worst:.4f}")
    assert worst < 0.02


def test_sun_is_shadowed_by_a_wall():
    wall = box([0.0, -2.0, -2.0], [0.2, 2.0, 2.0])
    scene, _ = scene_of(wall)
    d = np.array([1.0, 0.0, 1.0]) / math.sqrt(2)
    pts = np.array([[-0.5, 0.0, 0.0], [-0.5, 0.0, 3.0], [1.0, 0.0, 0.0]])  # behind, above, sunny side
    out = hp.bake(scene, pts, suns=[Sun(d, strength=math.pi)])
    lit = np.maximum(hp.AXES @ d, 0)  # strength pi: a facing side gets 1.0
    assert np.abs(out["cube"][0]).max() < 1e-6
    assert np.allclose(out["cube"][1:], lit[None, :, None], atol=1e-5)
    y = hemishadow.sh_basis(d[None].astype(np.float32), 3)[0]
    assert np.allclose(out["sh9"][2, :, 0], math.pi * y, atol=1e-5)


@pytest.mark.parametrize("bounces", [0, 1, 2])
def test_bounces_in_a_closed_emissive_room(bounces):
    """A closed room of emission 1 and albedo 0.5: every side holds 1 + 0.5 + ... after N bounces."""
    room = box([-1, -1, -1], [1, 1, 1], inward=True)
    scene, (walls,) = scene_of(room)
    pts = np.array([[0.0, 0.0, 0.0], [0.5, -0.3, 0.2]])
    out = hp.bake(scene, pts, surfaces=[Surface(walls, *room, albedo=0.5, emission=1.0)], bounces=bounces)
    expected = sum(0.5 ** k for k in range(bounces + 1))
    assert np.abs(out["cube"] / expected - 1).max() < 0.03
    assert np.abs(out["sh9"][:, 0] / (expected * math.sqrt(4 * math.pi)) - 1).max() < 0.03


# --- invalid probes ----------------------------------------------------------------------------


def test_invalid_probes_in_a_closed_box_and_in_a_wall():
    """A grid of 1 m cells over a lit floor: one probe sits in the middle of a 2 m solid box
    (no free spot within half a cell: stays invalid, left out, never black), one inside a
    0.2 m wall (moved out by a quarter cell, valid)."""
    solid = box([-1.0, -1.0, 0.0], [1.0, 1.0, 2.0])      # probe (0, 0, 1) at its centre
    wall = box([2.9, -3.0, 0.0], [3.1, 3.0, 3.0])        # probe (3, 0, 1) inside it
    scene, _ = scene_of(solid, wall)
    matrix = np.eye(4)
    matrix[:3, 3] = (-1.0, -1.0, 1.0)
    out = hp.bake_grid(scene, matrix, (6, 3, 1), lighting=sky_sh(3, 5))
    pos = hp.grid_points(matrix, (6, 3, 1))
    inside_box = np.flatnonzero(np.all(np.isclose(pos, [0, 0, 1]), axis=1))[0]
    inside_wall = np.flatnonzero(np.all(np.isclose(pos, [3, 0, 1]), axis=1))[0]
    assert not out["valid"][inside_box] and not out["moved"][inside_box]
    assert out["valid"][inside_wall] and out["moved"][inside_wall]
    moved_by = out["positions"][inside_wall] - pos[inside_wall]
    assert 0 < np.linalg.norm(moved_by) <= 0.5 * math.sqrt(3) + 1e-6 and abs(moved_by[0]) >= 0.1
    assert out["valid"].sum() == len(pos) - 1
    assert out["cube"].max(axis=(1, 2)).min() > 0.1  # never a black cube under the sky
    # without a cell, the probe in the wall stays where it is and is reported invalid
    plain = hp.bake(scene, pos, lighting=sky_sh(3, 5))
    assert not plain["valid"][[inside_box, inside_wall]].any() and not plain["moved"].any()
    assert plain["valid"].sum() < out["valid"].sum()


def test_a_probe_closed_in_by_a_box_without_bottom_and_the_floor_is_invalid():
    """Most of what the probe sees are back faces (the box's walls and roof from inside),
    though the floor below it faces it: invalid. Beside the box, over the same floor: valid."""
    v, t = box([-0.5, -0.5, 0.0], [0.5, 0.5, 1.0])
    t = t[~np.all(np.isclose(v[t][:, :, 2], 0.0), axis=1)]    # no bottom face
    floor = box([-4.0, -4.0, -0.1], [4.0, 4.0, 0.0])
    scene, _ = scene_of((v, t), floor)
    for height in (0.1, 0.5, 0.9):
        out = hp.bake(scene, [[0.0, 0.0, height], [2.0, 0.0, height]], lighting=sky_sh(3, 5))
        assert list(out["valid"]) == [False, True], height


# --- evaluation without leaks ------------------------------------------------------------------


def two_rooms():
    """Room A (x in [-2, 0]) with walls of emission 1, room B (x in [0.1, 2.1]) with walls of
    emission 0.05: closed boxes facing inwards, sharing a 0.1 m wall."""
    a = box([-2.0, -1.0, 0.0], [0.0, 1.0, 2.0], inward=True)
    b = box([0.1, -1.0, 0.0], [2.1, 1.0, 2.0], inward=True)
    scene, (ia, ib) = scene_of(a, b)
    surfaces = [Surface(ia, *a, albedo=0.0, emission=1.0), Surface(ib, *b, albedo=0.0, emission=0.05)]
    world = np.concatenate([a[0][a[1]], b[0][b[1]]])
    return scene, surfaces, world


def test_no_light_leaks_through_a_wall():
    scene, surfaces, world = two_rooms()
    matrix = np.diag([0.5, 0.5, 0.5, 1.0])
    matrix[:3, 3] = (-1.75, -0.5, 0.5)     # x = -1.75 .. 1.75: probes at -0.25 (room A) and 0.25 (room B)
    out = hp.bake_grid(scene, matrix, (8, 3, 3), surfaces=surfaces, bounces=0)
    assert out["valid"].all()
    x = out["positions"][:, 0]
    assert np.abs(out["cube"][x < 0] - 1).max() < 0.03 and np.abs(out["cube"][x > 0.1] / 0.05 - 1).max() < 0.03
    q = np.array([[0.15, 0.1, 1.1], [0.2, -0.3, 0.7], [1.0, 0.2, 1.0]])  # room B, the first two near the wall
    n = np.array([[0.0, 0.0, 1.0]] * 3)
    leaky = hp.evaluate(out, q, n)["value"]
    tight = hp.evaluate(out, q, n, blockers=world)
    print("plain trilinear", leaky[:, 0], "with the visibility rule", tight["value"][:, 0])
    assert (leaky[:2] > 2.5 * 0.05).all()                      # plain trilinear leaks room A's light
    assert np.abs(tight["value"] / 0.05 - 1).max() < 0.03       # room B's light only
    assert not tight["fallback"].any()
    # and room A's side of the wall keeps room A's light
    qa = np.array([[-0.05, 0.0, 1.0]])
    assert abs(hp.evaluate(out, qa, n[:1], blockers=world)["value"][0, 0] - 1) < 0.03


def test_evaluate_skips_invalid_probes_and_reproduces_probes():
    scene = speck()
    matrix = np.eye(4)
    out = hp.bake_grid(scene, matrix, (2, 2, 2), lighting=sky_sh(3, 6))
    q = hp.grid_points(matrix, (2, 2, 2))
    e = hp.evaluate(out, q)
    assert np.allclose(e["cube"], out["cube"], atol=1e-6)
    out["valid"][0] = False
    out["cube"][0] = 0
    e = hp.evaluate(out, q[:1] + 0.1)
    assert e["weights"][0][e["ids"][0] == 0].sum() == 0 and e["cube"].min() > 0.1


# --- grids and files ---------------------------------------------------------------------------


def test_grid_placement_as_blender():
    """Blender puts sample i of N at local (i + 1) / (N + 1) * 2 - 1, C order of (x, y, z)."""
    obj = np.eye(4)
    obj[:3, :3] = np.diag([2.0, 1.0, 3.0]) @ hemishadow.rotation_matrix((0, 0, 1), 0.3)
    obj[:3, 3] = (1.0, 2.0, 3.0)
    res = (3, 1, 2)
    m = hp.volume_matrix(obj, res)
    pts = hp.grid_points(m, res)
    local = np.array([[(i + 1) / 4 * 2 - 1, 0.0, (k + 1) / 3 * 2 - 1] for i in range(3) for k in range(2)])
    assert np.allclose(pts, local @ obj[:3, :3].T + obj[:3, 3])


def test_files_round_trip_and_y_up(tmp_path):
    sh = sky_sh(3, 7)
    out = hp.bake_grid(speck(), np.eye(4), (2, 1, 2), lighting=sh)
    hp.write_npz(tmp_path / "p.npz", out)
    back = hp.read_npz(tmp_path / "p.npz")
    for k in hp.files.KEYS:
        assert np.array_equal(back[k], np.asarray(out[k]).astype(back[k].dtype)), k
    hp.write_json(tmp_path / "p.json", out)
    import json
    data = json.loads((tmp_path / "p.json").read_text())
    assert np.allclose(data["cube"], out["cube"]) and data["side_order"][4] == "+Z" and "n.x^2" in data["shader"]
    assert not list(tmp_path.glob(".hemishadow-*"))  # no temporary file left
    y = hp.y_up(out)
    assert np.allclose(y["cube"], hp.sh_to_cube(y["sh9"]), atol=2e-3)  # the cube of the rotated light
    assert np.allclose(y["positions"][:, 1], out["positions"][:, 2])
    # a list of points round-trips without a grid
    pts = hp.bake(speck(), np.zeros((3, 3)), lighting=sh)
    hp.write_npz(tmp_path / "q.npz", pts)
    assert "grid_matrix" not in hp.read_npz(tmp_path / "q.npz")


# --- bad input ---------------------------------------------------------------------------------


def test_bad_input_raises_clear_errors():
    scene = speck()
    with pytest.raises(ValueError, match="resolution"):
        hp.bake_grid(scene, np.eye(4), (0, 2, 2))
    with pytest.raises(ValueError, match="NaN"):
        hp.bake(scene, np.array([[0.0, np.nan, 0.0]]))
    with pytest.raises(ValueError, match="no probe points"):
        hp.bake(scene, np.zeros((0, 3)))
    with pytest.raises(ValueError, match="no geometry"):
        hp.bake(hemishadow.Scene(), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="lighting"):
        hp.bake(scene, np.zeros((1, 3)), lighting=np.zeros((5, 3)))
    with pytest.raises(hemishadow.Cancelled):
        hp.bake(scene, np.zeros((2, 3)), lighting=sky_sh(), progress=lambda f: False)


def test_probe_lists_evaluate_without_leaks_too():
    """Probes given as a list (no grid): the 8 nearest, 1 / d^2, the same visibility rule."""
    scene, surfaces, world = two_rooms()
    pts = np.array([[x, y, z] for x in (-0.6, -0.2, 0.3, 0.7) for y in (-0.4, 0.4) for z in (0.6, 1.4)])
    out = hp.bake(scene, pts, surfaces=surfaces, bounces=0)
    assert out["valid"].all() and "grid_matrix" not in out
    q = np.array([[0.15, 0.0, 1.0]])
    n = np.array([[0.0, 0.0, 1.0]])
    assert hp.evaluate(out, q, n)["value"][0, 0] > 0.2
    tight = hp.evaluate(out, q, n, blockers=world)
    assert abs(tight["value"][0, 0] / 0.05 - 1) < 0.03 and not tight["fallback"].any()
    # a point that sees no probe at all (inside the shared wall) falls back to valid probes, flagged
    inside = hp.evaluate(out, np.array([[0.05, 0.0, 1.0]]), blockers=world)
    assert inside["fallback"].all()
