"""The lightmap bake reports progress often at every stage (issue 11: Esc cancels at once), so
that a cancel lands within 0.2 s: rasterizing texels, masks, environment, suns, lamps, bounce
passes, the final gather, padding, the atlas and the seams.

Gaps are measured in the process's CPU time, which a loaded machine does not stretch (on 2
idle cores a gap of c CPU seconds takes at most c seconds). The engine's one-off scene build
(`Scene.prepare`, uninterruptible) is done before timing.
"""

import importlib
import time
import traceback

import numpy as np
import pytest

hemishadow = pytest.importorskip("hemishadow")
from hemishadow.lightmap import Point, Sun, Surface, Target, bake, cells  # noqa: E402
from test_lightmap import cube, cylinder, grid_plane, scene_of, uniform_sky  # noqa: E402

bake_module = importlib.import_module("hemishadow.lightmap.bake")
LIMIT = 0.2
SKIP = {"progress", "step", "check", "chunks", "_checked", "<lambda>"}


@pytest.mark.parametrize("atlas", [False, True])
def test_every_stage_reports_within_a_fifth_of_a_second(atlas):
    v, t, uv = grid_plane(size=4.0, n=16)
    cv, ct, cuv = cylinder(segments=48, rings=6)              # UV seams: the stitch pass
    box = cube([-0.4, -0.4, 0.3], [0.4, 0.4, 0.6])
    scene, (pid, cid, bid) = scene_of((v, t), (cv, ct), box)
    if atlas:
        uv, cuv = uv * 0.5, cuv * 0.5 + 0.5                    # two slots of one map
    targets = [Target(Surface(pid, v, t), uv), Target(Surface(cid, cv, ct), cuv)]
    scene.prepare()
    cells.moments()                                           # a cached quadrature, computed once
    stamps, stages = [time.process_time()], ["start"]

    def progress(fraction):
        stamps.append(time.process_time())
        frames = [f.name for f in traceback.extract_stack(limit=8)[::-1]]
        stages.append(next(f for f in frames if f not in SKIP))
        return True

    bake(scene, targets, resolution=64, lighting=uniform_sky(0.5), suns=[Sun((0.3, -0.6, 0.7), 3.0, 0.02)],
         lamps=[Point((1.0, 1.0, 2.0), 200.0, 0.1)], surfaces=[Surface(bid, *box)], bounces=2, margin=2,
         progress=progress, **({"atlas": True} if atlas else {}))
    stamps.append(time.process_time())
    stages.append("end")
    gaps = np.diff(stamps)
    worst = int(np.argmax(gaps))
    print(f"{len(stamps) - 2} reports, worst gap {gaps[worst]:.3f} s CPU: {stages[worst]} -> {stages[worst + 1]}")
    for stage in ("rasterize", "_masks_and_valid", "environment_light", "_sun_rays", "_record", "_gather_some",
                  "fill", "stitch"):
        assert stage in stages, stage                          # every stage reports
    assert gaps.max() < LIMIT
