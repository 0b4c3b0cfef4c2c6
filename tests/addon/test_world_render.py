"""The World as the user sees it (issue 7, case 4): any node setup lights the object with what
it emits, through a small Cycles render of the World projected to SH (addon/world_render.py),
and the fast paths (Environment Texture, plain colour) agree with that render.

Before: every World without an Environment Texture feeding the Background lit the object with
the built-in "forest" HDRI (a plain colour, a Sky Texture, a gradient, mixes), and a Mix of
Backgrounds took the first one found.
"""

import math
import pathlib
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import hemishadow  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
from addon import world, world_render  # noqa: E402
from test_sh import equirect_directions  # noqa: E402
from test_world import FOREST, scene, settings  # noqa: E402,F401  (scene: the same fixture)


def new_world(scene):
    w = bpy.data.worlds.new("probe")
    scene.world = w
    return w, w.node_tree.nodes, w.node_tree.links


def gradient_world(scene, a, v):
    """Radiance a + v . d along direction d (grey): World 'Generated' coordinates are d."""
    w, nodes, links = new_world(scene)
    coords = nodes.new("ShaderNodeTexCoord")
    dot = nodes.new("ShaderNodeVectorMath")
    dot.operation = "DOT_PRODUCT"
    dot.inputs[1].default_value = v
    add = nodes.new("ShaderNodeMath")
    add.operation = "ADD"
    add.inputs[1].default_value = a
    links.new(coords.outputs["Generated"], dot.inputs[0])
    links.new(dot.outputs["Value"], add.inputs[0])
    links.new(add.outputs[0], nodes["Background"].inputs["Color"])
    return w


def expected_gradient(a, v, bands=5):
    d = equirect_directions(256, 512)
    image = np.repeat((a + d @ np.asarray(v, float))[..., None], 3, axis=2)
    return hemishadow.project_environment(image, bands)


def relative_error(got, expected):
    return float(np.linalg.norm(got - expected) / np.linalg.norm(expected))


def test_plain_background_colour_is_a_uniform_sky(scene):
    w, nodes, _ = new_world(scene)
    nodes["Background"].inputs["Color"].default_value = (0.2, 0.4, 0.6, 1)
    nodes["Background"].inputs["Strength"].default_value = 2.0
    assert world.lighting_source(scene, settings()).kind == "WORLD_COLOR"
    lighting = world.scene_lighting(scene, 5, settings())
    np.testing.assert_allclose(lighting[0], math.sqrt(4 * math.pi) * 2.0 * np.array([0.2, 0.4, 0.6]), rtol=1e-5)
    assert not lighting[1:].any()
    # and the render of that World agrees with the exact value
    rendered = world_render.render_projection(w, scene.frame_current)
    np.testing.assert_allclose(rendered, lighting, atol=2e-3 * lighting[0].max())


def test_gradient_world_is_rendered_with_the_right_directions_and_scale(scene):
    a, v = 1.0, (0.3, -0.2, 0.6)  # brighter towards +x, -y, +z: a wrong mapping shows
    gradient_world(scene, a, v)
    source = world.lighting_source(scene, settings())
    assert source.kind == "WORLD_RENDER"
    lighting = world.scene_lighting(scene, 5, settings())
    expected = expected_gradient(a, v)
    assert relative_error(lighting, expected) < 0.01
    np.testing.assert_allclose(lighting[:4], expected[:4], atol=0.01 * expected[0, 0])


def test_mix_of_backgrounds_is_what_the_world_emits(scene):
    w, nodes, links = new_world(scene)
    first = nodes["Background"]
    first.inputs["Color"].default_value = (1.0, 0.0, 0.0, 1)
    second = nodes.new("ShaderNodeBackground")
    second.inputs["Color"].default_value = (0.0, 0.0, 1.0, 1)
    second.inputs["Strength"].default_value = 2.0
    mix = nodes.new("ShaderNodeMixShader")
    mix.inputs["Fac"].default_value = 0.25
    links.new(first.outputs[0], mix.inputs[1])
    links.new(second.outputs[0], mix.inputs[2])
    links.new(mix.outputs[0], nodes["World Output"].inputs["Surface"])
    lighting = world.scene_lighting(scene, 3, settings())
    uniform = math.sqrt(4 * math.pi) * np.array([0.75, 0.0, 0.5])
    np.testing.assert_allclose(lighting[0], uniform, atol=0.01 * uniform.max())
    assert np.abs(lighting[1:]).max() < 0.01 * uniform.max()


