"""The SH basis, rotation, windowing and environment projection against independent references."""

import json
import pathlib

import numpy as np
import pytest

import hemishadow

TESTVECTORS = pathlib.Path(__file__).resolve().parents[2] / "shared" / "testvectors" / "sh_basis.json"


def sphere_quadrature(n_theta=64, n_phi=128):
    """Gauss-Legendre in cos(theta) x uniform phi: exact for polynomials far beyond band 4."""
    z, wz = np.polynomial.legendre.leggauss(n_theta)
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    s = np.sqrt(1 - zz ** 2)
    dirs = np.stack([s * np.cos(pp), s * np.sin(pp), zz], -1).reshape(-1, 3)
    weights = (wz[:, None] * np.full(n_phi, 2 * np.pi / n_phi)).reshape(-1)
    return dirs, weights


def test_convention_values_match_the_shared_test_vectors():
    cases = json.loads(TESTVECTORS.read_text())["cases"]
    dirs = np.array([c["direction"] for c in cases], dtype=np.float64)
    expected = np.array([c["values"] for c in cases])
    got = hemishadow.sh_basis(dirs, 5)
    assert np.abs(got - expected).max() < 2e-6


def test_named_values():
    y = hemishadow.sh_basis(np.eye(3), 2)
    assert y[:, 0] == pytest.approx([0.282095] * 3, abs=1e-6)
    assert y[0, 3] == pytest.approx(-0.488603, abs=1e-6)  # Y(1,1) = -0.488603 x
    assert y[1, 1] == pytest.approx(-0.488603, abs=1e-6)  # Y(1,-1) = -0.488603 y
    assert y[2, 2] == pytest.approx(0.488603, abs=1e-6)   # Y(1,0) = 0.488603 z


@pytest.mark.parametrize("bands", [3, 4, 5, 8])
def test_orthonormal_by_quadrature(bands):
    dirs, w = sphere_quadrature()
    y = hemishadow.sh_basis(dirs, bands).astype(np.float64)
    gram = (y * w[:, None]).T @ y
    assert np.abs(gram - np.eye(bands * bands)).max() < 1e-4


def test_directions_are_normalised():
    assert np.allclose(hemishadow.sh_basis([[0, 0, 5.0]], 3), hemishadow.sh_basis([[0, 0, 1.0]], 3))


