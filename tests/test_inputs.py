"""Bad input gets a ValueError that says what is wrong; nothing crashes the process."""

import numpy as np
import pytest

import hemishadow

TETRA_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
TETRA_T = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.uint32)


def raises(match, fn, *args, **kwargs):
    with pytest.raises(ValueError, match=match):
        fn(*args, **kwargs)


def test_good_input_runs():
    t = hemishadow.transfer(TETRA_V, TETRA_T)
    assert t.shape == (4, 25) and t.dtype == np.float32 and np.isfinite(t).all()


def test_accepts_float64_and_int64_and_lists():
    a = hemishadow.transfer(TETRA_V.astype(np.float64), TETRA_T.astype(np.int64))
    b = hemishadow.transfer(TETRA_V.tolist(), TETRA_T.tolist())
    assert np.array_equal(a, b)


@pytest.mark.parametrize("vertices, match", [
    (TETRA_V[:, :2], "shape"),
    (TETRA_V.reshape(-1), "shape"),
    (TETRA_V.astype(str), "real numbers"),
    (TETRA_V.astype(complex), "real numbers"),
    (np.where(np.arange(12).reshape(4, 3) == 4, np.nan, TETRA_V), "NaN or infinite"),
    (np.where(np.arange(12).reshape(4, 3) == 7, np.inf, TETRA_V), "NaN or infinite"),
])
def test_bad_vertices(vertices, match):
    raises(match, hemishadow.transfer, vertices, TETRA_T)


@pytest.mark.parametrize("triangles, match", [
    (TETRA_T[:, :2], "shape"),
    (TETRA_T.astype(np.float32), "integer"),
    (TETRA_T + 1, "index 4"),
    (TETRA_T.astype(np.int64) - 1, "index -1"),
    (np.array([[0, 1, 2**40]]), "index"),
])
def test_bad_triangles(triangles, match):
    raises(match, hemishadow.transfer, TETRA_V, triangles)


def test_empty_meshes():
    raises("empty", hemishadow.transfer, np.zeros((0, 3)), np.zeros((0, 3), int))
    raises("empty", hemishadow.transfer, TETRA_V, np.zeros((0, 3), int))


def test_bad_normals_bands_offset():
    raises("shape", hemishadow.transfer, TETRA_V, TETRA_T, normals=np.ones((3, 3)))
    raises("NaN", hemishadow.transfer, TETRA_V, TETRA_T, normals=np.full((4, 3), np.nan))
    for bands in (0, 9, 2.5, "5", True):
        raises("bands", hemishadow.transfer, TETRA_V, TETRA_T, bands=bands)
    raises("offset", hemishadow.transfer, TETRA_V, TETRA_T, offset=-1.0)
    raises("offset", hemishadow.transfer, TETRA_V, TETRA_T, offset=float("nan"))


def test_bad_brdf_arguments():
    raises("brdf", hemishadow.transfer, TETRA_V, TETRA_T, brdf="ward")
    raises("exponent", hemishadow.transfer, TETRA_V, TETRA_T, brdf="phong", view=[0, 0, 1])
    raises("exponent", hemishadow.transfer, TETRA_V, TETRA_T, brdf="phong", exponent=-2, view=[0, 0, 1])
    raises("exponent applies", hemishadow.transfer, TETRA_V, TETRA_T, exponent=8)
    raises("view", hemishadow.transfer, TETRA_V, TETRA_T, brdf="phong", exponent=8)
    raises("view", hemishadow.transfer, TETRA_V, TETRA_T, brdf="phong", exponent=8, view=[0, 0, 0])
    raises("view", hemishadow.transfer, TETRA_V, TETRA_T, brdf="phong", exponent=8, view=np.ones((3, 3)))


def test_degenerate_and_non_manifold_meshes_give_finite_results():
    # All triangles collapsed to a line, a vertex shared by three sheets, an unreferenced vertex.
    line = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], np.float32)
    with pytest.warns(RuntimeWarning, match="touch no triangle"):
        t = hemishadow.transfer(line, [[0, 1, 2]])
    assert np.isfinite(t).all() and not t.any()
    # Edge 0-1 is shared by three triangles; vertex 4 only by a zero-area one; vertex 5 by none.
    fan_v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [5, 5, 5]], np.float32)
    fan_t = [[0, 1, 2], [0, 2, 3], [0, 3, 1], [0, 1, 4]]
    with pytest.warns(RuntimeWarning, match="^2 vertices"):
        t = hemishadow.transfer(fan_v, fan_t)
    assert np.isfinite(t).all() and not t[4:].any() and t[:4].any()


def test_solver_on_degenerate_meshes():
    # Zero-area triangles with distinct corners: zeros, as the exact path gives (without its
    # warning, which every frame would repeat; docs/usage.md).
    line = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], np.float32)
    t = hemishadow.TransferSolver(line, [[0, 1, 2]], bands=3).solve(line)
    assert t.shape == (3, 9) and np.isfinite(t).all() and not t.any()
    # Corners at one position weld into one vertex: no triangle is left to build blockers from.
    point = np.zeros((3, 3), np.float32)
    raises("two corners at the same position", hemishadow.TransferSolver, point, [[0, 1, 2]], bands=3)


def test_bad_environment_images(tmp_path):
    raises("shape", hemishadow.project_environment, np.ones((4, 8)))
    raises("3 or 4 channels", hemishadow.project_environment, np.ones((4, 8, 2)))
    raises("empty", hemishadow.project_environment, np.ones((0, 8, 3)))
    img = np.ones((4, 8, 3))
    img[1, 2, 0] = np.nan
    raises("NaN", hemishadow.project_environment, img)
    raises("no such", hemishadow.project_environment, tmp_path / "missing.exr")
    garbage = tmp_path / "garbage.exr"
    garbage.write_bytes(b"not an exr at all")
    raises("OpenEXR", hemishadow.project_environment, garbage)
    raises("rotation", hemishadow.project_environment, np.ones((4, 8, 3)), rotation=np.ones((3, 3)))
    raises("rotation", hemishadow.project_environment, np.ones((4, 8, 3)), rotation=[1, 2])


def test_bad_shading_arguments():
    raises("square", hemishadow.shade, np.ones((2, 10)), np.ones((10, 3)))
    raises("lighting", hemishadow.shade, np.ones((2, 9)), np.ones((16, 3)))
    raises("albedo", hemishadow.shade, np.ones((2, 9)), np.ones((9, 3)), albedo=np.ones((3, 3)))
    raises("NaN", hemishadow.shade, np.full((2, 9), np.nan), np.ones((9, 3)))


def test_bad_sh_arguments():
    raises("zero", hemishadow.sh_basis, [[0, 0, 0]])
    raises("shape", hemishadow.sh_basis, [[0, 0]])
    raises("square", hemishadow.rotate_sh, np.ones(10), np.eye(3))
    raises("rotation", hemishadow.rotate_sh, np.ones(9), np.ones((3, 3)))
    raises("axis", hemishadow.rotation_matrix, [0, 0, 0], 1.0)
