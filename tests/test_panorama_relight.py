"""Panoramas (issue 13), the relighting half: the engine's relight against numpy (suns as a
linear combination of the maps with Y_i(L), point lights per pixel, environments as a dot
product, sums), AVX2 against the portable code bit for bit, 8-bit maps against float maps
within the quantization bound, EXR and compact files, invariance under turning scene,
lights and viewpoint together, and the `relight` / `panorama` commands."""

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
import trimesh

import panorama_scenes as ps
import reference as ref

hemishadow = pytest.importorskip("hemishadow")
from hemishadow import panorama as pano  # noqa: E402
from hemishadow import png  # noqa: E402
from hemishadow.panorama import compact  # noqa: E402

W, H, K = 61, 32, 16  # a width that is not a multiple of 8: the SIMD blocks' tail


def synthetic(k=K, width=W, height=H, seed=0):
    """Random maps and positions with a background region, as a Panorama."""
    rng = np.random.default_rng(seed)
    coefficients = (rng.normal(size=(height, width, k, 3)) / (1 + np.arange(k))[:, None]).astype(np.float32)
    position = rng.uniform(-3, 3, size=(height, width, 3)).astype(np.float32)
    alpha = np.ones((height, width), np.float32)
    alpha[:5, :] = 0
    alpha[10:12, 20:40] = 0
    coefficients[alpha == 0] = 0
    return pano.Panorama(coefficients=coefficients, position=position, normal=np.zeros_like(position),
                         depth=np.linalg.norm(position, axis=-1), alpha=alpha, origin=(0, 0, 0),
                         rotation=hemishadow.rotation_matrix((1, 2, 3), 0.4), bands=int(math.isqrt(k)))


def as_half(p):
    return p.coefficients.astype(np.float16).astype(np.float64)


def test_sun_is_the_maps_combined_with_y_of_l():
    p = synthetic()
    direction = np.array([0.3, -0.5, 0.8])
    l = direction / np.linalg.norm(direction)
    y = ref.sh_basis_reference(l, 4)
    got = pano.relight(p, [pano.Sun(direction, 2.5, color=(1.0, 0.5, 0.25))])
    expect = np.einsum("hwkc,k->hwc", as_half(p), y) * 2.5 * np.array([1.0, 0.5, 0.25])
    expect[~p.mask] = 0  # black behind a lamp
    assert np.abs(got - expect).max() < 1e-5 * np.abs(expect).max()


@pytest.mark.parametrize("falloff", ["inverse_square", "constant"])
def test_point_light_per_pixel(falloff):
    p = synthetic()
    light = np.array([0.5, 0.7, -0.2])
    got = pano.relight(p, [pano.Point(light, 400.0, color=(0.2, 1.0, 0.6), falloff=falloff)])
    v = light - p.position.astype(np.float64)
    d = np.linalg.norm(v, axis=-1)
    y = ref.sh_basis_reference(v / d[..., None], 4)
    f = 1 / d ** 2 if falloff == "inverse_square" else np.ones_like(d)
    expect = np.einsum("hwkc,hwk->hwc", as_half(p), y) * (f * 400.0 / (4 * np.pi))[..., None] * np.array([0.2, 1.0, 0.6])
    expect[~p.mask] = 0
    assert np.abs(got - expect)[p.mask].max() < 2e-5 * np.abs(expect).max()
    assert (got[~p.mask] == 0).all()


def test_environment_is_a_dot_product_and_fills_the_background():
    p = synthetic()
    rng = np.random.default_rng(3)
    sh = rng.normal(size=(25, 3))  # more bands than the panorama: truncated
    got = pano.relight(p, [pano.Environment(sh, strength=0.5)])
    expect = np.einsum("hwkc,kc->hwc", as_half(p), sh[:K]) * 0.5
    dirs = pano.directions(W, H, p.rotation).astype(np.float64)
    background = np.einsum("hwk,kc->hwc", ref.sh_basis_reference(dirs, 4), sh[:K]) * 0.5
    expect[~p.mask] = background[~p.mask]
    assert np.abs(got - expect).max() < 1e-5 * np.abs(expect).max()


