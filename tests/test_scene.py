"""Scene visibility (issue 10): many meshes and instances shadowing arbitrary receivers.

Accuracy against dense Embree ray casting of the whole scene (tests/scene_reference.py) for
three kinds of receivers; validity inside closed meshes and in open concave corners; instances
against transformed copies; set_vertices / set_matrix against a fresh scene; agreement with
`hemishadow.transfer` on a one-mesh scene; ordered gather against ray-cast first hits; input
checks. Per-kind numbers are printed (pytest -s).
"""

import math

import numpy as np
import pytest
import reference as ref
import scene_reference as sref
from meshes import grid, load_asset

hemishadow = pytest.importorskip("hemishadow")

# The issue asks for a 3 % median and a 5 % mean. Measured (lod 0.15, 1 x 1 blocks, plane
# table 256, pinholes closed, proxies pushed out by 0.25 x their error): objects 2.0 % / 2.1 %,
# surfaces 1.4 % / 1.7 %, open air 2.2 % / 2.1 %. With every triangle (lod 0) the errors are
# larger (2.2 / 1.5 / 2.7 % median): far triangles smaller than the plane table's rounding
# cover cells spuriously, and proxies have fewer of them and fewer seams. Before (2 x 2 blocks,
# table 128, proxies pushed out by their whole error): 3.5 / 2.7 / 4.8 %.
# Bounds: the measured values with a margin, within the issue's.
BOUNDS = {"objects": (0.025, 0.026), "surfaces": (0.018, 0.021), "open_air": (0.027, 0.026)}
LOD_MARGIN = 0.005  # the default lod's median error may exceed every triangle's by this much
RECEIVERS = 200


def y_up(scale=1.0, at=(0.0, 0.0, 0.0), mirror=False):
    """Matrix taking a Y-up asset to Z-up, scaled, optionally mirrored in x, then moved."""
    m = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])
    s = np.diag([-scale if mirror else scale, scale, scale, 1.0])
    t = np.eye(4)
    t[:3, 3] = at
    return t @ s @ m


def cube():
    box = np.array([[x, y, z] for z in (-0.5, 0.5) for y in (-0.5, 0.5) for x in (-0.5, 0.5)])
    quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    return box, np.array([t for q in quads for t in ([q[0], q[1], q[2]], [q[0], q[2], q[3]])])


def welded(name):
    v, t = load_asset(name)
    v, t, _ = ref.weld(v, t)
    return v, t


def translation(x, y, z):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def room():
    """A floor, a wall, spot (twice, once mirrored), the bunny, the teapot and a box."""
    world = sref.WorldScene()
    floor = world.add_mesh(*grid(3.0, 25))
    world.add_instance(floor, np.eye(4))
    wall = np.array([[0, 0, 1.0, -2.5], [0, 1.0, 0, 0], [-1.0, 0, 0, 0], [0, 0, 0, 1]])  # floor stood up, facing +x
    world.add_instance(floor, wall @ translation(-3.0, 0, 0))
    spot = world.add_mesh(*welded("spot.obj"))
    world.add_instance(spot, y_up(1.0, (0.0, 0.0, 0.737)))
    world.add_instance(spot, y_up(1.0, (1.5, 1.2, 0.737), mirror=True))
    bunny = world.add_mesh(*welded("bunny.obj"))
    world.add_instance(bunny, y_up(8.0, (-1.2, 1.3, -0.26)))
    teapot = world.add_mesh(*welded("teapot.obj"))
    world.add_instance(teapot, y_up(0.25, (1.3, -1.3, 0.0)))
    box = world.add_mesh(*cube())
    world.add_instance(box, translation(-1.2, -1.4, 0.4) @ np.diag([0.8, 0.8, 0.8, 1.0]))
    return world


@pytest.fixture(scope="module")
def scene_pair():
    world = room()
    scene = world.engine(hemishadow)
    verts, tris, _ = world.flattened()
    return world, scene, verts, tris