def random_rotation(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return hemishadow.rotation_matrix(q[1:], 2 * np.arccos(np.clip(q[0], -1, 1)))


def test_rotation_keeps_band_energies_and_matches_rotated_evaluation():
    rng = np.random.default_rng(4)
    coeffs = rng.normal(size=25)
    rotation = random_rotation(rng)
    rotated = hemishadow.rotate_sh(coeffs, rotation).astype(np.float64)
    for l in range(5):
        band = slice(l * l, (l + 1) * (l + 1))
        assert np.linalg.norm(rotated[band]) == pytest.approx(np.linalg.norm(coeffs[band]), rel=1e-4)
    dirs = rng.normal(size=(200, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    g = hemishadow.sh_basis(dirs, 5) @ rotated
    f = hemishadow.sh_basis(dirs @ rotation, 5) @ coeffs  # f(R^T d)
    assert np.abs(g - f).max() < 1e-4


@pytest.mark.parametrize("bands", [1, 2, 3, 5, 8])
def test_lighting_in_receiver_frames_takes_the_worlds_values(bands):
    """The lightmap's lighting per receiver frame (the engine's rotation, `_native.sh_to_frames`):
    at any direction, the frame's coefficients in local coordinates give the world's value
    there, for right- and left-handed frames; checked by evaluating both bases directly."""
    from hemishadow.lightmap.light import local_lighting
    from hemishadow.sh import fibonacci_directions

    rng = np.random.default_rng(bands)
    n = rng.normal(size=(200, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    t = np.cross(n, rng.normal(size=3))
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(n, t)
    b[::2] *= -1  # mirrored frames
    lighting = rng.normal(size=(bands * bands, 3)).astype(np.float32)
    local = local_lighting(lighting, t, b, n)
    dirs = fibonacci_directions(64)
    world_values = hemishadow.sh_basis(dirs, bands) @ lighting                            # (D, 3)
    for p in range(len(n)):
        in_frame = dirs @ np.stack([t[p], b[p], n[p]]).T                                   # (D, 3) local
        local_values = hemishadow.sh_basis(in_frame, bands) @ local[p]
        assert np.abs(local_values - world_values).max() < 1e-4 * (1 + np.abs(world_values).max())


def test_lighting_in_receiver_frames_refuses_bad_input():
    from hemishadow import _native

    with pytest.raises(ValueError, match="square number"):
        _native.sh_to_frames(np.zeros((8, 3), np.float32), np.eye(3, dtype=np.float32)[None])
    with pytest.raises(ValueError, match="finite"):
        _native.sh_to_frames(np.zeros((9, 3), np.float32), np.full((1, 3, 3), np.nan, np.float32))
    with pytest.raises(ValueError, match=r"\(P, 3, 3\)"):
        _native.sh_to_frames(np.zeros((9, 3), np.float32), np.zeros((2, 3, 2), np.float32))
    assert _native.sh_to_frames(np.zeros((9, 3), np.float32), np.zeros((0, 3, 3), np.float32)).shape == (0, 9, 3)
    assert _native.sh_to_frames(np.zeros((9, 0), np.float32), np.eye(3, dtype=np.float32)[None]).shape == (1, 9, 0)


def test_rotation_about_z_by_quarter_turn_maps_x_to_y():
    # A lobe along +X rotated a quarter turn about +Z points along +Y.
    lobe = hemishadow.sh_basis([[1.0, 0, 0]], 3)[0]
    rotated = hemishadow.rotate_sh(lobe, hemishadow.rotation_matrix([0, 0, 1], np.pi / 2))
    assert np.allclose(rotated, hemishadow.sh_basis([[0, 1.0, 0]], 3)[0], atol=1e-5)


def test_windowing_damps_high_bands_only():
    coeffs = np.ones(25)
    for kind in ("hanning", "lanczos"):
        w = hemishadow.window_sh(coeffs, kind)
        assert w[0] == 1
        assert (np.diff([w[l * l] for l in range(5)]) < 0).all()
    with pytest.raises(ValueError):
        hemishadow.window_sh(coeffs, "box")


def equirect_directions(h, w):
    """Pixel-centre directions as Blender's Environment Texture maps them, written from
    u = 0.5 - atan2(y, x) / 2pi, v = 1 - acos(z) / pi with row 0 at v = 1."""
    v = 1 - (np.arange(h) + 0.5) / h
    u = (np.arange(w) + 0.5) / w
    theta = np.pi * (1 - v)
    phi = 2 * np.pi * (0.5 - u)
    tt, pp = np.meshgrid(theta, phi, indexing="ij")
    return np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], -1)


def test_projection_of_a_constant():
    image = np.full((128, 256, 3), 2.0, np.float32)
    light = hemishadow.project_environment(image, 5)
    assert light[0] == pytest.approx([2 * 4 * np.pi * 0.2820948] * 3, rel=1e-4)
    assert np.abs(light[1:]).max() < 1e-3


def test_projection_of_an_analytic_environment():
    """An environment that is a known SH expansion projects back onto its coefficients."""
    rng = np.random.default_rng(5)
    truth = rng.normal(size=(25, 3)).astype(np.float32)
    h, w = 256, 512
    dirs = equirect_directions(h, w).reshape(-1, 3)
    image = (hemishadow.sh_basis(dirs, 5) @ truth).reshape(h, w, 3)
    light = hemishadow.project_environment(image, 5)
    assert np.abs(light - truth).max() < 2e-3 * np.abs(truth).max()


def test_projection_with_alpha_channel_and_rotation():
    h, w = 64, 128
    dirs = equirect_directions(h, w).reshape(-1, 3)
    truth = np.zeros((9, 3), np.float32)
    truth[3] = [-1, -1, -1]  # radiance grows towards +X (Y(1,1) = -c x)
    rgb = (hemishadow.sh_basis(dirs, 3) @ truth).reshape(h, w, 3)
    rgba = np.concatenate([rgb, np.ones((h, w, 1), np.float32)], -1)
    assert np.allclose(hemishadow.project_environment(rgba, 3), hemishadow.project_environment(rgb, 3), atol=1e-6)
    # A Mapping node rotating the lookup vector by R shows the image turned by R^T:
    # the bright +X side of the image now arrives from R^T x.
    rotation = hemishadow.rotation_matrix([0, 0, 1], np.pi / 2)
    rotated = hemishadow.project_environment(rgb, 3, rotation=rotation)
    expected = hemishadow.rotate_sh(truth, rotation.T)
    assert np.abs(rotated - expected).max() < 2e-3
    # Euler angles give the same as the matrix they stand for.
    assert np.allclose(hemishadow.project_environment(rgb, 3, rotation=[0, 0, np.pi / 2]), rotated, atol=1e-6)


def test_shade_and_ambient_occlusion():
    transfer = np.zeros((2, 9), np.float32)
    transfer[0, 0] = hemishadow.AO_UNOCCLUDED
    transfer[1, 0] = hemishadow.AO_UNOCCLUDED / 2
    lighting = np.zeros((9, 3), np.float32)
    lighting[0] = 1 / 0.2820948  # radiance 1 from everywhere
    irradiance = hemishadow.shade(transfer, lighting)
    assert irradiance[0] == pytest.approx([np.pi] * 3, rel=1e-5)  # E = pi for unit radiance
    radiance = hemishadow.shade(transfer, lighting, albedo=[0.5, 0.5, 0.5])
    assert radiance[0] == pytest.approx([0.5] * 3, rel=1e-5)
    assert hemishadow.ambient_occlusion(transfer) == pytest.approx([1.0, 0.5], rel=1e-6)