def test_environment_rotation_is_the_mapping_nodes():
    """Rotated by a about Z, the radiance arriving from d is f(Rz(a) d): fitted in numpy."""
    p = synthetic()
    sh = np.random.default_rng(4).normal(size=(16, 3))
    angle = 0.8
    dirs = np.asarray(hemishadow.sh.fibonacci_directions(400))
    c, s = math.cos(angle), math.sin(angle)
    rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    values = ref.sh_basis_reference(dirs @ rz.T, 4) @ sh
    fitted, *_ = np.linalg.lstsq(ref.sh_basis_reference(dirs, 4), values, rcond=None)
    got = pano.relight(p, [pano.Environment(sh, rotation=angle)])
    expect = pano.relight(p, [pano.Environment(fitted)])
    assert np.abs(got - expect).max() < 1e-4 * np.abs(expect).max()


def test_lights_sum_and_exposure_scales():
    p = synthetic()
    lights = [pano.Sun((0, 1, 1), 3.0), pano.Point((1, -1, 0.5), 200.0), pano.Point((-1, 0, 2), 90.0, falloff="constant"),
              pano.Environment(np.random.default_rng(5).normal(size=(16, 3)))]
    total = pano.relight(p, lights)
    parts = sum(pano.relight(p, [light]) for light in lights)
    assert np.abs(total - parts).max() < 1e-5 * np.abs(parts).max()
    brighter = pano.relight(p, lights, exposure=1.5)
    assert np.abs(brighter - total * 2 ** 1.5).max() < 1e-5 * np.abs(brighter).max()


@pytest.mark.parametrize("maps", ["8bit", "float16"])
def test_simd_and_portable_code_agree_to_the_bit(maps):
    if not hemishadow._native.Relighter.simd_available():
        pytest.skip("no AVX2 on this CPU")
    p = synthetic(k=25, width=77)
    lights = [pano.Sun((0.2, 0.1, 1), 2.0), pano.Point((1, -1, 0.5), 200.0), pano.Point((0, 0.5, 1), 50.0, falloff="constant"),
              pano.Environment(np.random.default_rng(6).normal(size=(25, 3)))]
    fast = pano.relight(p, lights, maps=maps, simd=True)
    portable = pano.relight(p, lights, maps=maps, simd=False)
    assert np.array_equal(fast, portable)


def test_eight_bit_maps_stay_within_the_quantization_bound():
    """|8-bit - float| <= sum_i |L_i| scale_i / 510 per pixel and channel (rounding to the
    nearest of 255 steps), and the compact form reloads to the same bytes."""
    p = synthetic()
    sh = np.random.default_rng(7).normal(size=(16, 3))
    exact = np.einsum("hwkc,kc->hwc", p.coefficients.astype(np.float64), sh)
    eight = pano.relight(p, [pano.Environment(sh)], maps="8bit")
    scales = np.stack([compact.quantize(p.coefficients[:, :, i])[1] for i in range(K)])
    bound = (np.abs(sh) * scales).sum(axis=0) / 510
    error = np.abs(eight - exact)[p.mask]
    assert (error <= bound * 1.001 + 1e-6).all()
    assert error.max() > 0.05 * bound.max()  # really quantized
    print(f"8-bit relight error: max {error.max():.4g}, bound {bound.max():.4g}")


def test_exr_and_compact_files_round_trip(tmp_path):
    p = synthetic()
    p.bounce = np.random.default_rng(8).uniform(0, 1, (H, W, 3)).astype(np.float32)
    report = p.save(tmp_path / "p.exr")
    assert report["bytes"] == os.path.getsize(tmp_path / "p.exr")
    e = pano.Panorama.load(tmp_path / "p.exr")
    assert np.array_equal(e.coefficients, p.coefficients.astype(np.float16).astype(np.float32))
    assert np.array_equal(e.position, p.position) and np.array_equal(e.depth, p.depth)
    assert np.array_equal(e.alpha, p.alpha) and np.allclose(e.rotation, p.rotation) and e.bands == 4
    assert np.abs(e.bounce - p.bounce).max() < 1e-3

    report = p.save(tmp_path / "c" / "panorama.json")
    meta = json.loads((tmp_path / "c" / "panorama.json").read_text())
    assert meta["format"] == "hemishadow-panorama" and meta["version"] == 1
    assert (meta["width"], meta["height"], meta["bands"], meta["coefficients"]) == (W, H, 4, K)
    assert [m["file"] for m in meta["maps"]] == [f"sh{i:02d}.png" for i in range(K)]
    c = pano.Panorama.load(tmp_path / "c" / "panorama.json")
    q, scale, offset = c.quantized
    for i in range(K):
        image = png.decode((tmp_path / "c" / f"sh{i:02d}.png").read_bytes())
        assert np.array_equal(image, q[i])
        value = np.asarray(meta["maps"][i]["offset"]) + np.asarray(meta["maps"][i]["scale"]) * image / 255.0
        assert np.abs(value - p.coefficients[:, :, i]).max() <= np.max(meta["maps"][i]["scale"]) / 510 * 1.001 + 1e-7
    assert report["max_quantization_error"] <= scale.max() / 510 * 1.001
    raw = np.fromfile(tmp_path / "c" / "position.f32", "<f4").reshape(H, W, 3)
    assert np.array_equal(raw, p.position) and np.array_equal(c.position, p.position)
    assert np.array_equal(png.decode((tmp_path / "c" / "alpha.png").read_bytes()) == 255, p.mask)
    # A second save over the folder replaces it; no temporary folder stays behind.
    p.save(tmp_path / "c" / "panorama.json")
    assert sorted(os.listdir(tmp_path)) == ["c", "p.exr"]


