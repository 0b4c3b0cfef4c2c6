"""Test meshes: the shared assets at rest, and procedural ones with hard cases (deep crevices,
both faces of a sheet seen at grazing angles). Plain numpy and trimesh, no pytest."""

import math
import pathlib

import numpy as np
import trimesh

DATA = pathlib.Path(__file__).resolve().parents[2] / "shared" / "data"


def grid(half, n, z=0.0, facing_down=False):
    """Flat square (n x n vertices) in the plane at height z, facing +Z unless facing_down."""
    c = np.linspace(-half, half, n)
    x, y = np.meshgrid(c, c, indexing="ij")
    vertices = np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c_, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    triangles = np.concatenate([np.stack([a, b, c_], -1).reshape(-1, 3), np.stack([a, c_, d], -1).reshape(-1, 3)])
    return vertices, (triangles[:, ::-1] if facing_down else triangles)


def tube(centre_line, radius, sides):
    """Closed tube around a closed curve (K, 3); frames from the curve tangent and +Z,
    which is never parallel to the tangent for the curves used here."""
    tangent = np.roll(centre_line, -1, axis=0) - np.roll(centre_line, 1, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    side = np.cross(tangent, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    up = np.cross(tangent, side)
    angle = 2.0 * math.pi * np.arange(sides) / sides
    ring = np.cos(angle)[None, :, None] * side[:, None] + np.sin(angle)[None, :, None] * up[:, None]
    vertices = (centre_line[:, None] + radius * ring).reshape(-1, 3)
    return vertices, _quads(len(centre_line), sides, wrap_u=True, wrap_v=True)


def _quads(nu, nv, wrap_u, wrap_v):
    """Two triangles per cell of an nu x nv vertex grid (index u * nv + v), optionally
    wrapping around in u and v."""
    u, v = np.meshgrid(np.arange(nu if wrap_u else nu - 1), np.arange(nv if wrap_v else nv - 1), indexing="ij")
    a = u * nv + v
    b = ((u + 1) % nu) * nv + v
    c = ((u + 1) % nu) * nv + (v + 1) % nv
    d = u * nv + (v + 1) % nv
    return np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])


def torus_knot(p=2, q=3, samples=240, sides=14, radius=0.4):
    """Closed (p, q) torus knot tube: strands pass close over each other (deep crevices)."""
    t = 2.0 * math.pi * np.arange(samples) / samples
    r = 2.0 + np.cos(q * t)
    line = np.stack([r * np.cos(p * t), r * np.sin(p * t), -np.sin(q * t)], axis=1)
    return tube(line, radius, sides)


def rolled_sheet(nu=120, nv=24, turns=1.25, growth=0.4):
    """Open cloth-like sheet loosely rolled into a wrinkled spiral: receivers inside the roll
    see both faces of the sheet (culling blockers by facing would show here) at grazing
    angles. Loose enough that no receiver is nearly enclosed (reference AO >= 0.05)."""
    angle = 2.0 * math.pi * turns * np.linspace(0.0, 1.0, nu)
    y = np.linspace(-1.5, 1.5, nv)
    radius = (0.5 + growth * angle / math.pi)[:, None] + 0.04 * np.sin(9.0 * y)[None, :]  # wrinkles along y
    vertices = np.stack([radius * np.cos(angle)[:, None], np.broadcast_to(y, radius.shape),
                         radius * np.sin(angle)[:, None]], axis=-1).reshape(-1, 3)
    return vertices, _quads(nu, nv, wrap_u=False, wrap_v=False)


def load_asset(name):
    """A shared asset at its rest pose, as trimesh reads it (glTF: scene flattened)."""
    mesh = trimesh.load(DATA / name, force="mesh", process=False)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


MESHES = {
    "spot": lambda: load_asset("spot.obj"),
    "teapot": lambda: load_asset("teapot.obj"),
    "bunny": lambda: load_asset("bunny.obj"),
    "cesium_man": lambda: load_asset("cesium_man.glb"),
    "fox": lambda: load_asset("fox.glb"),
    "rigged_figure": lambda: load_asset("rigged_figure.glb"),
    "torus_knot": torus_knot,
    "rolled_sheet": rolled_sheet,
}
