"""Draws docs/images/scene_hierarchy.png: how one receiver walks the scene hierarchy (schematic,
side view). Run: python docs/scene_hierarchy_figure.py"""

import math
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

OUT = pathlib.Path(__file__).resolve().parent / "images" / "scene_hierarchy.png"
LOD = 0.1


def blob(ax, cx, cy, r, color, fine, label=None):
    """A bumpy object: fine = many small triangles (full resolution), else a coarse proxy."""
    k = 40 if fine else 7
    t = np.linspace(0, 2 * math.pi, k + 1)
    rr = r * (0.82 + 0.12 * np.sin(5 * t + cx))
    ax.fill(cx + rr * np.cos(t), cy + rr * np.sin(t), color=color, alpha=0.55, lw=1.0, ec=color, label=label)
    ax.add_patch(plt.Circle((cx, cy), r, fill=False, ls=":", color="0.4", lw=0.8))


def main():
    fig, ax = plt.subplots(figsize=(9, 4.2))
    receiver = np.array([0.0, 0.0])
    ax.axhline(0, color="0.2", lw=1)
    ax.fill_between([-3, 16], -1.6, 0, color="0.93")
    ax.text(15.8, -0.25, "receiver's horizon (tangent plane)", ha="right", va="top", fontsize=8)
    objects = [(1.3, 0.9, 0.7), (3.2, 1.6, 0.9), (6.0, 1.2, 0.8), (9.5, 2.4, 0.9), (13.5, 1.5, 0.9), (-1.8, 1.4, 0.7),
               (4.5, -0.9, 0.6), (11.0, -1.0, 0.5)]
    seen = set()
    for cx, cy, r in objects:
        d = math.hypot(cx, cy)
        if cy + r <= 0:
            kind, color = "culled: box below the horizon", "0.6"
        elif r < LOD * d:
            kind, color = "proxy: radius < lod x distance", "tab:blue"
        else:
            kind, color = "full resolution: close or large", "tab:red"
        blob(ax, cx, cy, r, color, kind.startswith("full"), None if kind in seen else kind)
        seen.add(kind)
        if cy + r > 0:
            ang = math.asin(min(1.0, r / d))
            base = math.atan2(cy, cx)
            for a in (base - ang, base + ang):
                ax.plot([0, d * math.cos(a)], [0, d * math.sin(a)], color=color, lw=0.5, alpha=0.5)
    # a group of far instances, culled or drawn as one node of the top tree
    ax.add_patch(plt.Rectangle((8.3, 1.2), 6.6, 2.4, fill=False, ec="tab:green", lw=1.2, ls="--"))
    ax.text(8.4, 3.7, "top tree node (box over instances): culled whole below the horizon", color="tab:green", fontsize=8)
    ax.annotate("", xy=(0, 1.2), xytext=(0, 0), arrowprops=dict(arrowstyle="->", lw=1.5))
    ax.plot(*receiver, "ko")
    ax.text(0.15, 1.0, "n", fontsize=9)
    ax.text(-0.2, -0.35, "receiver (p + offset n)", fontsize=8, ha="left", va="top")
    ax.set_xlim(-3, 16)
    ax.set_ylim(-1.6, 4.2)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.legend(loc="upper left", fontsize=8, frameon=False)
    ax.set_title("One receiver's walk: cull below the horizon, proxies far away, every triangle near by", fontsize=10)
    fig.tight_layout()
    OUT.parent.mkdir(exist_ok=True)
    fig.savefig(OUT, dpi=110)


if __name__ == "__main__":
    main()
