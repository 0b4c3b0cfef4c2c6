"""The pose-distance rule of the potentially visible sets (`TransferSolver.build_pvs`): how far
a frame's AO moves from the full hierarchy's when the sets are forced on it, against the
frame's distance from the nearest sampled pose.

Per animation (the shared characters, every frame of every action, and a cloth falling on a
sphere, frames 1-48), sets are sampled from every 4th frame and forced on every frame
(`tolerance` 1e9); each frame's distance is the largest vertex displacement from the
nearest sample as a fraction of the rest pose's half size (what `tolerance` compares, default
0.03). Prints, per animation, the worst |AO - full hierarchy| over vertices of the frames
within the default tolerance, within twice it and beyond, with the frame's distance, and the
blockers per receiver against the full hierarchy's.

Run: .venv/bin/python bench/pvs_tolerance.py   (about 3 minutes on 2 cores)
"""

import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "bench"), str(ROOT / "tests")]
import hemishadow  # noqa: E402
import scenes  # noqa: E402
from animated import CHARACTERS, character_frames  # noqa: E402
from hemishadow.solver import DEFAULT_PVS_TOLERANCE  # noqa: E402

BANDS = 3  # AO is T_0; the band count does not change which blockers are used
SAMPLE_EVERY = 4


def animations():
    for name in CHARACTERS:
        triangles, frames = character_frames(name)
        yield name, np.array([v for _, _, v in frames], np.float32), triangles
    poses, triangles = scenes.cloth(frames=tuple(range(1, 49)))[:2]
    yield "falling cloth", np.asarray(poses, np.float32), triangles


def pose_distances(poses, sampled):
    """Per frame, the largest vertex displacement from the nearest sampled pose / half size."""
    rest = poses[0]
    half = 0.5 * np.ptp(rest, axis=0).max()
    moved = np.array([[np.linalg.norm(p - poses[s], axis=1).max() for s in sampled] for p in poses])
    return moved.min(axis=1) / half


def measure(name, poses, triangles):
    sampled = list(range(0, len(poses), SAMPLE_EVERY))
    full = hemishadow.TransferSolver(poses[0], triangles, bands=BANDS, reuse=False)
    forced = hemishadow.TransferSolver(poses[0], triangles, bands=BANDS, reuse=False)
    forced.build_pvs(poses[sampled], tolerance=1e9)
    distance = pose_distances(poses, sampled)
    worst, fewer = [], []
    for v in poses:
        expected, got = full.solve(v), forced.solve(v)
        worst.append(np.abs(hemishadow.ambient_occlusion(got) - hemishadow.ambient_occlusion(expected)).max())
        fewer.append(forced.stats["blockers_per_vertex"] / max(full.stats["blockers_per_vertex"], 1e-9))
    worst = np.array(worst)
    tol = DEFAULT_PVS_TOLERANCE
    line = f"{name:18s} {len(poses):4d} frames, {len(sampled):3d} sampled: worst {worst[distance == 0].max():.4f} on them"
    for label, band in ((f"(0, {tol}]", (distance > 0) & (distance <= tol)),
                        (f"({tol}, {2 * tol}]", (distance > tol) & (distance <= 2 * tol)),
                        (f"> {2 * tol}", distance > 2 * tol)):
        k = np.argmax(np.where(band, worst, -1))
        line += f"; {label}: {band.sum():3d} frames" + (f", worst {worst[k]:.4f} at {distance[k]:.3f}" if band.any() else "")
    print(line + f"; blockers x{np.mean(fewer):.2f}", flush=True)


def main():
    print(f"max |AO with the sets forced - full hierarchy| over vertices (tolerance {DEFAULT_PVS_TOLERANCE})")
    for name, poses, triangles in animations():
        measure(name, poses, triangles)


if __name__ == "__main__":
    main()
