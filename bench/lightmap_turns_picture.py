"""The room's sky through one mask lattice and through four turned ones, against Cycles.

Draws docs/images/lightmap_turned_lattices.png: the room of lightmap_cycles.py lit by its sky
alone (no sun, no lamp), 64 x 64, at one exposure: Cycles' bake (4096 samples), ours through
one lattice (the masks untilted and unfiltered, as before lightmap/tilts.py), ours as baked
now. Prints each one's mean relative error against Cycles (texels away from footprints and
brighter than 1 % of the open sky; Cycles' own noise in this dim, sky-lit room is part of it).

    PYTHONPATH=native/python .venv/bin/python bench/lightmap_turns_picture.py
"""

import importlib
import pathlib
import sys
import tempfile

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

import lightmap_cycles as lc  # noqa: E402
from addon import lightmaps  # noqa: E402
from hemishadow import lightmap as lm  # noqa: E402
from hemishadow.lightmap import tilts  # noqa: E402
from hemishadow.lightmap.encode import write_png  # noqa: E402

bake_module = importlib.import_module("hemishadow.lightmap.bake")
OUT = pathlib.Path(__file__).resolve().parents[1] / "docs" / "images" / "lightmap_turned_lattices.png"
R = 64


def ours(scene, floor, one_lattice):
    """Our flat map and coverage; one_lattice: masks untilted and unfiltered."""
    saved = tilts.TILT, bake_module._smoothed_environment
    if one_lattice:
        tilts.TILT, bake_module._smoothed_environment = 0.0, lambda lit, smooth: lit
    try:
        with tempfile.TemporaryDirectory() as folder:
            out = lightmaps.bake_lightmaps(scene, [floor], resolution=R, basis="flat", bounces=0, samples=4,
                                           margin=2, out_dir=folder, images=False)
            maps = lm.read_exr(out["Floor"])
    finally:
        tilts.TILT, bake_module._smoothed_environment = saved
    return maps["flat"], maps["coverage"] > 0


def main():
    scene, floor, material = lc.build(False, 0, None, "room", "none", 1.0)
    reference, _ = lc.cycles_bake(scene, floor, material, R, 4096, 0, 2)
    white = np.percentile(reference.mean(-1), 99)
    srgb = lambda x: np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(np.maximum(x, 0.0031308), 1 / 2.4) - 0.055)
    panels = [srgb(np.clip(reference.mean(-1) / white, 0, 1))]
    for label, one in (("one lattice", True), ("four turned lattices", False)):
        flat, covered = ours(scene, floor, one)
        relative, _, clear = lc.errors(flat, reference, covered, lc.footprints(floor, R))
        print(f"{label}: mean {100 * relative[clear].mean():.2f} % over {clear.sum()} texels")
        panels.append(srgb(np.clip(flat.mean(-1) / white, 0, 1)))
    gap = np.ones((R, 2))
    grey = np.concatenate([p for panel in panels for p in (panel, gap)][:-1], axis=1).repeat(4, 0).repeat(4, 1)
    rgba = np.concatenate([np.repeat(grey[..., None], 3, axis=2), np.ones(grey.shape + (1,))], axis=2)
    write_png(OUT, (rgba * 255 + 0.5).astype(np.uint8))
    print("wrote", OUT)


if __name__ == "__main__":
    main()
