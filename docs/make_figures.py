"""Regenerate every figure in docs/images/ (deterministic; matplotlib, Agg backend).

Run from the repository root:

    .venv/bin/python docs/make_figures.py

Figures:
  visibility_mask.png  one receiver of spot.obj: its 32x32 mask, the 8x8 grey occlusion term,
                       and one blocker triangle as the AND of three half-spaces
  spot_ao.png          spot.obj coloured by per-vertex ambient occlusion
  spot_shaded.png      spot.obj lit by Blender's "forest" HDRI, without and with self-shadowing
  accuracy.png         relative L2 error per mesh, from tests/.results/transfer_accuracy.json
                       (skipped when that file does not exist: run the accuracy tests first)
"""

from __future__ import annotations

import json
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402

import hemishadow  # noqa: E402
from hemishadow.environment import default_hdri  # noqa: E402
from hemishadow.meshio import linear_to_srgb8, load_mesh  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
IMAGES = ROOT / "docs" / "images"
SPOT = ROOT / "tests" / "assets" / "spot.obj"
ACCURACY = ROOT / "tests" / ".results" / "transfer_accuracy.json"

# OBJ is +Y up; Blender (and the CLI with --up auto) turns it to +Z up: (x, y, z) -> (x, -z, y).
Y_UP_TO_Z_UP = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=np.float32)
ALBEDO = 0.8  # as the CLI
BACKGROUND = (0.22, 0.24, 0.27)  # behind the shaded renders
CELL = 2.0 / 32  # side of a mask cell in disk coordinates

plt.rcParams.update({
    "font.size": 9,
    "axes.titlesize": 10,
    "figure.dpi": 100,
    "savefig.dpi": 150,
    "svg.hashsalt": "hemishadow",
})


# --- mesh helpers ----------------------------------------------------------------------------


def load_spot():
    """spot.obj in Blender's +Z-up world: vertices as stored (split at UV seams) and triangles."""
    vertices, triangles, _ = load_mesh(SPOT)
    return np.ascontiguousarray(vertices @ Y_UP_TO_Z_UP.T), triangles


def weld(vertices, triangles):
    """Weld by exact position, as the engine does: (positions, triangles, input -> welded)."""
    positions, first, remap = np.unique(vertices, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)  # number welded vertices in order of first appearance, like the engine
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    remap = rank[remap.ravel()]
    welded = remap[triangles]
    keep = (welded[:, 0] != welded[:, 1]) & (welded[:, 1] != welded[:, 2]) & (welded[:, 2] != welded[:, 0])
    return np.ascontiguousarray(positions[order]), welded[keep].astype(np.uint32), remap


def area_normals(positions, triangles):
    """Area-weighted vertex normals, as the engine computes them when none are given."""
    p = positions.astype(np.float64)
    face = np.cross(p[triangles[:, 1]] - p[triangles[:, 0]], p[triangles[:, 2]] - p[triangles[:, 0]])
    sums = np.zeros_like(p)
    for k in range(3):
        np.add.at(sums, triangles[:, k], face)
    return sums / np.linalg.norm(sums, axis=1, keepdims=True)


def tangent_frame(n):
    """The engine's tangent frame (Duff et al. 2017, mesh.rs::tangent_frame)."""
    nx, ny, nz = n
    sign = np.copysign(1.0, nz)
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    t = np.array([1.0 + sign * nx * nx * a, sign * b, -sign * nx])
    bt = np.array([b, sign + ny * ny * a, -ny])
    return t, bt


def mean_edge_length(positions, triangles):
    p = positions.astype(np.float64)[triangles]
    return float(np.mean(np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2)))


def unoccluded_transfer(normals, bands=5):
    """A_l Y_lm(n): the transfer of a receiver that nothing blocks (clamped-cosine zonal SH)."""
    zonal = [np.pi, 2 * np.pi / 3, np.pi / 4, 0.0, -np.pi / 24][:bands]
    y = hemishadow.sh_basis(normals, bands)
    return (y * np.repeat(zonal, [2 * l + 1 for l in range(bands)])[None]).astype(np.float32)


# --- a small software renderer: orthographic z-buffer, Gouraud colours, 2x supersampling --------


