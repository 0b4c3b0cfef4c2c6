"""The per-frame solver can be trusted vertex by vertex: against the exact path on every shared
mesh and character (all frames of their animations) and the procedural meshes, and unchanged
by the mesh's size, place, rotation and mirroring.

Bounds (issue: trustworthy live results): no vertex's AO more than 0.1 from the exact path; over
an animation no more frame-to-frame jumps |dAO| > 0.2 than the exact path has, and no larger
jump than the exact path's largest + 0.05; scaling by 0.001..1000 changes AO by at most 0.005
per vertex (the solver: on all but 0.1 % of vertices, and 0.01 on those). Rotation and
mirroring: the mask's cells are laid out in a tangent frame fixed to world axes, so the engine
itself is not exactly invariant (AO within 0.025 per vertex, transfer 1 % median, 4 % at the
99th percentile, up to 8 % on single vertices); the Blender add-on solves in each object's own
frame and turns the result, which makes objects exactly invariant (tests/addon/test_objects.py). The 25k-35k-vertex scans are checked on a fixed subset
of receivers here (the exact path is slow there); bench/solver_trust.py runs them whole.
"""

import numpy as np
import pytest

import hemishadow
from meshes import MESHES, grid, load_asset
from reference import relative_l2_errors

BANDS = 3  # AO is T_0; the hierarchy does not depend on the band count
SUBSET = 1500  # receivers checked on the large scans
STATIC = dict(MESHES, armadillo=lambda: load_asset("armadillo.obj"))


def as_engine(make):
    v, t = make()
    return np.asarray(v, np.float32), np.asarray(t, np.uint32)


def ao(transfer):
    return hemishadow.ambient_occlusion(transfer)


def receivers(count):
    if count <= 5000:
        return np.arange(count)
    return np.sort(np.random.default_rng(7).choice(count, SUBSET, replace=False))


@pytest.mark.parametrize("name", sorted(STATIC))
def test_no_vertex_far_from_the_exact_path(name):
    v, t = as_engine(STATIC[name])
    ids = receivers(len(v))
    exact = ao(hemishadow.transfer(v, t, bands=BANDS, receivers=ids))
    solved = ao(hemishadow.TransferSolver(v, t, bands=BANDS).solve(v))[ids]
    worst = np.abs(solved - exact)
    print(f"\n{name}: {len(ids)} receivers, max |dAO| {worst.max():.4f}, median {np.median(worst):.4f}")
    assert worst.max() <= 0.1, f"vertex {ids[np.argmax(worst)]}: exact {exact[np.argmax(worst)]:.3f}, solver " \
                               f"{solved[np.argmax(worst)]:.3f}"


@pytest.fixture(scope="module")
def animations():
    pytest.importorskip("bpy")
    from animated import CHARACTERS, character_frames

    return {name: character_frames(name) for name in CHARACTERS}


def frame_jumps(series, actions):
    """|dAO| between consecutive frames of the same action, (pairs, V)."""
    same = np.array([a == b for a, b in zip(actions[:-1], actions[1:])])
    return np.abs(np.diff(series, axis=0))[same]


@pytest.fixture(scope="module")
def exact_animations(animations):
    """Per character, the exact path's AO on every frame, (F, V)."""
    return {name: np.array([ao(hemishadow.transfer(v, triangles, bands=BANDS)) for _, _, v in frames])
            for name, (triangles, frames) in animations.items()}