def test_light_path_camera_trick_lights_with_what_diffuse_rays_see(scene):
    """Camera sees red, everything it lights sees green: the object is lit green."""
    w, nodes, links = new_world(scene)
    seen = nodes["Background"]
    seen.inputs["Color"].default_value = (1.0, 0.0, 0.0, 1)
    lights = nodes.new("ShaderNodeBackground")
    lights.inputs["Color"].default_value = (0.0, 1.0, 0.0, 1)
    path = nodes.new("ShaderNodeLightPath")
    mix = nodes.new("ShaderNodeMixShader")
    links.new(path.outputs["Is Camera Ray"], mix.inputs["Fac"])
    links.new(lights.outputs[0], mix.inputs[1])
    links.new(seen.outputs[0], mix.inputs[2])
    links.new(mix.outputs[0], nodes["World Output"].inputs["Surface"])
    lighting = world.scene_lighting(scene, 3, settings())
    np.testing.assert_allclose(lighting[0], [0, math.sqrt(4 * math.pi), 0], atol=0.02)
    assert len(w.node_tree.nodes) == 5 and len(w.node_tree.links) == 4  # the user's World untouched


def test_environment_fast_path_agrees_with_the_render(scene):
    w, nodes, links = new_world(scene)
    env = nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(FOREST))
    links.new(env.outputs["Color"], nodes["Background"].inputs["Color"])
    assert world.lighting_source(scene, settings()).kind == "WORLD"
    fast = world.scene_lighting(scene, 5, settings())
    rendered = world_render.render_projection(w, scene.frame_current)
    assert relative_error(rendered, fast) < 0.005
    np.testing.assert_allclose(rendered, fast, atol=0.005 * np.abs(fast).max())


def test_rendering_leaves_nothing_behind(scene):
    gradient_world(scene, 1.0, (0, 0, 0.5))
    before = {name: len(getattr(bpy.data, name)) for name in ("scenes", "objects", "cameras", "worlds", "images",
                                                             "node_groups", "materials")}
    fingerprint = world_render.fingerprint(scene.world)
    world.scene_lighting(scene, 5, settings())
    after = {name: len(getattr(bpy.data, name)) for name in before}
    assert after == before
    assert world_render.fingerprint(scene.world) == fingerprint
    assert bpy.context.scene == scene and scene.camera is None


def test_in_a_handler_nothing_renders_it_is_scheduled_and_said(scene, monkeypatch):
    w = gradient_world(scene, 1.0, (0, 0, 0.5))
    scheduled = []
    monkeypatch.setattr(world_render, "schedule", lambda s, cb=None: scheduled.append(s.name))
    with world_render.no_render():
        lighting = world.scene_lighting(scene, 5, settings())
    assert scheduled == [scene.name] and not lighting.any()
    assert any("not rendered" in m for m in world.notes(scene))
    assert world_render.precompute(scene) == 1
    lighting = world.scene_lighting(scene, 5, settings())
    assert relative_error(lighting, expected_gradient(1.0, (0, 0, 0.5))) < 0.01
    assert not world.notes(scene)
    # an edit of a node asks for a new render; the old one stands in meanwhile
    w.node_tree.nodes["Math"].inputs[1].default_value = 2.0
    assert world_render.missing_frames(scene) == [scene.frame_current]
    with world_render.no_render():
        stale = world.scene_lighting(scene, 5, settings())
    np.testing.assert_allclose(stale, lighting)


def test_animated_world_is_precomputed_per_frame(scene):
    w = gradient_world(scene, 1.0, (0, 0, 0))  # radiance = the Math node's value, rendered
    value = w.node_tree.nodes["Math"].inputs[1]
    value.default_value = 1.0
    value.keyframe_insert("default_value", frame=1)
    value.default_value = 3.0
    value.keyframe_insert("default_value", frame=3)
    scene.frame_start, scene.frame_end = 1, 3
    assert world_render.is_animated(w)
    assert world_render.missing_frames(scene) == [1, 2, 3]
    assert world_render.precompute(scene) == 3
    assert world_render.missing_frames(scene) == []
    for frame, radiance in [(1, 1.0), (2, 2.0), (3, 3.0)]:
        scene.frame_set(frame)
        with world_render.no_render():  # as in the frame handler: cached, nothing rendered
            lighting = world.scene_lighting(scene, 3, settings())
        assert lighting[0, 0] == pytest.approx(radiance * math.sqrt(4 * math.pi), rel=0.01)
        assert not world.notes(scene)


