"""docs/images/panorama_mapping.png: the demo's panorama under the sky (make demo-panorama)
with the directions its columns and rows look along (docs/panoramas.md, "The mapping").

    .venv/bin/python docs/panorama_figure.py [out/demo_panorama/relit_sky.png]
"""

import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]


def main(source=ROOT / "out" / "demo_panorama" / "relit_sky.png"):
    image = plt.imread(str(source))
    h, w = image.shape[:2]
    fig, ax = plt.subplots(figsize=(8, 4.6), dpi=100)
    ax.imshow(image, extent=(0, 1, 0, 1), aspect=0.5)
    ticks = [0.0, 0.25, 0.5, 0.75, 1.0]
    ax.set_xticks(ticks, ["-X\nu = 0", "+Y\nu = 0.25", "+X\nu = 0.5", "-Y\nu = 0.75", "-X\nu = 1"])
    ax.set_yticks([0.0, 0.5, 1.0], ["-Z  v = 0", "horizon  v = 0.5", "+Z  v = 1"])
    for x in ticks[1:-1]:
        ax.axvline(x, color="white", lw=0.6, ls="--")
    ax.axhline(0.5, color="white", lw=0.6, ls="--")
    ax.set_title(f"{w} x {h}: phi = (0.5 - u) 2 pi, theta = (v - 0.5) pi (centre column +X, top row +Z)", fontsize=9)
    fig.tight_layout()
    out = ROOT / "docs" / "images" / "panorama_mapping.png"
    fig.savefig(out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main(*sys.argv[1:])