@pytest.mark.parametrize("name", ["cesium_man.glb", "fox.glb", "rigged_figure.glb"])
def test_animation_follows_the_exact_path(animations, exact_animations, name):
    triangles, frames = animations[name]
    solver = hemishadow.TransferSolver(frames[0][2], triangles, bands=BANDS)
    exact = exact_animations[name]
    solved = np.array([ao(solver.solve(v)) for _, _, v in frames])
    worst = np.abs(solved - exact).max()
    actions = [a for a, _, _ in frames]
    jumps_exact, jumps_solved = frame_jumps(exact, actions), frame_jumps(solved, actions)
    print(f"\n{name}: {len(frames)} frames, max |dAO| vs exact {worst:.4f}; jumps > 0.2: exact "
          f"{(jumps_exact > 0.2).sum()}, solver {(jumps_solved > 0.2).sum()}; largest jump: exact "
          f"{jumps_exact.max():.3f}, solver {jumps_solved.max():.3f}")
    assert worst <= 0.1
    assert (jumps_solved > 0.2).sum() <= (jumps_exact > 0.2).sum()
    assert jumps_solved.max() <= jumps_exact.max() + 0.05


@pytest.mark.parametrize("name", ["cesium_man.glb", "fox.glb", "rigged_figure.glb"])
def test_potentially_visible_sets_keep_the_bound(animations, exact_animations, name):
    """PVS from every 4th frame: sampled frames give exactly the full hierarchy's result, every
    frame stays within 0.1 AO of the exact path, and frames far from the samples fall back."""
    triangles, frames = animations[name]
    poses = np.array([v for _, _, v in frames])
    full = hemishadow.TransferSolver(poses[0], triangles, bands=BANDS, reuse=False)
    pvs = hemishadow.TransferSolver(poses[0], triangles, bands=BANDS, reuse=False)
    sampled = list(range(0, len(poses), 4))
    pvs.build_pvs(poses[sampled])
    worst, used, fewer = 0.0, 0, []
    for f, v in enumerate(poses):
        expected, got = full.solve(v), pvs.solve(v)
        if f in sampled:
            assert pvs.stats["pvs"]
            np.testing.assert_array_equal(got, expected)
        used += pvs.stats["pvs"]
        if pvs.stats["pvs"]:
            fewer.append(pvs.stats["blockers_per_vertex"] / full.stats["blockers_per_vertex"])
        worst = max(worst, np.abs(ao(got) - exact_animations[name][f]).max())
    print(f"\n{name}: PVS used on {used} of {len(poses)} frames, blockers x{np.mean(fewer):.2f}, "
          f"max |dAO| vs exact {worst:.4f}")
    assert worst <= 0.1
    # Measured x0.84, x0.95, x0.75 (x0.71, x0.93 before the rasterizer skipped triangles under
    # the lowest cell samples, which are much of what the sets leave out).
    assert np.mean(fewer) < {"cesium_man.glb": 0.88, "fox.glb": 0.98, "rigged_figure.glb": 0.9}[name]
    far = poses[0] + np.array([0.0, 0.0, 0.5]) * np.ptp(poses[0], axis=0).max() * np.sin(poses[0][:, :1] * 40.0)
    pvs.solve(far)
    assert not pvs.stats["pvs"]


def test_pvs_input_is_checked():
    v, t = as_engine(MESHES["spot"])
    solver = hemishadow.TransferSolver(v, t, bands=BANDS)
    with pytest.raises(ValueError, match="shape"):
        solver.build_pvs(v)
    with pytest.raises(ValueError, match="finite"):
        solver.build_pvs(np.full((1,) + v.shape, np.nan, np.float32))
    with pytest.raises(ValueError, match="tolerance"):
        solver.build_pvs(v[None], tolerance=-1.0)
    assert solver.pvs is None
    solver.build_pvs(v[None])
    assert solver.pvs["poses"] == 1 and solver.pvs["clusters_per_vertex"] > 0
    solver.clear_pvs()
    assert solver.pvs is None
    with pytest.raises(ValueError, match="normals"):
        solver.build_pvs(v[None], v[None, :5])