def receivers_on_objects(world, rng):
    """Vertices of the placed objects (not the floor) with their normals."""
    points, normals = [], []
    for mesh, m in world.instances[2:]:
        v, t = world.meshes[mesh]
        n = ref.vertex_normals(v, t)
        pick = rng.choice(len(v), min(len(v), RECEIVERS // 5), replace=False)
        points.append(v[pick] @ m[:3, :3].T + m[:3, 3])
        nw = n[pick] @ np.linalg.inv(m[:3, :3])  # normals transform by the inverse transpose
        normals.append(nw / np.linalg.norm(nw, axis=1, keepdims=True))
    return np.concatenate(points), np.concatenate(normals)


def receivers_on_surfaces(verts, tris, rng):
    """Random points of random triangles (area-weighted) with the face normals."""
    a, b, c = (verts[tris[:, k]] for k in range(3))
    cross = np.cross(b - a, c - a)
    area = np.linalg.norm(cross, axis=1)
    pick = rng.choice(len(tris), RECEIVERS, p=area / area.sum())
    u, v = rng.random((2, RECEIVERS))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    points = a[pick] + u[:, None] * (b - a)[pick] + v[:, None] * (c - a)[pick]
    return points, cross[pick] / area[pick, None]


def receivers_in_open_air(rng):
    """Points above the floor, away from the objects, with normals along each axis."""
    points = np.column_stack([rng.uniform(-2.3, 2.8, RECEIVERS), rng.uniform(-2.8, 2.8, RECEIVERS),
                              rng.uniform(0.05, 1.5, RECEIVERS)])
    axes = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float64)
    return points, axes[np.arange(RECEIVERS) % 6]


def outside(world, points):
    """Points outside every closed object (trimesh's inside test on the watertight ones)."""
    import trimesh

    keep = np.ones(len(points), dtype=bool)
    for mesh, m in world.instances:
        v, t = world.meshes[mesh]
        tm = trimesh.Trimesh(v @ m[:3, :3].T + m[:3, 3], t if np.linalg.det(m[:3, :3]) > 0 else t[:, ::-1], process=False)
        if tm.is_watertight:
            keep &= ~tm.contains(points)
    return keep


@pytest.mark.parametrize("kind", ["objects", "surfaces", "open_air"])
def test_transfer_matches_ray_casting(scene_pair, kind):
    world, scene, verts, tris = scene_pair
    rng = np.random.default_rng({"objects": 1, "surfaces": 2, "open_air": 3}[kind])
    if kind == "objects":
        points, normals = receivers_on_objects(world, rng)
    elif kind == "surfaces":
        points, normals = receivers_on_surfaces(verts, tris, rng)
    else:
        points, normals = receivers_in_open_air(rng)
        keep = outside(world, points)
        points, normals = points[keep], normals[keep]
    offset = 1e-4 * scene.size
    T = scene.transfer(points, normals)
    T_ref, ao_ref = sref.transfer_reference(verts, tris, points, normals, offset=offset)
    summary = ref.error_summary(T, T_ref, ao_ref)
    print(f"\n{kind}: median {summary['median']:.4f} mean (AO>=0.1) {summary['mean']:.4f} p95 {summary['p95']:.4f}"
          f" receivers {summary['n_vertices']} blockers/receiver {scene.blockers_per_receiver:.0f}")
    median_bound, mean_bound = BOUNDS[kind]
    assert summary["median"] <= median_bound
    assert summary["mean"] <= mean_bound
    exact_scene = world.engine(hemishadow, lod=0)
    exact = ref.error_summary(exact_scene.transfer(points, normals), T_ref, ao_ref)
    print(f"  every triangle (lod 0): median {exact['median']:.4f}, blockers/receiver {exact_scene.blockers_per_receiver:.0f}")
    assert summary["median"] <= exact["median"] + LOD_MARGIN
    ao = scene.ambient_occlusion(points, normals)
    assert np.abs(ao - T[:, 0] / ref.AO_SCALE).max() < 1e-5


def test_masks_match_rays_through_the_cells(scene_pair):
    """Cell by cell against a ray through each cell's centre: catches a missing instance or a
    wrong transform, which the SH error would blur."""
    world, scene, verts, tris = scene_pair
    import trimesh
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    intersector = RayMeshIntersector(trimesh.Trimesh(verts, tris, process=False))
    c = (np.arange(32) + 0.5) / 16 - 1
    x, y = (a.ravel() for a in np.meshgrid(c, c))
    inner = x * x + y * y < 0.95  # rim cells sample their in-disk part's centroid
    local = np.column_stack([x, y, np.sqrt(np.maximum(0.0, 1 - x * x - y * y))])[inner]
    points, normals = receivers_in_open_air(np.random.default_rng(7))
    keep = outside(world, points)
    points, normals = points[keep][:60], normals[keep][:60]
    blocked = np.unpackbits(scene.visibility(points, normals).view(np.uint8), axis=1, bitorder="little").astype(bool)
    offset = 1e-4 * scene.size
    missed = []
    for p, n, mask in zip(points, normals, blocked):
        t, b = ref.orthonormal_basis(n[None])  # the engine's frame (Duff et al. 2017)
        dirs = local[:, :1] * t + local[:, 1:2] * b + local[:, 2:] * n
        hit = intersector.intersects_any(np.repeat((p + offset * n)[None], len(dirs), 0), dirs)
        missed.append((hit != mask[inner]).mean())
    print(f"\ncells differing from rays: mean {np.mean(missed):.4f} max {np.max(missed):.4f}")
    assert np.mean(missed) < 0.01 and np.max(missed) < 0.04  # measured 0.0047 and 0.022


def test_closed_meshes_flag_their_inside(scene_pair):
    world, scene, verts, tris = scene_pair
    candidates = np.array([[0.0, 0.2, 0.0], [0.0, 0.3, -0.2], [0.0, 0.2, 0.3], [0.1, 0.1, -0.1]])  # spot's body, Y-up
    spot_inside = candidates[load_trimesh(world, 1).contains(candidates)]
    assert len(spot_inside) >= 3
    points = [y_up(1.0, (0.0, 0.0, 0.737)) @ np.append(p, 1) for p in spot_inside]
    points += [y_up(1.0, (1.5, 1.2, 0.737), mirror=True) @ np.append(p, 1) for p in spot_inside]
    points = np.array([p[:3] for p in points] + [[-1.2, -1.4, 0.4], [-1.0, -1.2, 0.2], [-1.45, -1.6, 0.7]])
    for normal in np.eye(3).tolist() + (-np.eye(3)).tolist():
        valid = scene.valid(points, np.tile(normal, (len(points), 1)))
        assert not valid.any(), (normal, valid)


def load_trimesh(world, mesh):
    import trimesh

    return trimesh.Trimesh(*world.meshes[mesh], process=False)


def test_open_concave_corners_stay_valid(scene_pair):
    _, scene, _, _ = scene_pair
    e = 0.01
    # floor meets wall (x = -2.5), floor meets the box, the box's top under nothing
    points = np.array([[-2.5 + e, 0.0, e], [-2.5 + e, -2.0, e], [-2.5 + e, 0.5, 1.0], [-0.8 + e, -1.4, e],
                       [-1.2, -1.0 + e, e], [-1.2, -1.4, 0.8 + e], [0.5, -2.5, e]])
    for normal in ([0, 0, 1], [1, 0, 0], [0.7, 0, 0.7], [0, 1, 0], [0.5, 0.5, 0.7]):
        assert scene.valid(points, np.tile(normal, (len(points), 1))).all(), normal


def suzanne():
    bpy = pytest.importorskip("bpy")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_monkey_add()
    mesh = bpy.context.active_object.data
    mesh.calc_loop_triangles()
    v = np.array([x.co[:] for x in mesh.vertices])
    t = np.array([lt.vertices[:] for lt in mesh.loop_triangles])
    return v, t


def test_suzanne_and_a_mirrored_cube_flag_their_inside():
    scene = hemishadow.Scene()
    head = scene.add_mesh(*suzanne())
    scene.add_instance(head, translation(0, 0, 2))
    box = scene.add_mesh(*cube())
    scene.add_instance(box, translation(3, 0, 0) @ np.diag([-1.0, 2.0, 1.0, 1.0]))
    inside = np.array([[0, 0.1, 2.2], [0.3, 0.1, 2.0], [-0.3, 0.0, 1.8], [3.1, 0.4, 0.0], [2.9, -0.7, 0.2]])
    outside = np.array([[0, -1.5, 2.0], [0, 0, 0.5], [4.0, 0, 0], [3.0, 0, 0.6], [0, 0, 3.2]])
    for normal in np.eye(3).tolist() + (-np.eye(3)).tolist():
        n = np.tile(normal, (5, 1))
        assert not scene.valid(inside, n).any(), normal
        assert scene.valid(outside, n).all(), normal


def test_instances_equal_transformed_copies():
    v, t = welded("spot.obj")
    matrices = [y_up(1.0, (0, 0, 0.7)), y_up(0.8, (1.2, 0.3, 0.6), mirror=True),
                np.array([[0, -1.2, 0, -1.0], [1.2, 0, 0, 0.5], [0, 0, 1.2, 0.8], [0, 0, 0, 1]])]
    shared, copied = hemishadow.Scene(lod=0), hemishadow.Scene(lod=0)
    mesh = shared.add_mesh(v, t)
    for m in matrices:
        shared.add_instance(mesh, m)
        copied.add_instance(copied.add_mesh(v @ m[:3, :3].T + m[:3, 3], t if np.linalg.det(m) > 0 else t[:, ::-1]))
    rng = np.random.default_rng(5)
    points = rng.uniform([-2, -1.5, 0], [2.5, 2, 1.5], (150, 3))
    normals = rng.normal(size=(150, 3))
    a, b = shared.transfer(points, normals), copied.transfer(points, normals)
    assert np.abs(a - b).max() < 1e-2 and np.percentile(np.abs(a - b), 99) < 1e-3  # rounding flips a few cells
    assert (shared.valid(points, normals) == copied.valid(points, normals)).all()
    shared.lod = copied.lod = hemishadow.Scene().lod  # proxies differ (built in different spaces), results not much
    a, b = shared.transfer(points, normals), copied.transfer(points, normals)
    assert np.median(ref.relative_l2_errors(a, b)) < 0.01
    assert np.abs(a[:, 0] - b[:, 0]).max() / ref.AO_SCALE < 0.05


@pytest.mark.parametrize("lod", [0.0, None])
def test_moving_meshes_match_a_fresh_scene(lod):
    v, t = welded("spot.obj")
    floor_v, floor_t = grid(2.0, 9)
    bent = v + 0.1 * np.sin(3 * v[:, [1, 2, 0]])
    start, end = y_up(1.0, (0, 0, 0.74)), y_up(0.9, (0.3, -0.2, 0.8))
    live = hemishadow.Scene(lod=lod)
    floor, spot = live.add_mesh(floor_v, floor_t), live.add_mesh(v, t)
    live.add_instance(floor)
    moving = live.add_instance(spot, start)
    rng = np.random.default_rng(2)
    points = np.column_stack([rng.uniform(-1.5, 1.5, 100), rng.uniform(-1.5, 1.5, 100), np.zeros(100)])
    up = np.tile([0.0, 0, 1], (100, 1))
    before = live.transfer(points, up)
    live.set_vertices(spot, bent)
    live.set_matrix(moving, end)
    after = live.transfer(points, up)
    fresh = hemishadow.Scene(lod=lod)
    fresh.add_instance(fresh.add_mesh(floor_v, floor_t))
    fresh.add_instance(fresh.add_mesh(bent, t), end)
    expected = fresh.transfer(points, up)
    assert np.abs(after - before).max() > 0.05  # the change shows
    if lod == 0.0:
        assert np.abs(after - expected).max() < 1e-5
    else:  # the live scene keeps its first clusters and proxies, refitted
        assert np.median(ref.relative_l2_errors(after, expected)) < 0.02
        assert np.abs(after[:, 0] - expected[:, 0]).max() / ref.AO_SCALE < 0.05


def test_one_mesh_scene_agrees_with_transfer_at_vertices():
    v, t = welded("spot.obj")
    v = v.astype(np.float32)
    normals = ref.vertex_normals(v, t).astype(np.float32)
    scene = hemishadow.Scene()
    scene.add_instance(scene.add_mesh(v, t))
    ao_scene = scene.ambient_occlusion(v, normals)
    ao_mesh = hemishadow.ambient_occlusion(hemishadow.transfer(v, t, normals))
    diff = ao_scene - ao_mesh
    print(f"\nAO scene - mesh: mean {diff.mean():.4f} median {np.median(diff):.4f} p95 |diff| {np.percentile(np.abs(diff), 95):.4f}")
    assert abs(diff.mean()) < 0.01 and abs(np.median(diff)) < 0.01
    assert np.percentile(np.abs(diff), 95) < 0.05


def glowing_room():
    world = sref.WorldScene()
    floor_v, floor_t = grid(2.0, 12)
    floor = world.add_mesh(floor_v, floor_t)
    world.add_instance(floor, np.eye(4))
    world.radiance[floor] = np.column_stack([0.5 + 0.25 * floor_v[:, 0], np.full(len(floor_v), 0.2), 0.5 - 0.2 * floor_v[:, 1]])
    roof = np.diag([1.0, 1.0, -1.0, 1.0])
    roof[2, 3] = 1.5
    world.add_instance(floor, roof)
    v, t = welded("spot.obj")
    spot = world.add_mesh(v, t)
    world.add_instance(spot, y_up(1.0, (0.3, 0.2, 0.74)))
    world.radiance[spot] = np.column_stack([np.full(len(v), 1.0), 0.5 + 0.5 * v[:, 1], np.zeros(len(v))])
    return world


@pytest.mark.parametrize("probes", [True, False])
def test_gather_matches_first_hits(probes):
    world = glowing_room()
    scene = world.engine(hemishadow)
    verts, tris, radiance = world.flattened()
    points = np.array([[-1.0, -1.0, 0.7], [1.2, 0.9, 0.4], [-0.5, 1.0, 1.2], [0.9, -0.8, 0.9]])
    normals = None if probes else np.array([[0.3, 0.4, 0.8], [-1.0, 0.0, 0.0], [0.0, -1.0, -0.3], [0.0, 0.0, -1.0]])
    g = scene.gather(points, normals, bands=3)
    g_ref = sref.gather_reference(verts, tris, radiance, points, normals, offset=1e-4 * scene.size, bands=3)
    assert g.shape == (4, 9, 3) and g.dtype == np.float32
    err = np.linalg.norm(g - g_ref, axis=1) / np.linalg.norm(g_ref, axis=1)  # per point and channel
    print(f"\ngather ({'probes' if probes else 'hemispheres'}): relative L2 per channel median {np.median(err):.4f} max {err.max():.4f}")
    # Cells are 1/804 of the disk: small coloured features near the horizon alias. Measured
    # (lod 0.15): hemispheres 3.8 % median, 8.5 % max; probes 6.1 % / 9.0 %.
    assert np.median(err) < 0.07 and err.max() < 0.11


def test_bounce_weights_give_the_gather_under_any_radiance():
    """Recorded once, the weights give `gather` + the lobe along each normal for whatever
    radiance the scene shows later, per-instance radiance and a mirrored instance included,
    and their walk's masks are `visibility`'s; a scene whose vertices or instances changed
    is refused."""
    from hemishadow.lightmap.bounce import lobe_irradiance
    world = glowing_room()
    scene = world.engine(hemishadow)
    rng = np.random.default_rng(5)
    points = rng.uniform([-1.0, -1.0, 0.05], [1.0, 1.0, 1.4], (300, 3))
    normals = rng.normal(size=(300, 3))
    weights = scene.bounce_weights(points, normals)
    assert len(weights) == 300 and weights.entries > 300
    # The walk's masks are a radiance walk's, which draws proxies only where they are small
    # in angle (`visibility` also where their error is small); with every triangle drawn
    # they are `visibility`'s but for a rare cell where the ordered mode closes a pinhole
    # the mask walk does not.
    fine = world.engine(hemishadow)
    fine.lod = 0.0
    differ = np.unpackbits((fine.bounce_weights(points, normals).masks ^ fine.visibility(points, normals)).view(np.uint8))
    assert differ.sum() <= 3, differ.sum()
    coarse = scene.visibility(points, normals)
    cells = np.unpackbits((weights.masks ^ coarse).view(np.uint8)).sum() / np.unpackbits(coarse.view(np.uint8)).sum()
    assert cells < 0.01, cells  # the proxies' silhouettes
    # Validity from the same walk is `valid`'s (a few receivers lie inside the cow).
    inside = ~fine.valid(points, normals)
    assert inside.any() and np.array_equal(fine.bounce_weights(points, normals).valid, ~inside)
    np.testing.assert_array_equal(weights.valid, scene.valid(points, normals))
    counts = {m: len(world.meshes[m][0]) for m in range(len(world.meshes))}
    for trial in range(3):
        for m, n in counts.items():
            scene.set_radiance(m, rng.uniform(0, 2, (n, 3)))
        if trial == 2:  # the mirrored roof glows on its own
            scene.set_radiance(0, rng.uniform(0, 5, (counts[0], 3)), instance_id=1)
        expected = lobe_irradiance(scene.gather(points, normals, bands=3), (normals / np.linalg.norm(normals, axis=1, keepdims=True))[:, None])[:, 0]
        got = weights.irradiance()
        assert got.shape == (300, 3) and got.dtype == np.float32
        np.testing.assert_allclose(got, expected, atol=2e-5 * expected.max())
        assert (expected > 0.01).mean() > 0.5  # most receivers see something lit
    spot = world.meshes[1][0]
    scene.set_vertices(1, spot + [0.0, 0.0, 0.05])               # the same vertex count, moved
    with pytest.raises(ValueError, match="changed since these bounce weights"):
        weights.irradiance()
    again = scene.bounce_weights(points, normals)
    scene.add_instance(1, y_up(1.0, (-0.6, -0.5, 0.74)))
    with pytest.raises(ValueError, match="changed since these bounce weights"):
        again.irradiance()
    other = world.engine(hemishadow).bounce_weights(points, normals)
    with pytest.raises(ValueError, match="another scene"):                # the engine's guard
        scene._native.apply_bounce_weights(other._native)


def test_bounce_passes_agree_with_and_without_recorded_weights(monkeypatch):
    """`vertex_radiance` reuses recorded weights; past its memory budget it gathers every
    pass: both give the same radiance."""
    from hemishadow.lightmap import bounce
    world = glowing_room()
    rng = np.random.default_rng(6)
    receivers, direct = [], []
    for m, (v, t) in enumerate(world.meshes):
        normals = np.tile([0.0, 0.0, 1.0], (len(v), 1)) if m == 0 else rng.normal(size=(len(v), 3))
        usable = rng.random(len(v)) > 0.1
        receivers.append(bounce.BounceSurface(m, v + 0.0, normals, usable, np.full((len(v), 3), 0.7),
                                              np.zeros((len(v), 3))))
        direct.append(rng.uniform(0, 1, (len(v), 3)).astype(np.float32))
    recorded = bounce.vertex_radiance(world.engine(hemishadow), receivers, direct, 3)
    monkeypatch.setattr(bounce, "MAX_WEIGHT_ENTRIES", 0)
    gathered = bounce.vertex_radiance(world.engine(hemishadow), receivers, direct, 3)
    for r, g in zip(recorded, gathered):
        np.testing.assert_allclose(r, g, atol=1e-5)
    assert max(np.abs(r - 0.7 * d).max() for r, d in zip(recorded, direct)) > 0.05  # bounce light was added


def test_visibility_masks_are_the_transfer_masks():
    scene = room().engine(hemishadow)
    points, normals = np.array([[0.5, -0.5, 0.01], [-2.0, 0.0, 0.5]]), np.array([[0, 0, 1.0], [1.0, 0, 0]])
    masks = scene.visibility(points, normals)
    assert masks.shape == (2, 16) and masks.dtype == np.uint64
    cells = hemishadow.disk_cells().ravel()
    blocked = np.unpackbits(masks.view(np.uint8), axis=1, bitorder="little").astype(bool)
    assert not (blocked & ~cells).any()
    ao = scene.ambient_occlusion(points, normals)
    assert np.allclose(1 - blocked.sum(1) / cells.sum(), ao, atol=0.03)


def test_bad_input_raises_value_errors():
    scene = hemishadow.Scene()
    v, t = cube()
    with pytest.raises(ValueError, match="mesh id"):
        scene.add_instance(0)
    mesh = scene.add_mesh(v, t)
    bad_matrices = [np.eye(3), np.full((4, 4), np.nan), np.diag([1.0, 0, 1, 1]), np.vstack([np.eye(4)[:3], [1, 0, 0, 1]]),
                    np.eye(4).astype(bool)]
    for m in bad_matrices:
        with pytest.raises(ValueError):
            scene.add_instance(mesh, m)
    scene.add_instance(mesh, np.eye(4, dtype=np.float32))
    for call in [lambda: scene.add_mesh(v, t + 8), lambda: scene.add_mesh(v[:, :2], t), lambda: scene.add_mesh(v, t[:0]),
                 lambda: scene.set_vertices(mesh, v[:7]), lambda: scene.set_vertices(1, v), lambda: scene.set_vertices(True, v),
                 lambda: scene.set_matrix(1, np.eye(4)), lambda: scene.set_radiance(mesh, np.ones((8, 4))),
                 lambda: scene.transfer([[0, 0, 0]], [[0, 0, 0]]), lambda: scene.transfer([[0, 0, np.inf]], [[0, 0, 1]]),
                 lambda: scene.transfer([[0, 0, 0]], [[0, 0, 1], [0, 0, 1]]), lambda: scene.transfer([[0, 0, 0]], [[0, 0, 1]], bands=9),
                 lambda: scene.transfer([[0, 0, 0]], [[0, 0, 1]], offset=-1), lambda: scene.transfer([[0, 0, 0]], [[0, 0, 1]], brdf="phong"),
                 lambda: scene.gather([[0, 0, 0]], [[0, 0, 1]], bands=0), lambda: scene.valid([[0, 0]], [[0, 0, 1]]),
                 lambda: setattr(scene, "lod", 2.0)]:
        with pytest.raises(ValueError):
            call()
    # Errors leave the scene usable.
    assert scene.transfer([[0, 0, 2.0]], [[0, 0, 1]]).shape == (1, 25)


def test_scene_queries_use_the_finer_plane_table():
    scene = room().engine(hemishadow)
    assert scene.table_resolution == 256
    rng = np.random.default_rng(4)
    points, normals = receivers_in_open_air(rng)
    points, normals = points[:40], normals[:40]
    default = scene.transfer(points, normals)
    assert np.array_equal(default, scene.transfer(points, normals, table_resolution=256))
    assert not np.array_equal(default, scene.transfer(points, normals, table_resolution=128))


def test_phong_and_bands_follow_the_mesh_api():
    scene = hemishadow.Scene()
    scene.add_instance(scene.add_mesh(*grid(20.0, 3)))
    p, n = np.array([[0, 0, 0.5]]), np.array([[0, 0, -1.0]])
    for bands in (1, 3, 8):
        assert scene.transfer(p, n, bands=bands).shape == (1, bands * bands)
    glossy = scene.transfer(p, [[0, 0, 1.0]], brdf="phong", exponent=8, view=[0, 0, 1])
    assert math.isclose(float(glossy[0, 0]), 0.282095, rel_tol=0.02)  # open: normalised Phong reflects everything
    assert scene.transfer(p, n)[0, 0] < 0.05 * ref.AO_SCALE  # facing the plane: blocked


def test_instances_show_their_own_radiance():
    """Two instances of one roof, one given its own radiance: the receiver under each sees its
    instance's colour, exactly as with two separate meshes."""
    v, t = grid(0.5, 4, z=1.0, facing_down=True)
    left, right = np.eye(4), np.eye(4)
    left[0, 3], right[0, 3] = -0.6, 0.6
    red, blue = np.tile([1.0, 0, 0], (len(v), 1)), np.tile([0, 0, 1.0], (len(v), 1))
    shared = hemishadow.Scene()
    roof = shared.add_mesh(v, t)
    shared.add_instance(roof, left)
    second = shared.add_instance(roof, right)
    shared.set_radiance(roof, red)
    points, normals = np.array([[-0.6, 0.0, 0.0], [0.6, 0.0, 0.0]]), np.tile([0, 0, 1.0], (2, 1))
    before = shared.gather(points, normals, bands=1)[:, 0]
    assert (before[:, 0] > 0.2).all() and (before[:, 2] == 0).all()  # both red
    shared.set_radiance(roof, blue, instance_id=second)
    after = shared.gather(points, normals, bands=1)[:, 0]
    separate = hemishadow.Scene()
    for matrix, colour in ((left, red), (right, blue)):
        mesh = separate.add_mesh(v, t)
        separate.add_instance(mesh, matrix)
        separate.set_radiance(mesh, colour)
    np.testing.assert_allclose(after, separate.gather(points, normals, bands=1)[:, 0], atol=1e-6)
    assert after[0, 0] > after[0, 2] and after[1, 2] > after[1, 0]  # each sees most of its own roof
    np.testing.assert_allclose(after[:, 0] + after[:, 2], before[:, 0], rtol=1e-5)  # the same geometry, recoloured
    with pytest.raises(ValueError, match="places mesh"):
        separate.set_radiance(0, red, instance_id=1)
    with pytest.raises(ValueError, match="instance id"):
        shared.set_radiance(roof, red, instance_id=7)


def test_irradiance_is_transfer_under_the_lighting():
    """Uniform radiance 1 gives pi on an open receiver, and AO x pi under a blocker (against
    Embree); any lighting gives transfer . lighting."""
    scene = room().engine(hemishadow)
    points, normals = np.array([[0.5, -0.5, 0.01], [9.0, 9.0, 9.0]]), np.array([[0, 0, 1.0], [0, 0, 1.0]])
    uniform = np.zeros((9, 3))
    uniform[0] = 2.0 * np.sqrt(np.pi)  # L(s) = 1: the coefficient of Y_0 = 1 / (2 sqrt(pi))
    e = scene.irradiance(points, normals, uniform)
    assert e.shape == (2, 3) and e.dtype == np.float32
    np.testing.assert_allclose(e[1], np.pi, rtol=2e-3)  # far outside the room: open sky
    np.testing.assert_allclose(e[0] / np.pi, scene.ambient_occlusion(points[:1], normals[:1])[0], rtol=2e-3)
    assert e[0, 0] < 0.9 * np.pi
    lighting = np.random.default_rng(3).normal(size=(16, 3))
    np.testing.assert_allclose(scene.irradiance(points, normals, lighting),
                               scene.transfer(points, normals, bands=4) @ lighting, rtol=1e-5, atol=1e-5)
    for bad in (np.zeros((8, 3)), np.zeros((9, 2)), np.full((9, 3), np.nan)):
        with pytest.raises(ValueError):
            scene.irradiance(points, normals, bad)


def test_gather_views_distance_is_the_harmonic_mean_distance():
    """Irradiance caching's R: under a ceiling at height h, 1/d = cos(theta) / h averaged with
    the cosine weight gives 2 / (3 h), so R = 1.5 h (the ceiling, 400 wide, leaves out a
    sliver at the horizon); nothing seen: inf."""
    scene = hemishadow.Scene()
    v, t = grid(200.0, 9, z=1.0, facing_down=True)
    scene.add_instance(scene.add_mesh(v, t), np.eye(4))
    points = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.5]])
    views = scene.gather_views(points, np.tile([0.0, 0.0, 1.0], (2, 1)), bands=1, offset=0.0)
    assert views.distance.shape == (1, 2)
    np.testing.assert_allclose(views.distance[0], [1.5, 0.75], rtol=0.02)
    empty = hemishadow.Scene()
    empty.add_instance(empty.add_mesh(v, t), np.eye(4))
    assert np.isinf(empty.gather_views(points, np.tile([0.0, 0.0, -1.0], (2, 1)), bands=1).distance).all()
