"""Point, spot and area lamps in the probe bake (issue 12), the engine part: their direct light
on the six sides and in the SH9 against closed forms and fine quadrature, shadows, and the
light they give the bounce surfaces. Worst probe checked. Run from a worktree with
PYTHONPATH=native/python when the installed package is another checkout's.
"""

import math

import numpy as np
import pytest

hemishadow = pytest.importorskip("hemishadow")
import hemishadow.probes as hp  # noqa: E402
from hemishadow.lightmap import Area, Point, Spot, Surface  # noqa: E402
from test_probes import box, scene_of, speck  # noqa: E402


def delta_probe(intensity, lamp, point):
    """Sides (6,) and SH9 (9,) of a point source of `intensity` W/sr at `lamp` seen from `point`."""
    to = np.asarray(lamp, float) - point
    d2 = to @ to
    w = to / math.sqrt(d2)
    e = intensity / d2
    return e * np.maximum(hp.AXES @ w, 0) / math.pi, e * hemishadow.sh_basis(w[None].astype(np.float32), 3)[0]


def test_point_lamp_matches_the_inverse_square_law_on_every_side_and_in_sh9():
    """Probes around a 100 W point lamp, one level with it (a direction in the plane of +Z
    and -Z) and one on an axis: every side and SH coefficient as the closed form (1e-4)."""
    lamp = np.array([0.3, -0.2, 1.0])
    pts = np.array([[2.0, 0.5, 1.0], [0.3, -0.2, -1.5], [-1.0, 1.2, 2.5], [0.3, 2.0, 1.0]])
    out = hp.bake(speck(), pts, lamps=[Point(lamp, power=100.0)])
    for k, p in enumerate(pts):
        sides, sh9 = delta_probe(100.0 / (4 * math.pi), lamp, p)
        assert np.abs(out["cube"][k] - sides[:, None]).max() < 1e-4 * sides.max(), (k, out["cube"][k, :, 0], sides)
        assert np.abs(out["sh9"][k] - sh9[:, None]).max() < 1e-4 * abs(sh9[0]), (k, out["sh9"][k, :, 0], sh9)


def test_area_lamp_matches_quadrature_and_rgb_power_colours_it():
    """A 1 m square area lamp at 1.5 to 3 m (a wide source): the sides against a 200 x 200
    quadrature of its Lambertian radiance P / (pi A); worst side within 1.5 % of the probe's
    brightest side with the baker's 16 points on the lamp."""
    power = np.array([200.0, 100.0, 50.0])
    position, direction, u = np.array([0.0, 0.0, 2.0]), np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0])
    pts = np.array([[0.0, 0.0, 0.5], [1.5, 0.5, 0.0], [-0.8, -1.0, -1.0]])
    out = hp.bake(speck(), pts, lamps=[Area(position, direction, u, power=power, size=1.0)])
    g = (np.arange(200) + 0.5) / 200 - 0.5
    x, y = np.meshgrid(g, g)
    on_lamp = np.stack([x.ravel(), y.ravel(), np.full(x.size, 2.0)], 1)
    for k, p in enumerate(pts):
        to = on_lamp - p
        d2 = (to ** 2).sum(1)
        w = to / np.sqrt(d2)[:, None]
        e = (1.0 / math.pi) * np.maximum(-(w @ direction), 0) / d2 / 200 ** 2  # radiance x dA cos / d^2, per W
        sides = (np.maximum(w @ hp.AXES.T, 0) * e[:, None]).sum(0) / math.pi
        err = np.abs(out["cube"][k] - sides[:, None] * power).max(0) / (sides.max() * power)
        assert err.max() < 0.015, (k, err, out["cube"][k, :, 0], sides * power[0])
        sh0 = e.sum() * 0.282095 * power  # band 0: the irradiance from every direction, times Y00
        assert np.allclose(out["sh9"][k, 0], sh0, rtol=0.01)


