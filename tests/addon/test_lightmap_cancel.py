"""Esc cancels a lightmap bake at once, at any stage (issue 11): the job's next step says
CANCELLED without waiting, the worker stops within 0.2 s of CPU time (see
tests/test_lightmap_progress.py), and nothing is written: no file, no image, no UV map."""

import importlib
import pathlib
import sys
import time

import pytest

bpy = pytest.importorskip("bpy")
import hemishadow.lightmap as lm  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
import addon  # noqa: E402
from addon import lightmap_job, lightmaps, world  # noqa: E402
from lightmap_scenes import white_world  # noqa: E402

engine = importlib.import_module("hemishadow.lightmap.bake")
LIMIT = 0.2

# stage: (module, function); the cancel comes as the function is entered ("after": as it returns)
STAGES = {
    "setup (texels)": ("texels", "rasterize"),
    "masks": ("bake", "_masks_and_valid"),
    "environment": ("light", "environment"),
    "sun": ("bake", "_sun_rays"),
    "lamp": ("lamps", "lamp_light"),
    "bounce passes": ("bounce", "_record"),
    "final gather": ("bounce", "vertex_radiance", "after"),
    "padding": ("dilate", "fill"),
    "atlas": ("atlas", "compose"),
    "seams": ("seams", "stitch"),
}


@pytest.fixture
def scene():
    scene = white_world(world, color=None)
    addon.register()  # last: a failed set-up must not leave it registered
    yield scene
    addon.unregister()


def snapshot():
    return (sorted(i.name for i in bpy.data.images),
            sorted((m.name, tuple(u.name for u in m.uv_layers)) for m in bpy.data.meshes))


def objects(scene):
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    floor = bpy.context.active_object
    floor.data.uv_layers.new(name="lightmap")
    bpy.ops.mesh.primitive_cylinder_add(radius=0.4, depth=1.0, location=(0, 0, 0.5))
    post = bpy.context.active_object
    lightmaps.make_lightmap_uv(post)                      # one island per face: UV seams to stitch
    for kind, location in (("SUN", (0, 0, 5)), ("POINT", (1, 1, 2))):
        bpy.ops.object.light_add(type=kind, location=location)
    return [floor, post]


@pytest.mark.parametrize("stage", list(STAGES))
def test_cancel_at_every_stage_stops_at_once_and_writes_nothing(scene, tmp_path, monkeypatch, stage):
    floor, post = objects(scene)
    # one object (the post, the floor around it): its own UV map; the atlas stage bakes both
    baked, atlas = ([floor, post], {"layout": "ATLAS"}) if stage == "atlas" else ([post], {})
    module, name, *when = STAGES[stage]
    module = importlib.import_module(f"hemishadow.lightmap.{module}")
    original = getattr(module, name)
    fired = {}

    def wrapped(*args, **kwargs):
        if not fired and not when:
            fired["cpu"] = time.process_time()
            job.cancel()
        out = original(*args, **kwargs)
        if not fired and when:
            fired["cpu"] = time.process_time()
            job.cancel()
        return out

    monkeypatch.setattr(module, name, wrapped)
    job = lightmap_job.LightmapBake(scene, baked, out_dir=str(tmp_path), resolution=48, bounces=2, **atlas)
    before = snapshot()  # after prepare: an atlas's UV map is made there, before the bake starts
    job.start()
    while job.step(0.005) == lightmap_job.RUNNING:
        pass
    job._thread.join()
    stopped = time.process_time()
    assert fired, f"the bake never reached {stage}"
    assert job.state == lightmap_job.CANCELLED
    assert stopped - fired["cpu"] < LIMIT, f"{stage}: the worker ran {stopped - fired['cpu']:.2f} s CPU after Esc"
    assert list(tmp_path.iterdir()) == [] and snapshot() == before


def test_step_says_cancelled_at_once_while_the_worker_still_runs(scene, tmp_path, monkeypatch):
    job = lightmap_job.LightmapBake(scene, objects(scene)[1:], out_dir=str(tmp_path), resolution=32, bounces=0)
    release = __import__("threading").Event()
    original = engine._masks_and_valid

    def slow(*args, **kwargs):  # an engine call that cannot be interrupted (Scene.prepare, say)
        release.wait(5)
        return original(*args, **kwargs)

    monkeypatch.setattr(engine, "_masks_and_valid", slow)
    job.start()
    assert job.step(0.05) == lightmap_job.RUNNING
    job.cancel()
    assert job.step() == lightmap_job.CANCELLED           # Esc ends the operator now
    assert job._thread.is_alive()
    release.set()
    job._thread.join()
    assert job.step() == lightmap_job.CANCELLED and list(tmp_path.iterdir()) == []