def render(vertices, triangles, colors, view_dir, up=(0.0, 0.0, 1.0), size=(720, 560), background=1.0, margin=0.06,
           ss=2):
    """Image (H, W, C) of a mesh with per-vertex colours (N, C) seen along -view_dir.

    view_dir points from the object towards the camera. Returns the image and a function
    mapping world points to pixel coordinates (for overlays).
    """
    w = np.asarray(view_dir, float)
    w /= np.linalg.norm(w)
    right = np.cross(up, w)
    right /= np.linalg.norm(right)
    upv = np.cross(w, right)
    p = vertices.astype(np.float64)
    xy = np.stack([p @ right, p @ upv], axis=1)
    depth = p @ w  # larger = closer to the camera
    lo, hi = xy.min(0), xy.max(0)
    width, height = size[0] * ss, size[1] * ss
    scale = (1 - 2 * margin) * min(width / (hi - lo)[0], height / (hi - lo)[1])
    centre = (lo + hi) / 2

    def to_pixels(q):
        q = np.atleast_2d(np.asarray(q, float))
        u = (q @ right - centre[0]) * scale + width / 2
        v = height / 2 - (q @ upv - centre[1]) * scale
        return np.stack([u, v], axis=1) / ss

    px = np.stack([(xy[:, 0] - centre[0]) * scale + width / 2, height / 2 - (xy[:, 1] - centre[1]) * scale], axis=1)
    colors = np.asarray(colors, float)
    if colors.ndim == 1:
        colors = colors[:, None]
    image = np.full((height, width, colors.shape[1]), background, float)
    zbuf = np.full((height, width), -np.inf)
    for tri in triangles:
        (x0, y0), (x1, y1), (x2, y2) = px[tri]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if area >= 0:  # back-facing in image space (y points down) or degenerate
            continue
        xmin, xmax = int(max(np.floor(min(x0, x1, x2)), 0)), int(min(np.ceil(max(x0, x1, x2)), width - 1))
        ymin, ymax = int(max(np.floor(min(y0, y1, y2)), 0)), int(min(np.ceil(max(y0, y1, y2)), height - 1))
        if xmin > xmax or ymin > ymax:
            continue
        gx, gy = np.meshgrid(np.arange(xmin, xmax + 1) + 0.5, np.arange(ymin, ymax + 1) + 0.5)
        l0 = ((x1 - gx) * (y2 - gy) - (x2 - gx) * (y1 - gy)) / area
        l1 = ((x2 - gx) * (y0 - gy) - (x0 - gx) * (y2 - gy)) / area
        l2 = 1.0 - l0 - l1
        inside = (l0 >= 0) & (l1 >= 0) & (l2 >= 0)
        if not inside.any():
            continue
        z = l0 * depth[tri[0]] + l1 * depth[tri[1]] + l2 * depth[tri[2]]
        sub = zbuf[ymin:ymax + 1, xmin:xmax + 1]
        closer = inside & (z > sub)
        if not closer.any():
            continue
        sub[closer] = z[closer]
        c = (l0[..., None] * colors[tri[0]] + l1[..., None] * colors[tri[1]] + l2[..., None] * colors[tri[2]])
        image[ymin:ymax + 1, xmin:xmax + 1][closer] = c[closer]
    image = image.reshape(size[1], ss, size[0], ss, -1).mean(axis=(1, 3))

    def visible(q, tolerance=0.02):
        """Whether world point q is in front in the z-buffer (within tolerance x the object size)."""
        u, v = (to_pixels(q)[0] * ss).astype(int)
        near = zbuf[max(v - 2, 0):v + 3, max(u - 2, 0):u + 3]
        return near.size > 0 and np.asarray(q, float) @ w >= near.max() - tolerance * np.ptp(depth)

    to_pixels.visible = visible
    return image, to_pixels


VIEW = (1.25, 1.5, 0.45)  # front right of the cow, a little from above (in +Z-up the head looks along +Y)
VIEW_BACK = (-1.2, -1.5, -0.05)  # back left, at belly height
VIEW_LOW = (1.3, 1.4, 0.08)  # front right, at belly height


# --- figure: visibility mask -------------------------------------------------------------------