def test_lamps_are_shadowed_and_spots_masked():
    """A wall between a point lamp and a probe: black; the probe beside it: lit. A spot
    pointing down lights a probe inside its cone, not one outside it. (The 5 cm radius spreads
    the point lamp's light over a disk: 1 % of it reaches the sides across.)"""
    wall = box([0.0, -2.0, -2.0], [0.2, 2.0, 2.0])
    scene, _ = scene_of(wall)
    lamp = np.array([1.0, 0.0, 0.0])
    pts = np.array([[-1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 0.0, -1.0], [2.5, 0.0, -1.0]])
    out = hp.bake(scene, pts, lamps=[Point(lamp, power=50.0, radius=0.05),
                                     Spot(lamp, (0.0, 0.0, -1.0), power=50.0, spot_size=math.radians(60),
                                          spot_blend=0.0)])
    assert np.abs(out["cube"][0]).max() < 1e-7 and np.abs(out["sh9"][0]).max() < 1e-7
    point_only, _ = delta_probe(50.0 / (4 * math.pi), lamp, pts[1])
    assert np.allclose(out["cube"][1, :, 0], point_only, rtol=0.01, atol=0.011 * point_only.max())  # outside the cone
    both, _ = delta_probe(2 * 50.0 / (4 * math.pi), lamp, pts[2])
    assert np.allclose(out["cube"][2, :, 0], both, rtol=0.01, atol=0.011 * both.max())  # straight below: both
    one, _ = delta_probe(50.0 / (4 * math.pi), lamp, pts[3])  # 56 degrees off the spot's axis: outside
    assert np.allclose(out["cube"][3, :, 0], one, rtol=0.01, atol=0.011 * one.max())


def test_a_point_lamp_lights_the_bounce_surfaces():
    """A point lamp 2 m over a 12 m floor of albedo 0.5, a probe 1 m over the floor: its -Z
    side (light from the floor only) against quadrature of the floor's radiance
    albedo x E / pi (E = I h / d^3) within 4 %; without bounces it is black; +Z sees the lamp
    only, the same both ways."""
    n = 48
    g = np.linspace(-6, 6, n + 1)
    x, y = np.meshgrid(g, g)
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    quads = np.array([[i * (n + 1) + j, i * (n + 1) + j + 1, (i + 1) * (n + 1) + j + 1, (i + 1) * (n + 1) + j]
                      for i in range(n) for j in range(n)])
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    scene, (floor,) = scene_of((verts, tris))
    lamp, intensity = np.array([0.0, 0.0, 2.0]), 400.0 / (4 * math.pi)
    probe = np.array([[0.5, 0.0, 1.0]])
    kwargs = dict(lamps=[Point(lamp, power=400.0)], surfaces=[Surface(floor, verts, tris, albedo=0.5)])
    direct = hp.bake(scene, probe, bounces=0, **kwargs)
    assert np.abs(direct["cube"][0, 5]).max() < 1e-7
    lit = hp.bake(scene, probe, bounces=1, **kwargs)
    q = (np.arange(1200) + 0.5) / 1200 * 12 - 6
    qx, qy = np.meshgrid(q, q)
    d_lamp = np.sqrt(qx ** 2 + qy ** 2 + 4.0)
    radiance = 0.5 * intensity * 2.0 / d_lamp ** 3 / math.pi
    r2 = (qx - 0.5) ** 2 + qy ** 2 + 1.0
    expected = (radiance / r2 ** 2 * (12 / 1200) ** 2).sum() / math.pi  # cos x cos / r^2 with both cos = 1 / r
    got = lit["cube"][0, 5, 0]
    assert abs(got / expected - 1) < 0.04, (got, expected)
    # +Z sees the lamp, not the floor (which would add a few % of `got`); 1e-4: float rounding
    assert np.allclose(lit["cube"][0, 4], direct["cube"][0, 4], rtol=1e-4)


def test_bad_lamps_are_named():
    with pytest.raises(ValueError, match="lamp 0"):
        hp.bake(speck(), np.zeros((1, 3)), lamps=[Point((0.0, 0.0, math.nan))])
    with pytest.raises(ValueError, match="lamp_points"):
        hp.bake(speck(), np.zeros((1, 3)), lamps=[Point((0.0, 0.0, 1.0))], lamp_points=0)