def test_relit_picture_is_invariant_under_turning_everything():
    """Scene, sun, point light and viewpoint turned together about the viewpoint: the same
    picture, up to the hemispherical rasterization's discretization in turned tangent frames."""
    turn = hemishadow.rotation_matrix((0.4, -0.3, 1.0), 1.1)
    images = []
    for rotation in (np.eye(3), turn):
        _, scene = ps.engine_scene(hemishadow, rotation=rotation)
        baked = pano.bake(scene, (0, 0, 0), size=(48, 24), bands=4, rotation=rotation)
        lights = [pano.Sun(rotation @ np.array([0.4, 0.3, 1.0]), 3.0), pano.Point(rotation @ np.array([0.5, -0.8, 0.6]), 150.0)]
        images.append(pano.relight(baked, lights, maps="float16"))
    a, b = images
    scale = np.abs(a).max()
    diff = np.abs(a - b) / scale
    print(f"turned: mean {diff.mean():.4f}, 99th percentile {np.percentile(diff, 99):.4f}, max {diff.max():.4f}")
    # Measured: mean 0.07 %, 99th percentile 0.5 %, max 0.8 % of the brightest pixel.
    assert diff.mean() < 0.003
    assert np.percentile(diff, 99) < 0.015


def run_cli(*args):
    env = dict(os.environ)
    return subprocess.run([sys.executable, "-m", "hemishadow", *map(str, args)], capture_output=True, text=True, env=env,
                          timeout=300)


def test_panorama_and_relight_commands(tmp_path):
    mesh = trimesh.util.concatenate([trimesh.creation.box((6, 6, 0.2)).apply_translation((0, 0, -1)),
                                     trimesh.creation.icosphere(2, 0.5).apply_translation((1.2, 0.3, -0.4))])
    mesh.export(tmp_path / "scene.ply")
    done = run_cli("panorama", tmp_path / "scene.ply", "--at", "0,0,0", "--size", "32x16", "--coefficients", "9",
                   "--out", tmp_path / "p.exr")
    assert done.returncode == 0, done.stderr
    assert "bake time" in done.stdout
    p = pano.Panorama.load(tmp_path / "p.exr")
    assert (p.width, p.height, p.coefficient_count) == (32, 16, 9)
    hdri = tmp_path / "env.exr"
    from hemishadow.environment import write_exr
    write_exr(hdri, {"": np.random.default_rng(9).uniform(0, 2, (16, 32, 3)).astype(np.float32)})
    args = ["--sun", "0.3,0.2,1,3", "--point", "1,1,0.5,300", "--env", f"{hdri},0.5", "--env-rotation", "30",
            "--exposure", "-0.5"]
    assert run_cli("relight", tmp_path / "p.exr", *args, "--out", tmp_path / "r.exr").returncode == 0
    done = run_cli("relight", tmp_path / "p.exr", *args, "--out", tmp_path / "r.png")
    assert done.returncode == 0, done.stderr
    from hemishadow.environment import read_exr
    from hemishadow.panorama.picture import srgb
    linear = read_exr(tmp_path / "r.exr")
    picture = png.decode((tmp_path / "r.png").read_bytes())
    assert np.array_equal(picture, srgb(linear))
    # The same lights through the API.
    image = read_exr(hdri)
    mapping = hemishadow.euler_to_matrix((0, 0, math.radians(30)))
    sh = hemishadow.project_environment(image, bands=3, rotation=mapping)
    api = pano.relight(p, [pano.Sun((0.3, 0.2, 1), 3), pano.Point((1, 1, 0.5), 300), pano.Environment(sh, 0.5)],
                       exposure=-0.5)
    assert np.abs(api - linear)[p.mask].max() < 1e-5 * np.abs(api).max()
    # The background shows the HDRI itself; errors are one clear line and write nothing.
    assert np.abs(linear[~p.mask]).max() > 0
    done = run_cli("relight", tmp_path / "p.exr", "--sun", "0,0,1,3", "--out", tmp_path / "r.png" / "x.png")
    assert done.returncode == 2 and "cannot write" in done.stderr
    done = run_cli("relight", tmp_path / "p.exr", "--out", tmp_path / "s.png")
    assert done.returncode == 2 and "no light" in done.stderr
    done = run_cli("panorama", tmp_path / "scene.ply", "--at", "1.2,0.3,-0.4", "--size", "32x16", "--out", tmp_path / "q.exr")
    assert done.returncode == 2 and "inside geometry" in done.stderr
    assert not (tmp_path / "q.exr").exists() and not (tmp_path / "s.png").exists()


