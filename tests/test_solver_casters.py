"""Shadow casters (issue 10): `TransferSolver.solve(casters=Scene)` adds another scene's
blockers to a deforming mesh's self-shadowing.

Against dense Embree ray casting of the mesh and the casters together; the placement
(`to_world`: moved, turned, mirrored) changes nothing; excluded instances block nothing;
reuse follows the scene's edits; several solvers read one scene at once; input checks.
"""

import threading

import numpy as np
import pytest
import reference as ref
import scene_reference as sref
import trimesh
from meshes import grid, load_asset

hemishadow = pytest.importorskip("hemishadow")


def plane_and_box():
    """A 24 x 24 plane at z = 0 and a box hovering over part of it."""
    pv, pt = grid(1.0, 24)
    box = trimesh.creation.box((0.6, 0.6, 0.3))
    box.apply_translation((0.2, 0.0, 0.5))
    return (pv, pt), (np.asarray(box.vertices), np.asarray(box.faces))


def scene_of(*meshes, matrix=np.eye(4), lod=0.0):
    scene = hemishadow.Scene(lod=lod)
    ids = [scene.add_instance(scene.add_mesh(v, t), matrix) for v, t in meshes]
    return scene, ids


def rigid(angle, axis, mirror=False, shift=(0.0, 0.0, 0.0)):
    m = np.eye(4)
    m[:3, :3] = trimesh.transformations.rotation_matrix(angle, axis)[:3, :3] @ np.diag([-1.0 if mirror else 1.0, 1, 1])
    m[:3, 3] = shift
    return m


@pytest.mark.parametrize("hierarchy", [False, True])
def test_casters_match_ray_casting_of_both(hierarchy):
    """The plane's transfer under the box against Embree on plane + box together."""
    (pv, pt), (bv, bt) = plane_and_box()
    scene, _ = scene_of((bv, bt))
    solver = hemishadow.TransferSolver(pv, pt, hierarchy=hierarchy)
    shadowed = solver.solve(pv, casters=scene)
    alone = solver.solve(pv)
    normals = np.tile([0.0, 0.0, 1.0], (len(pv), 1))
    expected, ao = sref.transfer_reference(np.concatenate([pv, bv]), np.concatenate([pt, bt + len(pv)]), pv, normals,
                                           offset=1e-4, n_side=48)
    errors = ref.relative_l2_errors(shadowed, expected)
    ao_solved = shadowed[:, 0] / alone[:, 0]
    print(f"median {np.median(errors):.4f} max {errors.max():.4f} AO {ao.min():.3f} max AO error "
          f"{np.abs(ao_solved - ao).max():.4f}")
    assert ao.min() < 0.6  # the box does shadow the plane
    assert np.median(errors) < 0.02 and errors.max() < 0.08  # measured 0.8 % and 3.9 %
    assert np.abs(ao_solved - ao).max() < 0.03  # measured 0.010


@pytest.mark.parametrize("place", [rigid(0.7, (1, 2, 3), shift=(5.0, -2.0, 1.0)),
                                   rigid(2.0, (0, 1, 1), mirror=True, shift=(-3.0, 0.5, 8.0))],
                         ids=["turned", "mirrored"])
def test_placement_changes_nothing(place):
    """Casters placed in world by `to_world` give what they give in the solver's own space."""
    (pv, pt), (bv, bt) = plane_and_box()
    solver = hemishadow.TransferSolver(pv, pt)
    here = solver.solve(pv, casters=scene_of((bv, bt))[0])
    there = solver.solve(pv, casters=scene_of((bv, bt), matrix=place)[0], to_world=place)
    assert np.abs(here[:, 0] / np.abs(here[:, 0]).max() - there[:, 0] / np.abs(here[:, 0]).max()).max() < 0.01
    assert np.median(ref.relative_l2_errors(there, here)) < 1e-3


def test_excluded_instances_block_nothing():
    """The solver's own object in the casters scene, excluded, changes no bit; included, it
    would shadow the plane twice over (its own triangles through the scene)."""
    (pv, pt), (bv, bt) = plane_and_box()
    solver = hemishadow.TransferSolver(pv, pt, reuse=False)
    with_self, (own, _) = scene_of((pv, pt), (bv, bt))
    np.testing.assert_array_equal(solver.solve(pv, casters=with_self, exclude=[own]),
                                  solver.solve(pv, casters=scene_of((bv, bt))[0]))
    everything, ids = scene_of((bv, bt))
    np.testing.assert_array_equal(solver.solve(pv, casters=everything, exclude=ids), solver.solve(pv))


def test_reuse_follows_the_scene():
    (pv, pt), (bv, bt) = plane_and_box()
    solver = hemishadow.TransferSolver(pv, pt)
    scene, (box,) = scene_of((bv, bt))
    first = solver.solve(pv, casters=scene)
    again = solver.solve(pv, casters=scene)
    assert solver.stats["reused"] == len(pv)
    np.testing.assert_array_equal(first, again)
    moved = np.eye(4)
    moved[0, 3] = -0.5
    scene.set_matrix(box, moved)
    shifted = solver.solve(pv, casters=scene)
    assert solver.stats["reused"] == 0
    assert np.abs(shifted - first).max() > 0.1
    scene.set_matrix(box, np.eye(4))
    np.testing.assert_array_equal(solver.solve(pv, casters=scene), first)
    solver.solve(pv)  # no casters: nothing of the shadowed result may be reused
    assert solver.stats["reused"] == 0


