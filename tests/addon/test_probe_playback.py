"""Probe Lighting in animation-cache playback and after a new probe bake (issue 12): a cached
object lit by probes shows in playback what the live path shows, and a new bake of the
probes re-shades the objects they light at once, live and cached, without a frame change."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import hemishadow  # noqa: E402
from layers import attribute  # noqa: E402
import probe_scenes  # noqa: E402


@pytest.fixture
def yard(addon):
    """A floor, a wall at x = 2 and a low sun from +x (its shadow reaches 3.5 m west of the
    wall), a probe volume over both, and a ball with Probe Lighting walking from the sun
    (frame 1, x = -3.5) into the shade (frame 3, x = 1.2)."""
    scene = probe_scenes.yard(addon)
    volume = scene.objects["Volume"]
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, radius=0.3, location=(-3.5, 0.0, 0.6))
    ball = bpy.context.active_object
    ball.name = "Ball"
    ball.hemishadow.enabled = True
    ball.hemishadow.probe_volume = volume
    for frame, x in ((1, -3.5), (3, 1.2)):
        ball.location.x = x
        ball.keyframe_insert("location", index=0, frame=frame)
    scene.frame_start, scene.frame_end = 1, 3
    scene.frame_set(1)
    return scene


def probe_shaded(addon, scene, ball, transfer):
    """What Probe Lighting gives `transfer` (V, K) with the ball where it is now."""
    vertices, _, _ = addon.mesh_io.read_evaluated(ball, bpy.context.evaluated_depsgraph_get())
    bands = int(round(np.sqrt(transfer.shape[1])))
    lighting = addon.probe_lighting.lighting(ball, scene, vertices, bands)
    return hemishadow.shade(np.asarray(transfer, np.float32), lighting, np.asarray(ball.hemishadow.albedo))


def test_cached_playback_shows_the_probe_light_as_live(yard, addon):
    scene, ball = yard, yard.objects["Ball"]
    addon.operators.bake.bake_range(scene, [ball], 1, 3, location="PACKED")
    scene.hemishadow.live = True
    played = {}
    for frame in (1, 3, 2):
        addon.engine_bridge.last_timings.clear()
        scene.frame_set(frame)
        assert ball.name not in addon.engine_bridge.last_timings  # from the cache, not computed
        played[frame] = attribute(ball, addon.mesh_io.RADIANCE).copy()
    addon.cache.clear(ball)
    worst = 0.0
    for frame in (1, 2, 3):
        scene.frame_set(frame)
        live = attribute(ball, addon.mesh_io.RADIANCE)
        worst = max(worst, np.abs(played[frame] - live).max() / live.max())
    assert worst < 2e-3, worst  # the cache keeps transfer as float16
    assert played[3].mean() < 0.6 * played[1].mean()  # walked into the shade


def test_a_probe_cache_without_transfer_is_not_played(yard, addon):
    scene, ball = yard, yard.objects["Ball"]
    addon.operators.bake.bake_range(scene, [ball], 1, 3, location="PACKED", store_transfer=False)
    assert "Probe Lighting" in addon.cache.why_invalid(ball, scene, 2)


def brighter_sun_rebaked(addon, scene):
    scene.objects["Sun"].data.energy = 9.0
    addon.probes.bake_probes(scene, scene.objects["Volume"], bounces=0)


def test_a_new_probe_bake_reshades_live_objects_at_once(yard, addon):
    scene, ball = yard, yard.objects["Ball"]
    scene.hemishadow.live = True
    scene.frame_set(1)  # in the sun
    before = attribute(ball, addon.mesh_io.RADIANCE).copy()
    brighter_sun_rebaked(addon, scene)
    after = attribute(ball, addon.mesh_io.RADIANCE)
    entry = addon.engine_bridge._entries[ball.session_uid]
    expected = probe_shaded(addon, scene, ball, entry.transfer)
    np.testing.assert_allclose(after, expected, rtol=1e-4, atol=1e-6)
    assert after.max() > 1.5 * before.max()


def test_a_new_probe_bake_reshades_cached_objects_at_once(yard, addon):
    scene, ball = yard, yard.objects["Ball"]
    addon.operators.bake.bake_range(scene, [ball], 1, 3, location="PACKED")
    scene.hemishadow.live = True
    scene.frame_set(1)
    before = attribute(ball, addon.mesh_io.RADIANCE).copy()
    brighter_sun_rebaked(addon, scene)
    after = attribute(ball, addon.mesh_io.RADIANCE)
    expected = probe_shaded(addon, scene, ball, addon.cache.load(ball).transfer[0])
    np.testing.assert_allclose(after, expected, rtol=1e-4, atol=1e-6)
    assert after.max() > 1.5 * before.max()


def test_the_probe_preview_reshades_with_the_stored_probes(yard, addon):
    """Stored probes changed behind the add-on's back (as an undo brings older ones back):
    showing the preview re-shades the objects with what it shows."""
    scene, ball, volume = yard, yard.objects["Ball"], yard.objects["Volume"]
    scene.hemishadow.live = True
    scene.frame_set(1)
    before = attribute(ball, addon.mesh_io.RADIANCE).copy()
    data = addon.probes.stored(volume)
    data["cube"], data["sh9"] = 2 * data["cube"], 2 * data["sh9"]
    addon.probes.store_on(volume, data)
    bpy.context.view_layer.objects.active = volume
    assert bpy.ops.hemishadow.probe_preview() == {"FINISHED"}
    np.testing.assert_allclose(attribute(ball, addon.mesh_io.RADIANCE), 2 * before, rtol=1e-4, atol=1e-6)