def test_open_floor_radiance_follows_blenders_lamp_conventions():
    """An open floor seen from above: radiance = albedo / pi x E x clamped cosine for a sun
    of strength E, albedo / pi x P / (4 pi d^2) x cosine for a point lamp of power P (DESIGN.md),
    the cosine band-limited to the panorama's SH (the exact open transfer, tests/reference.py)."""
    scene = hemishadow.Scene()
    scene.add_instance(scene.add_mesh(np.array([[-50, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0]], np.float32),
                                      np.array([[0, 1, 2], [0, 2, 3]])))
    baked = pano.bake(scene, (0, 0, 1.5), size=(48, 24), bands=5, albedo=(0.8, 0.6, 0.4))
    floor = baked.mask & (np.abs(baked.position[..., :2]).max(axis=-1) < 5)
    assert floor.sum() > 100
    albedo = np.array([0.8, 0.6, 0.4]) / np.pi
    up = ref.unoccluded_transfer(np.array([[0.0, 0.0, 1.0]]), 5)[0]
    sun = np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0])
    got = pano.relight(baked, [pano.Sun(sun, 3.0)])[floor]
    expect = albedo * 3.0 * (up @ ref.sh_basis_reference(sun, 5))
    assert np.abs(got / expect - 1).max() < 0.01
    assert abs(up @ ref.sh_basis_reference(sun, 5) / sun[2] - 1) < 0.03  # the band-limited cosine is close
    lamp = np.array([0.5, -0.4, 2.0])
    got = pano.relight(baked, [pano.Point(lamp, 500.0)])[floor]
    v = lamp - baked.position[floor].astype(np.float64)
    d = np.linalg.norm(v, axis=-1)
    cosine = np.einsum("k,nk->n", up, ref.sh_basis_reference(v / d[:, None], 5))
    expect = albedo[None] * (500.0 / (4 * np.pi * d ** 2) * cosine)[:, None]
    assert np.abs(got / expect - 1).max() < 0.01


def test_png_round_trips_grey_rgb_and_rgba_bit_for_bit(tmp_path):
    """hemishadow.png (the compact maps' and the lightmaps' 8-bit files): every layout back
    as written, including the Up filter's wrap-around, and the lightmaps' RGBA writer."""
    import hemishadow.lightmap.encode as encode

    rng = np.random.default_rng(3)
    for shape in ((7, 5), (6, 9, 3), (4, 3, 4)):
        image = rng.integers(0, 256, shape, dtype=np.uint8)
        assert np.array_equal(png.decode(png.encode(image)), image), shape
    with pytest.raises(ValueError, match="uint8"):
        png.encode(np.zeros((2, 2, 2), np.uint8))
    rgba = rng.integers(0, 256, (5, 8, 4), dtype=np.uint8)
    encode.write_png(tmp_path / "m.png", rgba)
    assert np.array_equal(png.decode((tmp_path / "m.png").read_bytes()), rgba)