def test_character_shadowed_by_a_moving_caster():
    """A real asset: the sheet moving away from the character lets light back in, and the
    character's solve follows the caster frame by frame."""
    vertices, triangles = load_asset("cesium_man.glb")
    vertices = vertices[:, [0, 2, 1]] * [1, -1, 1]  # Y-up to Z-up
    low, high = vertices.min(0), vertices.max(0)
    centre = 0.5 * (low + high)
    sheet_v, sheet_t = grid(0.6 * np.ptp(vertices, axis=0).max(), 12)
    scene, (sheet,) = scene_of((sheet_v, sheet_t[:, ::-1]), lod=0.15)
    solver = hemishadow.TransferSolver(vertices, triangles)
    open_sky = solver.solve(vertices)[:, 0]
    aos = []
    for height in (0.05, 0.5, 3.0):  # just above the head, higher, far away
        m = np.eye(4)
        m[:3, 3] = centre + [0, 0, 0.5 * (high[2] - low[2]) * (1 + height)]
        scene.set_matrix(sheet, m)
        aos.append(np.mean(solver.solve(vertices, casters=scene)[:, 0] / np.maximum(open_sky, 1e-6)))
    assert aos[0] < aos[1] < aos[2] <= 1.0, aos


def test_solvers_share_a_scene_across_threads():
    (pv, pt), (bv, bt) = plane_and_box()
    scene, _ = scene_of((bv, bt))
    solvers = [hemishadow.TransferSolver(pv, pt, reuse=False) for _ in range(4)]
    expected = solvers[0].solve(pv, casters=scene)
    results, errors = [None] * 4, []

    def work(i):
        try:
            for _ in range(5):
                results[i] = solvers[i].solve(pv, casters=scene)
        except Exception as error:  # noqa: BLE001 - reported below
            errors.append(error)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    for r in results:
        np.testing.assert_array_equal(r, expected)


def test_bad_casters_input():
    (pv, pt), (bv, bt) = plane_and_box()
    solver = hemishadow.TransferSolver(pv, pt)
    scene, _ = scene_of((bv, bt))
    with pytest.raises(ValueError, match="rigid"):
        solver.solve(pv, casters=scene, to_world=np.diag([2.0, 2.0, 2.0, 1.0]))
    with pytest.raises(ValueError, match="out of range"):
        solver.solve(pv, casters=scene, exclude=[5])
    with pytest.raises(ValueError, match="instance ids"):
        solver.solve(pv, casters=scene, exclude=[-1])
    with pytest.raises(TypeError, match="hemishadow.Scene"):
        solver.solve(pv, casters="scene")
    with pytest.raises(ValueError, match="need casters"):
        solver.solve(pv, to_world=np.eye(4))
    nan = np.eye(4)
    nan[0, 3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        solver.solve(pv, casters=scene, to_world=nan)
    empty = hemishadow.Scene()
    np.testing.assert_array_equal(solver.solve(pv, casters=empty), solver.solve(pv))


def test_still_casters_are_not_rasterized_again():
    """A still ball (320 triangles) and a moving box (12) over a still plane: every frame
    equals a fresh solve bit for bit, and once the box is known to move only it is
    rasterized again; when the ball moves too, everything is recomputed and still exact."""
    (pv, pt), (bv, bt) = plane_and_box()
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.2)
    scene, (box, sphere) = scene_of((bv, bt), (np.asarray(ball.vertices), np.asarray(ball.faces)))
    solver = hemishadow.TransferSolver(pv, pt)
    fresh = hemishadow.TransferSolver(pv, pt, reuse=False)
    counts = []
    for frame, (box_x, x) in enumerate([(-0.5, 0.0), (-0.3, 0.0), (0.0, 0.0), (0.3, 0.0), (0.3, -0.4), (0.5, -0.4)]):
        m, b = np.eye(4), np.eye(4)
        m[:3, 3] = (x, 0.3, 0.35)
        b[0, 3] = box_x
        scene.set_matrix(sphere, m)
        scene.set_matrix(box, b)
        np.testing.assert_array_equal(solver.solve(pv, casters=scene), fresh.solve(pv, casters=scene), err_msg=f"frame {frame}")
        counts.append((solver.stats["blockers_per_vertex"], fresh.stats["blockers_per_vertex"]))
    # Frames 0-1 learn which caster moves; 2-3 rasterize only the box; 4 (the ball moved) all.
    assert counts[2][0] < 0.2 * counts[2][1] and counts[3][0] < 0.2 * counts[3][1], counts
    assert counts[4][0] == counts[4][1], counts


def test_a_cancelled_solve_leaves_the_caster_masks_as_they_were():
    """A solve cancelled after its first chunk of receivers (of 5) has written part of the
    next frame's masks: the solver must go on from the last complete frame's, bit for bit
    with a fresh solve, and still rasterize only the moving caster."""
    pv, pt = grid(1.0, 64)
    _, (bv, bt) = plane_and_box()
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.2)
    scene, (box, sphere) = scene_of((bv, bt), (np.asarray(ball.vertices), np.asarray(ball.faces)))
    ball_at = np.eye(4)
    ball_at[:3, 3] = (0.0, 0.3, 0.35)
    scene.set_matrix(sphere, ball_at)
    solver = hemishadow.TransferSolver(pv, pt)
    fresh = hemishadow.TransferSolver(pv, pt, reuse=False)

    def box_at(x):
        m = np.eye(4)
        m[0, 3] = x
        scene.set_matrix(box, m)

    for x in (-0.5, -0.3, 0.0):  # the solver learns that the box moves and the ball does not
        box_at(x)
        solver.solve(pv, casters=scene)
    box_at(0.3)
    with pytest.raises(hemishadow.Cancelled):
        solver.solve(pv, casters=scene, progress=lambda fraction: False)
    box_at(0.2)
    np.testing.assert_array_equal(solver.solve(pv, casters=scene), fresh.solve(pv, casters=scene))
    assert solver.stats["blockers_per_vertex"] < 0.2 * fresh.stats["blockers_per_vertex"], (solver.stats, fresh.stats)