def test_pvs_keep_distant_proxies_and_draw_them_whole_up_close():
    """A ceiling far above a floor is drawn through its proxy: in the sampled pose the sets
    give the full hierarchy's result bit for bit. Lowered close (the sets forced on that
    pose), the walk opens the ceiling, whose clusters were never candidates: the sets must
    draw all of it (without, the floor's median AO is 0.38 too high)."""
    floor_v, floor_t = grid(1.0, 30)
    ceiling_v, ceiling_t = grid(1.0, 30, facing_down=True)
    triangles = np.concatenate([floor_t, ceiling_t + len(floor_v)]).astype(np.uint32)

    def pose(height):
        return np.concatenate([floor_v, ceiling_v + [0.0, 0.0, height]]).astype(np.float32)

    far, close = pose(6.0), pose(1.0)
    full = hemishadow.TransferSolver(far, triangles, bands=BANDS, reuse=False)
    two_levels = hemishadow.TransferSolver(far, triangles, bands=BANDS, reuse=False, far_lod=0)
    pvs = hemishadow.TransferSolver(far, triangles, bands=BANDS, reuse=False)
    pvs.build_pvs(far[None], tolerance=1e9)
    expected = full.solve(far)
    np.testing.assert_array_equal(pvs.solve(far), expected)
    assert not np.array_equal(two_levels.solve(far), expected)  # the proxies were drawn
    shadowed = ao(full.solve(close))
    lowered = ao(pvs.solve(close)) - shadowed
    assert pvs.stats["pvs"]
    assert shadowed[: len(floor_v)].mean() < 0.7  # the lowered ceiling shadows the floor
    assert lowered.min() >= -1e-6  # the sets only ever leave blockers out
    # Measured: median 0.001, worst 0.13 (clusters sharing a group with the floor, too small to
    # draw from afar); without drawing the ceiling whole, 0.38 and 0.55.
    assert np.median(lowered[: len(floor_v)]) < 0.01 and lowered.max() < 0.2


def test_pvs_with_given_normals_matches_solves_given_them():
    """Sets sampled with the normals `solve` is given reproduce its result bit for bit (the
    mesh's own normals would pick different clusters)."""
    v, t = as_engine(MESHES["torus_knot"])
    rng = np.random.default_rng(3)
    normals = (v / np.linalg.norm(v, axis=1, keepdims=True) + 0.3 * rng.normal(size=v.shape)).astype(np.float32)
    full = hemishadow.TransferSolver(v, t, bands=BANDS, reuse=False)
    pvs = hemishadow.TransferSolver(v, t, bands=BANDS, reuse=False)
    pvs.build_pvs(v[None], normals[None])
    np.testing.assert_array_equal(pvs.solve(v, normals), full.solve(v, normals))
    assert pvs.stats["pvs"] and pvs.stats["blockers_per_vertex"] < full.stats["blockers_per_vertex"]


@pytest.mark.parametrize("name", ["spot", "teapot", "rolled_sheet", "cesium_man"])
@pytest.mark.parametrize("scale", [1e-3, 1e-2, 1e2, 1e3])
def test_size_does_not_change_results(name, scale):
    v, t = as_engine(MESHES[name])
    base_solver = ao(hemishadow.TransferSolver(v, t, bands=BANDS).solve(v))
    base_exact = ao(hemishadow.transfer(v, t, bands=BANDS))
    scaled = v * np.float32(scale)
    solver = ao(hemishadow.TransferSolver(scaled, t, bands=BANDS).solve(scaled))
    exact = ao(hemishadow.transfer(scaled, t, bands=BANDS))
    assert np.abs(exact - base_exact).max() <= 0.005
    # The solver's coarse triangles are large: when rounding puts one of their edge planes on
    # the other side of a table texel boundary, a strip one texel wide across the whole disk
    # flips (measured: 0.0076 AO on one vertex of cesium_man at 1000x). Such flips are rare.
    d = np.abs(solver - base_solver)
    assert d.max() <= 0.01 and (d > 0.005).mean() <= 0.001, (d.max(), (d > 0.005).sum())


# Bounds of the invariance tests (bench/near_scale_sweep.py prints them beside its sweep):
# the largest and the mean AO change under a turn; under the move, the largest change and the
# share of vertices allowed to change by more than MOVE_NOTICEABLE.
TURN_BOUND = 0.025
TURN_MEAN_BOUND = 0.005
MOVE_BOUND = 0.01
MOVE_NOTICEABLE = 0.005
MOVE_NOTICEABLE_SHARE = 0.005