def draw_disk(ax, title):
    ax.add_patch(Circle((0, 0), 1.0, fill=False, lw=1.2, color="#c0392b", zorder=5))
    ax.set_xlim(-1.04, 1.04)
    ax.set_ylim(-1.04, 1.04)
    ax.set_aspect("equal")
    ax.set_title(title)
    ax.set_xticks([-1, 0, 1])
    ax.set_yticks([-1, 0, 1])


def show_cells(ax, values, disk, cmap, vmin=0.0, vmax=1.0, grid=32):
    """values (grid, grid) over the disk square; row r is y, column c is x (as the engine)."""
    shown = np.where(disk, values.astype(float), np.nan)
    cmap = plt.get_cmap(cmap).copy() if isinstance(cmap, str) else cmap
    cmap.set_bad("#f4f4f4")
    ax.imshow(shown, origin="lower", extent=(-1, 1, -1, 1), cmap=cmap, vmin=vmin, vmax=vmax,
              interpolation="nearest")
    edges = np.linspace(-1, 1, grid + 1)
    ax.vlines(edges, -1, 1, color="white", lw=0.3 if grid == 32 else 0.8)
    ax.hlines(edges, -1, 1, color="white", lw=0.3 if grid == 32 else 0.8)


def projected_edge(p, q, steps=200):
    """Points of the spherical projection of segment p-q onto the disk (above the horizon only)."""
    t = np.linspace(0, 1, steps)[:, None]
    d = (1 - t) * p + t * q
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[d[:, 2] < 0] = np.nan
    return d[:, 0], d[:, 1]