def test_timer_renders_the_current_frame_first_then_the_range(scene, monkeypatch):
    """Timers do not run in background mode: drive the callback by hand."""
    w, nodes, _ = new_world(scene)
    sky = nodes.new("ShaderNodeTexSky")
    w.node_tree.links.new(sky.outputs[0], nodes["Background"].inputs["Color"])
    strength = nodes["Background"].inputs["Strength"]
    strength.keyframe_insert("default_value", frame=1)
    scene.frame_start, scene.frame_end = 1, 3
    scene.frame_set(2)
    ready = []
    world_render.schedule(scene, lambda s, remaining: ready.append((s.frame_current, remaining)))
    rendered = []
    original = world_render.render_projection
    monkeypatch.setattr(world_render, "render_projection", lambda w, f: rendered.append(f) or original(w, f))
    while world_render._tick() is not None:
        pass
    assert rendered == [2, 1, 3] and [r for _, r in ready] == [2, 1, 0]
    assert world_render.missing_frames(scene) == []
    if bpy.app.timers.is_registered(world_render._tick):
        bpy.app.timers.unregister(world_render._tick)


def test_missing_frames_are_reported_before_a_render(addon, scene, capfd):
    from addon import lighting

    w = gradient_world(scene, 1.0, (0, 0, 0.5))
    w.node_tree.nodes["Math"].inputs[1].keyframe_insert("default_value", frame=1)
    scene.frame_start, scene.frame_end = 1, 4
    assert lighting.check_before_render(scene) == [1, 2, 3, 4]
    assert "no lighting projection for 4 frames (1..4)" in capfd.readouterr().out
    world_render.precompute(scene, [1, 2])
    assert lighting.check_before_render(scene) == [3, 4]
    bpy.ops.hemishadow.precompute_world()
    assert lighting.check_before_render(scene) == []


def test_no_world_is_reported_by_the_compute_operator(addon, scene, capfd):
    import bmesh

    scene.world = None
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=1.0)
    mesh = bpy.data.meshes.new("cube")
    bm.to_mesh(mesh)
    bm.free()
    cube = bpy.data.objects.new("cube", mesh)
    scene.collection.objects.link(cube)
    cube.hemishadow.enabled = True
    assert bpy.ops.hemishadow.compute(target="ENABLED") == {"FINISHED"}
    out = capfd.readouterr().out
    assert "the scene has no World: lit by the built-in HDRI" in out


def test_fingerprint_sees_colour_ramp_and_sky_edits(scene):
    w, nodes, links = new_world(scene)
    ramp = nodes.new("ShaderNodeValToRGB")
    sky = nodes.new("ShaderNodeTexSky")
    links.new(sky.outputs[0], ramp.inputs[0])
    links.new(ramp.outputs[0], nodes["Background"].inputs["Color"])
    digests = {world_render.fingerprint(w)}
    ramp.color_ramp.elements[1].position = 0.7
    digests.add(world_render.fingerprint(w))
    sky.sun_elevation = 0.3
    digests.add(world_render.fingerprint(w))
    nodes["Background"].location = (500, 0)  # moving a node changes nothing emitted
    digests.add(world_render.fingerprint(w))
    assert len(digests) == 3


def test_a_previous_render_result_keeps_its_slots(scene, tmp_path):
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.render.resolution_x = scene.render.resolution_y = 8
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(camera)
    scene.camera = camera
    bpy.ops.render.render()
    result = bpy.data.images["Render Result"]
    result.render_slots.active_index = 2
    names = [slot.name for slot in result.render_slots]
    w = gradient_world(scene, 1.0, (0, 0, 0.5))
    world.scene_lighting(scene, 5, settings())
    w.node_tree.nodes["Math"].inputs[1].default_value = 2.0
    world.scene_lighting(scene, 5, settings())  # a second render reuses our slot
    assert [slot.name for slot in result.render_slots] == names + [world_render.SLOT_NAME]
    assert result.render_slots.active_index == 2  # the slot shown is the user's