def moved_away(v):
    """The mesh 50 of its sizes away, as the place test moves it (bench/near_scale_sweep.py
    moves it the same way)."""
    return v + np.float32(50.0)


def test_place_does_not_change_results():
    v, t = as_engine(MESHES["spot"])
    base = ao(hemishadow.TransferSolver(v, t, bands=BANDS).solve(v))
    far = moved_away(v)
    d = np.abs(ao(hemishadow.TransferSolver(far, t, bands=BANDS).solve(far)) - base)
    # float32 holds positions 50 sizes away to 4e-6 of the size: the geometry itself moves by
    # that much, enough for the simplifier to build another coarse mesh, which the near
    # clusters' fine triangles mostly hide (14 of 3225 vertices > 0.005; the exact path: none;
    # docs/solver_speed.md).
    noticeable = d > MOVE_NOTICEABLE
    assert d.max() <= MOVE_BOUND and noticeable.mean() <= MOVE_NOTICEABLE_SHARE, (d.max(), noticeable.sum())


def rotation(axis, angle):
    return hemishadow.rotation_matrix(axis, angle).astype(np.float64)


# The turns of the invariance test (bench/near_scale_sweep.py measures the same ones).
TURNS = {"rotate_x": rotation((1, 0, 0), 1.1),
         "rotate_xyz": rotation((1, 2, 3), 2.3),
         "mirror_x": np.diag([-1.0, 1, 1]),
         "mirror_xy": np.diag([-1.0, -1, 1]),
         "mirror_rotate": rotation((0, 1, 1), 0.7) @ np.diag([1.0, 1, -1])}


def turned(v, t, m):
    """The mesh (v, t) turned by the orthogonal m: float32 positions and, for a mirror, the
    triangles reversed (a mirror turns faces inside out)."""
    moved = (v.astype(np.float64) @ m.T).astype(np.float32)
    return moved, (t[:, ::-1].copy() if np.linalg.det(m) < 0 else t)


def moved_and_turned(v, t):
    """(vertices, triangles) of the mesh moved away, then turned by each of TURNS in order
    (the copies bench/solver_trust.py and bench/near_scale_sweep.py measure)."""
    return [(moved_away(v), t), *(turned(v, t, m) for m in TURNS.values())]


@pytest.mark.parametrize("name", ["spot", "cesium_man"])
@pytest.mark.parametrize("case", list(TURNS))
def test_rotation_and_mirroring_do_not_change_results(name, case):
    v, t = as_engine(MESHES[name])
    base = hemishadow.TransferSolver(v, t, bands=5).solve(v)
    m = TURNS[case]
    moved, tris = turned(v, t, m)
    result = hemishadow.TransferSolver(moved, tris, bands=5).solve(moved)
    d = np.abs(ao(result) - ao(base))
    assert d.max() <= TURN_BOUND and d.mean() <= TURN_MEAN_BOUND, (d.max(), d.mean())
    # Transfer of the moved mesh at s equals the original's at m^T s (rotate_sh takes any
    # orthogonal matrix: a mirror keeps each SH band too).
    back = hemishadow.rotate_sh(result.T, m.T).T
    errors = relative_l2_errors(back, base)
    assert np.median(errors) <= 0.01 and np.percentile(errors, 99) <= 0.04 and errors.max() <= 0.1, \
        (np.median(errors), np.percentile(errors, 99), errors.max())


def test_mirrored_winding_is_what_breaks_it():
    # The engine takes faces as given: the same mirror without reversing the winding turns
    # normals inwards. The add-on reverses the winding of objects with a negative scale.
    v, t = as_engine(MESHES["spot"])
    moved = v * np.float32([-1, 1, 1])
    inside_out = ao(hemishadow.TransferSolver(moved, t, bands=BANDS).solve(moved))
    assert inside_out.mean() < 0.5