def plane_trace(m, steps=400):
    """The great circle m.d = 0 over the upper hemisphere, projected to the disk."""
    m = m / np.linalg.norm(m)
    a = np.cross(m, [0.0, 0.0, 1.0]) if abs(m[2]) < 0.999 else np.array([1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(m, a)
    s = np.linspace(0, 2 * np.pi, steps)
    d = np.cos(s)[:, None] * a + np.sin(s)[:, None] * b
    d[d[:, 2] < 0] = np.nan
    return d[:, 0], d[:, 1]


def make_visibility_figure(vertices, triangles, transfer_world):
    positions, welded_tris, remap = weld(vertices, triangles)
    normals = area_normals(positions, welded_tris)
    ao = np.zeros(len(positions))
    ao[remap] = hemishadow.ambient_occlusion(transfer_world)
    candidates = np.nonzero(ao > 0.3)[0]
    r = int(candidates[np.argmin(ao[candidates])])
    n = normals[r]
    offset = 1e-3 * mean_edge_length(positions, welded_tris)
    origin = positions[r] + offset * n
    # the engine's transfer skips the receiver's own incident triangles; do the same here
    blockers = welded_tris[~np.any(welded_tris == r, axis=1)]
    mask = hemishadow.visibility_mask(origin.astype(np.float32), n.astype(np.float32), positions, blockers)
    disk = hemishadow.disk_cells()

    # 4x4 downsampling: blocked in-disk cells / in-disk cells per block
    blocks_in = disk.reshape(8, 4, 8, 4).sum(axis=(1, 3))
    blocks_blocked = (mask & disk).reshape(8, 4, 8, 4).sum(axis=(1, 3))
    grey = np.where(blocks_in > 0, blocks_blocked / np.maximum(blocks_in, 1), np.nan)
    # cosine-weighted solid angle is disk area: AO ~ 1 - sum(grey * block area) / pi
    ao_from_grey = 1.0 - np.nansum(grey * blocks_in) * CELL * CELL / np.pi

    # the blocker triangles in the receiver's tangent frame
    t, b = tangent_frame(n)
    local = (positions - origin) @ np.stack([t, b, n], axis=1)
    local_tris = local[blockers].astype(np.float32)
    counts = np.array([hemishadow.rasterize_local(tri[None]).sum() for tri in local_tris])
    above = (local_tris[:, :, 2] > 0).all(axis=1)
    pick = int(np.argmax(np.where(above, counts, -1)))
    tri = local_tris[pick].astype(np.float64)
    engine_tri = hemishadow.rasterize_local(local_tris[pick][None])

    # half-spaces of the three edge planes, in numpy (exact planes, no table quantisation)
    rows, cols = np.mgrid[0:32, 0:32]
    x, y = -1 + (cols + 0.5) * CELL, -1 + (rows + 0.5) * CELL
    dirs = np.stack([x, y, np.sqrt(np.clip(1 - x * x - y * y, 0, None))], axis=-1)
    a_, b_, c_ = tri
    planes = [np.cross(a_, b_), np.cross(b_, c_), np.cross(c_, a_)]
    if np.dot(planes[0], c_) < 0:
        planes = [-p for p in planes]
    halves = [(dirs @ p >= 0) & disk for p in planes]
    numpy_and = halves[0] & halves[1] & halves[2]

    fig = plt.figure(figsize=(11.5, 7.6))
    gs = fig.add_gridspec(2, 12, height_ratios=[1.25, 1.0], hspace=0.32, wspace=0.6)

    # (a) where the receiver is: the first of a few views that sees it
    ao_vertex = hemishadow.ambient_occlusion(transfer_world)
    cmap = plt.get_cmap("magma")
    for view in (VIEW_BACK, (0.4, -1.0, -0.35), (0.0, -1.0, -0.8), tuple(n + [0.0, 0.0, -0.3])):
        image, to_px = render(vertices, triangles, ao_vertex, view, size=(520, 440), background=np.nan)
        if to_px.visible(positions[r]):
            break
    ax = fig.add_subplot(gs[0, 0:4])
    ax.imshow(ao_rgba(image[..., 0], cmap))
    u, v = to_px(positions[r])[0]
    ax.plot(u, v, "o", ms=12, mfc="none", mec="#17becf", mew=2.2)
    ax.annotate("receiver", (u, v), (u + 70, v - 80), color="#17becf", fontsize=10, fontweight="bold",
                arrowprops=dict(arrowstyle="-", color="#17becf", lw=1.5))
    ax.set_axis_off()
    ax.set_title(f"(a) receiver: welded vertex {r} (colour = AO)\n"
                 f"AO {ao[r]:.3f}, the lowest above 0.3")

    # (b) the 32x32 mask
    ax = fig.add_subplot(gs[0, 4:8])
    show_cells(ax, mask, disk, ListedColormap(["#fdf6e3", "#2c3e50"]))
    for p, q in ((a_, b_), (b_, c_), (c_, a_)):
        ax.plot(*projected_edge(p, q), color="#e67e22", lw=1.4, zorder=6)
    draw_disk(ax, f"(b) 32x32 visibility mask\n{int((mask & disk).sum())} of {int(disk.sum())} disk cells blocked")
    ax.set_xlabel("x (tangent)")
    ax.set_ylabel("y (bitangent)")

    # (c) the 8x8 grey occlusion term
    ax = fig.add_subplot(gs[0, 8:12])
    show_cells(ax, np.nan_to_num(grey), blocks_in > 0, "Greys", grid=8)
    for (br, bc), g in np.ndenumerate(grey):
        if np.isfinite(g):
            ax.text(-1 + (bc + 0.5) * 0.25, -1 + (br + 0.5) * 0.25, f"{g:.2f}".lstrip("0") if g < 1 else "1",
                    ha="center", va="center", fontsize=6, color="white" if g > 0.55 else "black")
    draw_disk(ax, f"(c) 8x8 grey occlusion term (4x4 blocks)\n"
                  f"1 - sum(grey x area) / pi = {ao_from_grey:.3f}")
    ax.set_xlabel("x (tangent)")

    # (d)-(g) one blocker triangle: three half-spaces and their AND
    labels = ["edge a-b", "edge b-c", "edge c-a"]
    pairs = [(a_, b_), (b_, c_), (c_, a_)]
    for k in range(4):
        ax = fig.add_subplot(gs[1, 3 * k:3 * k + 3])
        if k < 3:
            show_cells(ax, halves[k], disk, ListedColormap(["#fdf6e3", "#7fb3d5"]))
            ax.plot(*plane_trace(planes[k]), color="#1f618d", lw=1.2, zorder=6)
            ax.plot(*projected_edge(*pairs[k]), color="#e67e22", lw=2.2, zorder=7)
            draw_disk(ax, f"({'def'[k]}) half-space of {labels[k]}\n{int(halves[k].sum())} cells")
        else:
            show_cells(ax, numpy_and, disk, ListedColormap(["#fdf6e3", "#2c3e50"]))
            differ = numpy_and != engine_tri
            if differ.any():
                rr, cc = np.nonzero(differ)
                ax.plot(-1 + (cc + 0.5) * CELL, -1 + (rr + 0.5) * CELL, "x", color="#c0392b", ms=4, mew=1)
            for p, q in pairs:
                ax.plot(*projected_edge(p, q), color="#e67e22", lw=1.4, zorder=6)
            draw_disk(ax, f"(g) AND of (d)-(f): {int(numpy_and.sum())} cells\n"
                          f"engine (rasterize_local): {int(engine_tri.sum())}, differ: {int(differ.sum())}")
        ax.tick_params(labelsize=7)

    fig.text(0.5, 0.015,
             "Cells: dark = blocked, light = open, pale grey = outside the unit disk; red circle = horizon. "
             "Orange = spherical projection of the blocker triangle used in (d)-(g) (the one covering the most cells);\n"
             "blue = the great circle of each edge plane. (b) and (g) come from the engine (visibility_mask without "
             "the receiver's own triangles, as transfer does; rasterize_local); (d)-(f) are computed in numpy with the "
             "exact\nplanes for illustration (the engine looks them up in the quantised 6x128x128 plane table; "
             "red x in (g) marks cells where the two differ). "
             f"(c): the engine's transfer gives AO {ao[r]:.3f} for this receiver.",
             ha="center", va="bottom", fontsize=7.5, color="#333333")
    fig.subplots_adjust(left=0.04, right=0.99, top=0.93, bottom=0.11)
    fig.savefig(IMAGES / "visibility_mask.png", metadata={"Software": None})
    plt.close(fig)
    print(f"visibility_mask.png: receiver {r}, AO {ao[r]:.4f}, AO from the grey term {ao_from_grey:.4f}, "
          f"blocker {pick}: numpy {int(numpy_and.sum())} cells, engine {int(engine_tri.sum())}")


# --- figures: ambient occlusion and shading ------------------------------------------------------


def colorbar_image(ax, cmap, label, vmin=0.0, vmax=1.0):
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(vmin, vmax))
    cb = plt.colorbar(sm, ax=ax, fraction=0.035, pad=0.01)
    cb.set_label(label)


def ao_rgba(values, cmap):
    """Colour-mapped AO image; NaN (background) white."""
    rgba = cmap(np.clip(np.nan_to_num(values, nan=0.0), 0, 1))
    rgba[np.isnan(values)] = (1, 1, 1, 1)
    return rgba


def make_ao_figure(vertices, triangles, transfer_world):
    ao = hemishadow.ambient_occlusion(transfer_world)
    cmap = plt.get_cmap("magma")
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6))
    for ax, view, title in ((axes[0], VIEW, "front right"), (axes[1], VIEW_BACK, "back left, from lower down")):
        image, _ = render(vertices, triangles, ao, view, background=np.nan)
        ax.imshow(ao_rgba(image[..., 0], cmap))
        ax.set_axis_off()
        ax.set_title(title)
    colorbar_image(axes, cmap, "ambient occlusion  T_0 / (pi Y_00)")
    fig.suptitle(f"spot.obj: per-vertex ambient occlusion from hemishadow.transfer "
                 f"({len(vertices)} vertices, {len(triangles)} triangles; min {ao.min():.2f}, "
                 f"median {np.median(ao):.2f})", fontsize=10)
    fig.text(0.45, 0.02, "Colours interpolated between vertices (Gouraud); 1 = nothing blocks the hemisphere.",
             ha="center", fontsize=8, color="#333333")
    fig.subplots_adjust(left=0.01, right=0.88, top=0.88, bottom=0.06, wspace=0.02)
    fig.savefig(IMAGES / "spot_ao.png", metadata={"Software": None})
    plt.close(fig)
    print(f"spot_ao.png: AO min {ao.min():.4f} median {np.median(ao):.4f}")


