"""The 32 x 32 visibility-mask cells as a quadrature over the hemisphere (numpy).

`Scene.visibility` sets a cell when the direction through its sample point (its centre, or
its centroid inside the disk for rim cells) is blocked, in the frame the engine builds from the
receiver's normal (Duff et al. 2017, as native/engine/src/mesh.rs::tangent_frame). Here each
cell also gets its exact first moment M_c = integral of s over the cell's solid angle, found
once by fine quadrature in (theta, phi), which has no 1/z singularity at the rim: the
integral of any clamped cosine max(0, v.s) over the open cells is then sum max(0, v.M_c).
"""

import functools

import numpy as np

SIDE = 32
CELLS = SIDE * SIDE
_RIM_SUBSAMPLES = 16  # as native/engine/src/disk_mask.rs::measure_cell


def engine_frame(normals):
    """Tangent and bitangent (P, 3) the engine completes unit normals (P, 3) with."""
    n = np.asarray(normals, dtype=np.float64)
    sign = np.where(np.signbit(n[:, 2]), -1.0, 1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    bt = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return t, bt


def unpack(masks):
    """Raw masks (P, 16) uint64 -> bool (P, 1024), True where blocked; cell r*32+c."""
    masks = np.ascontiguousarray(masks, dtype="<u8")
    bits = np.unpackbits(masks.view(np.uint8).reshape(len(masks), -1), axis=1, bitorder="little")
    return bits.astype(bool)


def centre(index):
    return -1.0 + (np.asarray(index) + 0.5) * (2.0 / SIDE)


@functools.cache
def directions():
    """Sample direction (1024, 3) of each cell in the receiver's frame; zero where the cell
    misses the disk (the engine never sets those). Rim cells: the centroid of their
    16 x 16 subsamples inside the disk, all cells at once."""
    x0, y0 = np.meshgrid(centre(np.arange(SIDE)), centre(np.arange(SIDE)))   # [row, col]
    x0, y0 = x0.ravel(), y0.ravel()
    x, y = x0.copy(), y0.copy()
    rim = (np.abs(x0) + 1.0 / SIDE) ** 2 + (np.abs(y0) + 1.0 / SIDE) ** 2 > 1.0
    sub = (np.arange(_RIM_SUBSAMPLES) + 0.5) / _RIM_SUBSAMPLES * (2.0 / SIDE) - 1.0 / SIDE
    xs = x0[rim, None, None] + sub[None, None, :]                              # (rim, 16, 16): [cell, j, i]
    ys = y0[rim, None, None] + sub[None, :, None]
    xs, ys = np.broadcast_arrays(xs, ys)
    inside = xs * xs + ys * ys < 1.0
    count = inside.sum(axis=(1, 2))
    with np.errstate(invalid="ignore"):
        x[rim] = np.where(inside, xs, 0.0).sum(axis=(1, 2)) / count
        y[rim] = np.where(inside, ys, 0.0).sum(axis=(1, 2)) / count
    out = np.stack([x, y, np.sqrt(np.maximum(0.0, 1.0 - x * x - y * y))], axis=1)
    out[np.flatnonzero(rim)[count == 0]] = 0.0
    return out


_MOMENTS = []


def moments(check=None):
    """(1024, 4): M_c, the integral of s over each cell's solid angle in the receiver's frame
    (its z components add up to pi, the cosine-weighted hemisphere, to 1e-6), and the cell's
    solid angle. Computed once by the engine (`_native.cell_moments`, about 10 ms: the
    quadrature of `integrate_moments`), then cached; `check` is called first (a cancel)."""
    if check is not None:
        check()
    if not _MOMENTS:
        from .. import _native

        _MOMENTS.append(_native.cell_moments())
    return _MOMENTS[0]


def integrate_moments(check=None, nt=1024, nphi=2048, bands=16):
    """`moments` in numpy (about 0.1 to 0.5 s), the reference the engine's is tested against:
    a midpoint rule in (theta, phi), each point to the cell its direction projects into."""
    theta = (np.arange(nt) + 0.5) * (np.pi / 2 / nt)
    phi = (np.arange(nphi) + 0.5) * (2 * np.pi / nphi)
    total = np.zeros((CELLS, 4))
    for rows in np.array_split(np.arange(nt), bands):
        if check is not None:
            check()
        st = np.sin(theta[rows])[:, None]
        s = np.stack(np.broadcast_arrays(st * np.cos(phi), st * np.sin(phi), np.cos(theta[rows])[:, None]),
                     axis=-1).reshape(-1, 3)
        weight = np.broadcast_to(st * (np.pi / 2 / nt) * (2 * np.pi / nphi), (len(rows), nphi)).reshape(-1)
        col = np.clip(((s[:, 0] + 1) * (SIDE / 2)).astype(np.int64), 0, SIDE - 1)
        row = np.clip(((s[:, 1] + 1) * (SIDE / 2)).astype(np.int64), 0, SIDE - 1)
        index = row * SIDE + col
        total += np.stack([np.bincount(index, s[:, k] * weight, CELLS) for k in range(3)]
                          + [np.bincount(index, weight, CELLS)], axis=1)
    return total


@functools.cache
def radiance_directions():
    """Where each cell samples the lighting (1024, 3): its engine sample direction, or the
    mean direction of its sliver for cells the engine never sets."""
    d = directions().copy()
    m = moments()[:, :3]
    empty = ~d.any(axis=1) & m.any(axis=1)
    d[empty] = m[empty] / np.linalg.norm(m[empty], axis=1, keepdims=True)
    d[~d.any(axis=1)] = (0.0, 0.0, 1.0)  # no solid angle: any direction
    return d


def largest_cell_ao():
    """The most one cell adds to ambient occlusion (1 = open): its share of the cosine-weighted
    hemisphere, about 1/800 (a 32 x 32 grid's cell's share of the unit disk)."""
    return float(moments()[:, 2].max() / np.pi)


def open_clamped_cosine(cos_angle):
    """Integral of max(0, v.s) over the hemisphere of n, for unit v at cos_angle = v.n."""
    return np.pi * (1.0 + np.clip(cos_angle, -1.0, 1.0)) / 2.0


def lobe_weights(v_local):
    """Weights (..., 1024) of each cell for the clamped cosine around unit directions v_local
    (..., 3) given in the receiver's frame: max(0, v.M_c), rescaled so that the open
    hemisphere gives the exact integral (the linear form is 0.07 % low for a b_i lobe, on cells
    that the lobe's edge crosses)."""
    m = moments()[:, :3].astype(np.float32)
    w = np.maximum(np.asarray(v_local, dtype=np.float32) @ m.T, 0.0)
    total = w.sum(axis=-1, keepdims=True)
    exact = open_clamped_cosine(v_local[..., 2:3]).astype(np.float32)
    return w * np.where(total > 0, exact / np.maximum(total, 1e-30), 0.0)
