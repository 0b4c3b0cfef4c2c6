"""Probe files: `.npz` for Python and tools, JSON for engines; both written atomically
(temporary file beside the target, then os.replace). Conventions: docs/probes.md."""

import json
import os
import tempfile

import numpy as np

from ..sh import rotate_sh

KEYS = ("positions", "cube", "sh9", "valid", "grid_matrix", "grid_resolution")

#: Blender (+Z up) -> a +Y-up engine (glTF): (x, y, z) -> (x, z, -y).
Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
#: Side k of the Y-up cube is side Y_UP_SIDES[k] of the Blender cube (+X, -X, +Y', -Y', +Z', -Z').
Y_UP_SIDES = (0, 1, 4, 5, 3, 2)

SHADER = """\
side j = (1/pi) * integral L(w) max(0, w.a_j) dw, a = (+X, -X, +Y, -Y, +Z, -Z): the radiance of a white
Lambertian surface facing a_j (irradiance / pi). Diffuse colour = albedo * C(n) with
C(n) = n.x^2 * (n.x < 0 ? cube[1] : cube[0]) + n.y^2 * (n.y < 0 ? cube[3] : cube[2])
     + n.z^2 * (n.z < 0 ? cube[5] : cube[4]).
sh9: integral of L(w) Y_k(w) dw (radiance, not divided by pi); real orthonormal SH with the Condon-Shortley phase:
Y0 = 0.282095, Y1 = -0.488603 y, Y2 = 0.488603 z, Y3 = -0.488603 x, Y4 = 1.092548 xy, Y5 = -1.092548 yz,
Y6 = 0.315392 (3z^2 - 1), Y7 = -1.092548 xz, Y8 = 0.546274 (x^2 - y^2).
Irradiance / pi for normal n: sum_k A_l(k) / pi * sh9[k] * Y_k(n), A = (pi, 2pi/3, pi/4) for bands 0, 1, 2.
Grid: probe index (i, j, k) -> world = grid_matrix * (i, j, k, 1); probes in C order of (i, j, k):
number = (i * res_y + j) * res_z + k. Blender places them at local (i + 1) / (res + 1) * 2 - 1 of the volume.
Interpolate trilinearly over the 8 probes of a cell, dropping probes with valid = false and probes the point
cannot see (a ray or depth test), renormalising the weights."""

Y_UP_NOTE = """\
Blender is +Z up. For a +Y-up engine: positions p' = (p.x, p.z, -p.y); grid_matrix' = R * grid_matrix with
R = [[1,0,0,0],[0,0,1,0],[0,-1,0,0],[0,0,0,1]]; cube' = cube[[0, 1, 4, 5, 3, 2]] (+X, -X, +Z, -Z, -Y, +Y of
Blender); sh9' = the SH rotated by R (hemishadow.probes.files.y_up does all of it). Engines whose band-1 basis
has no Condon-Shortley phase (+0.488603 y, +0.488603 x, Sloan's tables) negate coefficients 1, 3, 5 and 7."""


def _atomic(path, write, suffix):
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".hemishadow-", suffix=suffix)
    try:
        with os.fdopen(fd, "wb") as handle:
            write(handle)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _arrays(probes):
    p = len(probes["positions"])
    matrix = probes.get("grid_matrix")
    res = probes.get("grid_resolution")
    return {
        "positions": np.asarray(probes["positions"], np.float32),
        "cube": np.asarray(probes["cube"], np.float32),
        "sh9": np.asarray(probes["sh9"], np.float32),
        "valid": np.asarray(probes["valid"], bool),
        # a list of points has no grid: identity and (P, 1, 1)
        "grid_matrix": np.eye(4) if matrix is None else np.asarray(matrix, np.float64),
        "grid_resolution": np.array([p, 1, 1], np.int64) if res is None else np.asarray(res, np.int64),
    }


def write_npz(path, probes):
    arrays = _arrays(probes)
    _atomic(path, lambda f: np.savez(f, **arrays), ".npz")


def read_npz(path):
    """The arrays of a probe file; a point-list file (grid (P, 1, 1), identity) drops the grid keys."""
    with np.load(path) as data:
        out = {k: data[k] for k in data.files}
    missing = [k for k in ("positions", "cube", "sh9", "valid") if k not in out]
    if missing:
        raise ValueError(f"{path}: not a probe file, missing {missing}")
    if "grid_resolution" in out and np.array_equal(out["grid_resolution"], [len(out["positions"]), 1, 1]) \
            and np.array_equal(out.get("grid_matrix"), np.eye(4)):
        out.pop("grid_matrix"), out.pop("grid_resolution")
    return out


def to_json(probes):
    a = _arrays(probes)
    return {"format": "hemishadow-probes", "version": 1, "up": "+Z (Blender)", "units": "irradiance / pi",
            "side_order": ["+X", "-X", "+Y", "-Y", "+Z", "-Z"], "shader": SHADER, "y_up": Y_UP_NOTE,
            "count": int(len(a["positions"])),
            **{k: v.tolist() for k, v in a.items()}}


def write_json(path, probes):
    text = json.dumps(to_json(probes), separators=(",", ":")).encode()
    _atomic(path, lambda f: f.write(text), ".json")


def y_up(probes):
    """The arrays converted for a +Y-up engine (see `Y_UP_NOTE`)."""
    a = _arrays(probes)
    r4 = np.eye(4)
    r4[:3, :3] = Y_UP
    return {"positions": (a["positions"] @ Y_UP.T).astype(np.float32),
            "cube": a["cube"][:, list(Y_UP_SIDES)],
            "sh9": np.stack([rotate_sh(s, Y_UP) for s in a["sh9"]]) if len(a["sh9"]) else a["sh9"],
            "valid": a["valid"], "grid_matrix": r4 @ a["grid_matrix"], "grid_resolution": a["grid_resolution"]}