def make_shaded_figure(vertices, triangles, transfer_world):
    hdri = default_hdri()
    lighting = hemishadow.project_environment(hdri, bands=5)
    positions, welded_tris, remap = weld(vertices, triangles)
    normals = area_normals(positions, welded_tris)[remap].astype(np.float32)
    albedo = np.full((len(vertices), 3), ALBEDO, np.float32)
    shadowed = hemishadow.shade(transfer_world, lighting, albedo)
    open_ = hemishadow.shade(unoccluded_transfer(normals), lighting, albedo)
    # one exposure for both: the 99th percentile of the unshadowed radiance maps to 0.9
    exposure = 0.85 / np.percentile(open_.max(axis=1), 99)

    def display(radiance):
        image, _ = render(vertices, triangles, np.clip(radiance * exposure, 0, None), VIEW_LOW,
                          background=np.nan, size=(620, 500))
        out = linear_to_srgb8(np.nan_to_num(image, nan=0)) / 255.0
        out[np.isnan(image[..., 0])] = BACKGROUND
        return out

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.9))
    axes[0].imshow(display(open_))
    axes[0].set_title("unshadowed: transfer A_l Y_lm(n), cosine only")
    axes[1].imshow(display(shadowed))
    axes[1].set_title("self-shadowed: hemishadow.transfer")
    for ax in axes:
        ax.set_axis_off()
    fig.suptitle(f"spot.obj lit by Blender's \"{hdri.stem}\" HDRI (25 SH coefficients, albedo {ALBEDO})",
                 fontsize=10)
    fig.text(0.5, 0.02, f"Diffuse exitant radiance = albedo / pi x (transfer . lighting), "
                        f"exposure x{exposure:.2f} (same for both), sRGB; Gouraud-interpolated vertex colours.",
             ha="center", fontsize=8, color="#333333")
    fig.subplots_adjust(left=0.01, right=0.99, top=0.87, bottom=0.06, wspace=0.02)
    fig.savefig(IMAGES / "spot_shaded.png", metadata={"Software": None})
    plt.close(fig)
    print(f"spot_shaded.png: {hdri.name}, exposure {exposure:.3f}")


