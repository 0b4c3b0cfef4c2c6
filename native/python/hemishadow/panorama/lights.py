"""Lights for relighting, with Blender's conventions as Cycles renders them (DESIGN.md):
a sun's strength is the irradiance (W/m^2) on a surface facing it, its direction points
TOWARDS the light; a point lamp of power P radiates P / (4 pi) W/sr; an environment is the
SH (k, 3) of its incident radiance. Colour multiplies strength and power.

Each becomes SH weights of the incident light: a sun L_i = E Y_i(l), an environment its
coefficients, a point light L_i = I f(d) Y_i(l) per pixel (computed by the engine).
"""

from dataclasses import dataclass

import numpy as np

FALLOFFS = ("inverse_square", "constant")


@dataclass
class Sun:
    direction: tuple
    strength: float = 1.0
    color: tuple = (1.0, 1.0, 1.0)


@dataclass
class Point:
    """falloff: "inverse_square" (physical), or "constant" (Wong et al.'s option without
    distance falloff: every pixel lit as if the lamp were 1 m away)."""
    position: tuple
    power: float = 1000.0
    color: tuple = (1.0, 1.0, 1.0)
    falloff: str = "inverse_square"


@dataclass
class Environment:
    """Radiance SH (k, 3); `rotation` (radians about +Z) turns it as the World's Mapping node
    does (the lookup vector is rotated before sampling)."""
    sh: object
    strength: float = 1.0
    rotation: float = 0.0


def _rgb(value, label):
    a = np.broadcast_to(np.asarray(value, dtype=np.float64), (3,))
    if np.asarray(value).size not in (1, 3) or not np.isfinite(a).all():
        raise ValueError(f"{label} must be a finite number or RGB triple, got {value!r}")
    return a


def _unit(vector, label):
    v = np.asarray(vector, dtype=np.float64)
    n = np.linalg.norm(v) if v.shape == (3,) else 0.0
    if v.shape != (3,) or not np.isfinite(v).all() or n == 0:
        raise ValueError(f"{label} must be a finite, non-zero (x, y, z), got {vector!r}")
    return v / n


def environment_sh(light, coeffs):
    """An Environment's SH as (coeffs, 3) float64, truncated or zero-padded, rotated, scaled."""
    from ..sh import rotate_sh, rotation_matrix

    sh = np.asarray(light.sh, dtype=np.float64)
    if sh.ndim != 2 or sh.shape[1] != 3 or int(round(np.sqrt(len(sh)))) ** 2 != len(sh) or not np.isfinite(sh).all():
        raise ValueError(f"an Environment's sh must be finite (k, 3) with k = 1, 4, 9, 16, 25..., got shape {sh.shape}")
    if light.rotation:
        # Mapping node: radiance from d is f(R d) = rotate_sh(f, R^T).
        sh = rotate_sh(sh, rotation_matrix((0, 0, 1), float(light.rotation)).T).astype(np.float64)
    out = np.zeros((coeffs, 3))
    n = min(coeffs, len(sh))
    out[:n] = sh[:n]
    return out * float(light.strength)


def weights(lights, coeffs, scale=1.0):
    """(uniform (k, 3), points (n, 7), background (k, 3)) float32 for the engine; `scale`
    multiplies everything (exposure)."""
    from .. import sh_basis

    bands = int(round(np.sqrt(coeffs)))
    uniform = np.zeros((coeffs, 3))
    background = np.zeros((coeffs, 3))
    points = []
    for i, light in enumerate(lights):
        label = f"light {i} ({type(light).__name__})"
        if isinstance(light, Sun):
            y = sh_basis(_unit(light.direction, f"{label}: direction")[None, :], bands)[0].astype(np.float64)
            uniform += y[:, None] * (float(light.strength) * _rgb(light.color, f"{label}: color"))[None, :]
        elif isinstance(light, Environment):
            sh = environment_sh(light, coeffs)
            uniform += sh
            background += sh
        elif isinstance(light, Point):
            if light.falloff not in FALLOFFS:
                raise ValueError(f"{label}: falloff must be one of {FALLOFFS}, got {light.falloff!r}")
            position = np.asarray(light.position, dtype=np.float64)
            if position.shape != (3,) or not np.isfinite(position).all():
                raise ValueError(f"{label}: position must be a finite (x, y, z)")
            intensity = float(light.power) / (4 * np.pi) * _rgb(light.color, f"{label}: color")
            points.append([*position, *intensity, 1.0 if light.falloff == "inverse_square" else 0.0])
        else:
            raise ValueError(f"{label}: not a Sun, Point or Environment")
    points = np.asarray(points, dtype=np.float64).reshape(-1, 7)
    points[:, 3:6] *= scale
    return ((uniform * scale).astype(np.float32), np.ascontiguousarray(points, dtype=np.float32),
            (background * scale).astype(np.float32))
