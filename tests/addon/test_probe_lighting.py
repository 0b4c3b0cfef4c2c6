"""Live lighting from a baked probe grid (issue 12, addon/probe_lighting.py): an object with
Probe Lighting is shaded by the probes' light at its place, every frame, instead of the
World and lamps, keeping its own transfer (its soft self-shadows)."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import hemishadow  # noqa: E402
import hemishadow.probes as hp  # noqa: E402
from layers import attribute  # noqa: E402
import probe_scenes  # noqa: E402


@pytest.fixture
def yard(addon):
    """A floor, a 2 m wall at x = 2 and a low sun from +x: the wall's shadow reaches about
    3.5 m west of it. A probe volume spans both the sunlit and the shaded part."""
    return probe_scenes.yard(addon)


def test_an_object_walking_into_the_shade_takes_the_grid_light(yard, addon):
    scene, volume = yard, yard.objects["Volume"]
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3, location=(-3.5, 0.0, 0.6))
    ball = bpy.context.active_object
    ball.hemishadow.enabled = True
    ball.hemishadow.probe_volume = volume
    for frame, x in ((1, -3.5), (10, 1.2)):  # in the sun, then in the wall's shadow
        ball.location.x = x
        ball.keyframe_insert("location", index=0, frame=frame)
    scene.frame_set(1)
    scene.hemishadow.live = True
    addon.engine_bridge.compute_now(scene, bpy.context.evaluated_depsgraph_get())
    lit = attribute(ball, addon.mesh_io.RADIANCE).copy()
    scene.frame_set(10)
    shaded = attribute(ball, addon.mesh_io.RADIANCE)
    assert shaded.mean() < 0.6 * lit.mean(), (shaded.mean(), lit.mean())
    # Exactly its transfer under the probes' SH9 at the centre of its bounds (leak rule on).
    entry = addon.engine_bridge._entries[ball.session_uid]
    centre = np.array([1.2, 0.0, 0.6])
    data = addon.probes.stored(volume)
    _, _, blockers = addon.probes.scene_geometry(scene)
    sh9 = hp.evaluate(data, centre[None], blockers=blockers)["sh9"][0]
    lighting = np.zeros((entry.transfer.shape[1], 3), np.float32)
    lighting[:9] = sh9
    expected = hemishadow.shade(entry.transfer, lighting, np.asarray(ball.hemishadow.albedo))
    np.testing.assert_allclose(shaded, expected, rtol=1e-3, atol=1e-5)
    # Its own soft shadows stay: the underside (facing the floor) is darker than the top.
    z = np.array([v.co.z for v in ball.data.vertices])
    assert shaded[z < -0.2].mean() < shaded[z > 0.2].mean()


def test_without_baked_probes_the_status_says_so(yard, addon):
    scene = yard
    bpy.ops.object.empty_add(location=(0.0, 0.0, 1.0))
    empty = bpy.context.active_object
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3, location=(0.0, 0.0, 0.6))
    ball = bpy.context.active_object
    ball.hemishadow.enabled = True
    ball.hemishadow.probe_volume = empty
    computed, errors, _ = addon.engine_bridge.compute_now(scene, bpy.context.evaluated_depsgraph_get())
    assert ball.name in errors and "holds no baked probes" in errors[ball.name]
    assert "holds no baked probes" in ball.hemishadow.status


def test_the_probes_panel_draws_for_a_volume_and_without_one(yard, addon):
    """The panel's draw with the baked volume active (and a lit object naming it), and with
    nothing suitable active: labels only, no exception."""
    from addon import probe_panel

    volume = yard.objects["Volume"]
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3)
    ball = bpy.context.active_object
    ball.hemishadow.probe_volume = volume

    class Layout:
        def __init__(self):
            self.calls = []

        def label(self, text="", icon="NONE"):
            self.calls.append(text)

        def operator(self, idname, icon="NONE"):
            self.calls.append(idname)

    for active, expected in ((volume, ["24 probes baked", "hemishadow.bake_probes", "hemishadow.probe_preview",
                                       f"Lights {ball.name}"]),
                             (ball, ["Select a Light Probe Volume or an Empty"])):
        bpy.context.view_layer.objects.active = active
        panel = type("P", (), {"layout": Layout()})()
        probe_panel.HEMISHADOW_PT_probes.draw(panel, bpy.context)
        text = " | ".join(panel.layout.calls)
        assert all(e in text for e in expected), text