# --- figure: accuracy ------------------------------------------------------------------------------


def make_accuracy_figure(path=ACCURACY, out=None):
    if not path.exists():
        print(f"accuracy.png: skipped, {path.relative_to(ROOT)} does not exist "
              "(run .venv/bin/python -m pytest tests/test_transfer_accuracy.py first)")
        return
    results = json.loads(path.read_text())
    keys = sorted(k for k, v in results.items() if "median" in v and "occluded_mean" in v)
    if not keys:
        print(f"accuracy.png: skipped, no per-mesh rows in {path}")
        return
    median = np.array([results[k]["median"] for k in keys]) * 100
    occluded = np.array([results[k]["occluded_mean"] for k in keys], dtype=float) * 100
    fig, ax = plt.subplots(figsize=(max(6.0, 0.55 * len(keys) + 2.5), 4.6))
    x = np.arange(len(keys))
    ax.bar(x - 0.2, median, 0.4, label="median", color="#5d8aa8", zorder=3)
    ax.bar(x + 0.2, np.nan_to_num(occluded), 0.4, label="mean over occluded vertices (AO <= 0.9)", color="#c0392b",
           zorder=3)
    ax.axhspan(2.5, 8.0, color="#999999", alpha=0.2, lw=0, zorder=1, label="Kautz et al. 2004, Table 1: 2.5-8 %")
    ax.set_xticks(x)
    ax.set_xticklabels(keys, rotation=35, ha="right", fontsize=8)
    ax.set_ylabel("relative L2 error of the transfer vector (%)")
    ax.set_title("Transfer accuracy against a Monte-Carlo ray-cast reference\n(tests/test_transfer_accuracy.py)")
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(out or IMAGES / "accuracy.png", metadata={"Software": None})
    plt.close(fig)
    print(f"accuracy.png: {len(keys)} rows from {path.name}")


def main() -> int:
    IMAGES.mkdir(parents=True, exist_ok=True)
    vertices, triangles = load_spot()
    transfer_world = hemishadow.transfer(vertices, triangles, bands=5)
    make_visibility_figure(vertices, triangles, transfer_world)
    make_ao_figure(vertices, triangles, transfer_world)
    make_shaded_figure(vertices, triangles, transfer_world)
    make_accuracy_figure()
    return 0


if __name__ == "__main__":
    sys.exit(main())
