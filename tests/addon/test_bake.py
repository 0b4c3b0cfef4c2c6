"""Bake animation: a frame range into a per-object cache, and playback from it.

The scene is the shared RiggedFigure (370 vertices, a skinned walk) over a few frames, baked
with `bake_range` (what the modal operator drives): the cache is written beside the .blend or
packed into it, is valid for exactly what it was made from, playback copies it into the
attributes bit for bit, cancellation stops early without saving, and save/reload keeps it.
"""

import os
import pathlib
import threading

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

ROOT = pathlib.Path(__file__).resolve().parents[2]
FIGURE = ROOT.parent / "shared" / "data" / "rigged_figure.glb"


@pytest.fixture
def figure(addon, tmp_path):
    """A saved .blend with the walking figure, hemishadow enabled; returns (scene, object)."""
    if not FIGURE.is_file():
        pytest.skip(f"{FIGURE} is missing")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=str(FIGURE))
    obj = bpy.context.scene.objects["Proxy"]   # the skinned body (the file also has a static Icosphere)
    obj.hemishadow.enabled = True
    scene = bpy.context.scene
    scene.hemishadow.lighting_source = "BUILTIN"
    scene.frame_set(1)
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "figure.blend"))
    return scene, obj


def attributes(obj):
    mesh = obj.data
    rgba = np.empty(len(mesh.vertices) * 4, np.float32)
    mesh.color_attributes["hemishadow_radiance"].data.foreach_get("color", rgba)
    ao = np.empty(len(mesh.vertices), np.float32)
    mesh.attributes["hemishadow_ao"].data.foreach_get("value", ao)
    return rgba.reshape(-1, 4)[:, :3], ao


def bake(addon, scene, obj, start=1, end=5, **options):
    return addon.operators.bake.bake_range(scene, [obj], start, end, **options)


def test_bake_writes_a_valid_cache(addon, figure, tmp_path):
    scene, obj = figure
    progress = []
    result = bake(addon, scene, obj, 1, 5, progress=lambda done, total: progress.append((done, total)))
    assert progress == [(i, 5) for i in range(1, 6)]
    assert result.frames_done == 5 and not result.cancelled
    assert result.saved == {obj.name: f"//hemishadow_cache/{obj.name}.npz"}
    assert (tmp_path / "hemishadow_cache" / f"{obj.name}.npz").is_file()
    assert scene.frame_current == 1  # the frame the bake started from

    cache = addon.cache.load(obj)
    vertex_count = len(obj.data.vertices)
    assert cache.radiance.shape == (5, vertex_count, 3) and cache.radiance.dtype == np.float32
    assert cache.ao.shape == (5, vertex_count)
    assert cache.transfer.shape == (5, vertex_count, 25) and cache.transfer.dtype == np.float16
    assert [addon.cache.is_valid(obj, scene, f) for f in range(0, 7)] == [False] + [True] * 5 + [False]
    # The figure walks: the frames differ.
    assert not np.allclose(cache.radiance[0], cache.radiance[4])


def test_cache_matches_live_computation(addon, figure):
    scene, obj = figure
    bake(addon, scene, obj, 1, 4)
    cache = addon.cache.load(obj)
    addon.cache.clear(obj)
    scene.hemishadow.live = True
    for frame in (2, 4):
        scene.frame_set(frame)
        radiance, ao = attributes(obj)
        np.testing.assert_allclose(radiance, cache.radiance[frame - 1], rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(ao, cache.ao[frame - 1], rtol=1e-5, atol=1e-6)


def test_playback_copies_cached_values_exactly(addon, figure):
    scene, obj = figure
    bake(addon, scene, obj, 1, 5)
    cache = addon.cache.load(obj)
    engine_bridge = addon.engine_bridge
    scene.hemishadow.live = True
    for frame in (3, 5, 1, 4):
        engine_bridge.last_timings.clear()
        scene.frame_set(frame)
        radiance, ao = attributes(obj)
        assert np.array_equal(radiance, cache.radiance[frame - 1])
        assert np.array_equal(ao, cache.ao[frame - 1])
        assert obj.name not in engine_bridge.last_timings  # copied, not computed

    # Outside the cached range the live path computes again.
    scene.frame_set(7)
    assert obj.name in engine_bridge.last_timings


def test_cache_is_invalid_after_a_settings_or_topology_change(addon, figure):
    scene, obj = figure
    bake(addon, scene, obj, 1, 3)
    assert addon.cache.is_valid(obj, scene, 2)
    obj.hemishadow.bands = "9"
    assert not addon.cache.is_valid(obj, scene, 2)
    assert "settings" in addon.cache.why_invalid(obj, scene, 2)
    obj.hemishadow.bands = "25"
    assert addon.cache.is_valid(obj, scene, 2)
    obj.data.vertices[0].co.x += 0.01
    assert "edited" in addon.cache.why_invalid(obj, scene, 2)
    obj.data.polygons[0].vertices = tuple(reversed(obj.data.polygons[0].vertices))
    assert "topology" in addon.cache.why_invalid(obj, scene, 2)


def test_lighting_change_reshades_from_float16_transfer(addon, figure):
    scene, obj = figure
    bake(addon, scene, obj, 1, 3)
    cache = addon.cache.load(obj)
    # Same lighting: re-shading the float16 transfer reproduces the float32 radiance closely.
    lighting = addon.engine_bridge.scene_lighting(scene, 5)
    albedo = np.asarray(obj.hemishadow.albedo, np.float32)
    import hemishadow

    reshaded = hemishadow.shade(cache.transfer[1].astype(np.float32), lighting, albedo)
    error = np.abs(reshaded - cache.radiance[1]).max() / np.abs(cache.radiance[1]).max()
    assert error < 2e-3
    # Twice the intensity: the cache stays valid and playback shows twice the radiance.
    scene.hemishadow.intensity = 2.0
    assert addon.cache.is_valid(obj, scene, 2)
    assert addon.cache.apply_cached(obj, 2, scene)
    radiance, _ = attributes(obj)
    np.testing.assert_allclose(radiance, 2 * cache.radiance[1], rtol=0, atol=4e-3 * np.abs(cache.radiance[1]).max())


def test_without_transfer_a_lighting_change_invalidates(addon, figure):
    scene, obj = figure
    bake(addon, scene, obj, 1, 2, store_transfer=False)
    assert addon.cache.load(obj).transfer is None
    assert addon.cache.is_valid(obj, scene, 1)
    scene.hemishadow.intensity = 0.5
    assert "lighting" in addon.cache.why_invalid(obj, scene, 1)


def test_cancel_stops_early_and_saves_nothing(addon, figure, tmp_path):
    scene, obj = figure
    cancel = threading.Event()

    def progress(done, total):
        if done == 2:
            cancel.set()

    result = bake(addon, scene, obj, 1, 30, progress=progress, cancel=cancel)
    assert result.cancelled
    assert 2 <= result.frames_done <= 4  # the frames already in flight may finish
    assert result.saved == {}
    assert not (tmp_path / "hemishadow_cache").exists()
    assert addon.cache.load(obj) is None
    assert scene.frame_current == 1


@pytest.mark.parametrize("location", ["FILE", "PACKED"])
def test_save_and_reload_keep_the_cache(addon, figure, tmp_path, location):
    scene, obj = figure
    bake(addon, scene, obj, 2, 4, location=location)
    expected = addon.cache.load(obj).radiance.copy()
    name = obj.name
    bpy.ops.wm.save_mainfile()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.cache._loaded.clear()   # read it back from the file or the packed bytes
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "figure.blend"))
    scene = bpy.context.scene
    obj = scene.objects[name]
    assert addon.cache.is_valid(obj, scene, 3)
    assert (addon.cache.PACKED_KEY in obj) == (location == "PACKED")
    assert addon.cache.apply_cached(obj, 3, scene)
    radiance, _ = attributes(obj)
    assert np.array_equal(radiance, expected[1])


def test_bad_requests_raise_clear_errors(addon, figure):
    scene, obj = figure
    bake_range = addon.operators.bake.bake_range
    with pytest.raises(ValueError, match="empty"):
        bake_range(scene, [obj], 5, 4)
    with pytest.raises(ValueError, match="no objects"):
        bake_range(scene, [], 1, 2)
    with pytest.raises(ValueError, match="not a mesh"):
        bake_range(scene, [scene.objects["Armature"] if "Armature" in scene.objects else scene.camera], 1, 2)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_cube_add()
    with pytest.raises(ValueError, match="not saved"):
        bake_range(bpy.context.scene, [bpy.context.object], 1, 2)
    assert bake_range(bpy.context.scene, [bpy.context.object], 1, 2, location="PACKED").frames_done == 2


def test_operator_bakes_without_a_window(addon, figure, tmp_path):
    """In background mode there is no window for the modal run: the operator bakes in one go."""
    scene, obj = figure
    with bpy.context.temp_override(scene=scene, active_object=obj, object=obj, selected_objects=[obj]):
        assert bpy.ops.hemishadow.bake_animation("INVOKE_DEFAULT", frame_start=2, frame_end=3) == {"FINISHED"}
    assert (tmp_path / "hemishadow_cache" / f"{obj.name}.npz").is_file()
    assert addon.cache.is_valid(obj, scene, 3) and not addon.cache.is_valid(obj, scene, 4)
    with bpy.context.temp_override(scene=scene, active_object=obj, object=obj, selected_objects=[obj]):
        assert bpy.ops.hemishadow.clear_bake() == {"FINISHED"}
    assert addon.cache.load(obj) is None
    assert not (tmp_path / "hemishadow_cache" / f"{obj.name}.npz").exists()


# -- stale caches: the animation changed after the bake ------------------------------------------

def fcurves(action):
    if bpy.app.version < (4, 4):  # before layered actions, an Action holds its F-Curves
        return list(action.fcurves)
    return [c for layer in action.layers for strip in layer.strips for bag in strip.channelbags for c in bag.fcurves]


def served(addon, scene, obj, frame):
    """Step to `frame` with Live on; True when the cache supplied it (nothing was computed)."""
    if not scene.hemishadow.live:   # switching it on computes the current frame
        scene.hemishadow.live = True
    addon.engine_bridge.forget()   # a computation would then always show in last_timings
    addon.engine_bridge.last_timings.clear()
    scene.frame_set(frame)
    return obj.name not in addon.engine_bridge.last_timings


def assert_stale(addon, scene, obj, frame, words):
    """The cache is reported stale for `words` and not applied: the frame is computed live,
    the attributes are not the cached ones, the status and the console say so."""
    cached = addon.cache.load(obj)
    reason = addon.cache.why_invalid(obj, scene, frame)
    assert reason is not None and "stale" in reason and words in reason, reason
    assert not served(addon, scene, obj, frame)
    assert words in addon.cache.stale_reason(obj)
    assert obj.hemishadow.status.startswith("Bake cache stale, computed live")
    assert not addon.cache.apply_cached(obj, frame, scene)
    return cached


def torso_rotation(obj):
    action = obj.find_armature().animation_data.action
    return [c for c in fcurves(action) if c.data_path == 'pose.bones["torso_joint_1"].rotation_quaternion'
            and c.array_index == 1][0]


def test_edited_keyframes_make_the_cache_stale(addon, figure, capsys):
    scene, obj = figure
    bake(addon, scene, obj, 1, 5)
    assert all(served(addon, scene, obj, f) for f in (1, 2, 3))   # no false alarm before the edit
    curve = torso_rotation(obj)
    for key in curve.keyframe_points:
        for point in (key.co, key.handle_left, key.handle_right):
            point.y += 0.3
    curve.update()
    cached = assert_stale(addon, scene, obj, 4, "the keyframes of 'Armature' changed since the bake")
    radiance, _ = attributes(obj)
    assert np.abs(radiance - cached.radiance[3]).max() > 0.02   # the live values, not the stale ones
    assert "bake cache not used, it is stale" in capsys.readouterr().out

    class Layout:   # what the object panels draw
        lines = []

        def label(self, text, icon="NONE"):
            self.lines.append((text, icon))

    addon.cache.draw_status(Layout(), obj)
    assert Layout.lines[0] == ("Bake cache stale: not used, computed live", "ERROR")
    assert "keyframes of 'Armature'" in Layout.lines[1][0]


def test_a_disabled_modifier_makes_the_cache_stale(addon, figure):
    scene, obj = figure
    bake(addon, scene, obj, 1, 4)
    obj.modifiers["Armature"].show_viewport = False
    assert_stale(addon, scene, obj, 3, "the modifiers of 'Proxy' changed")


def test_an_added_constraint_makes_the_cache_stale(addon, figure):
    scene, obj = figure
    bake(addon, scene, obj, 1, 4)
    limit = obj.find_armature().pose.bones["torso_joint_1"].constraints.new("LIMIT_ROTATION")
    limit.use_limit_x = limit.use_limit_y = limit.use_limit_z = True
    assert_stale(addon, scene, obj, 2, "'Armature' has new constraints")


def test_positions_catch_what_the_digests_cannot_see(addon, figure):
    """Moving the object (no animation involved) changes its lighting: the per-frame position
    fingerprint refuses the cache on that frame, and it serves again once moved back."""
    scene, obj = figure
    bake(addon, scene, obj, 1, 4)
    obj.find_armature().location.x += 0.5
    assert_stale(addon, scene, obj, 1, "the evaluated positions at frame 1 are not the bake's")
    obj.find_armature().location.x -= 0.5
    assert served(addon, scene, obj, 2) and addon.cache.stale_reason(obj) is None


def test_playback_start_and_first_cached_frames_compare_the_digests(addon, figure):
    scene, obj = figure
    bake(addon, scene, obj, 1, 5)
    assert (addon.cache.on_playback_start in bpy.app.handlers.animation_playback_pre
            and addon.cache.on_render_init in bpy.app.handlers.render_init)
    curve = torso_rotation(obj)
    key = curve.keyframe_points[-1]   # the last key: frames after the current one
    value = key.co.y
    key.co.y = value + 0.3
    addon.cache.on_playback_start(scene)
    assert "keyframes" in addon.cache.stale_reason(obj)
    addon.cache.on_reset()       # as undo does
    assert served(addon, scene, obj, 2) is False   # the first cached frame compares the digests too
    key.co.y = value
    addon.cache.on_reset()
    assert served(addon, scene, obj, 2) and addon.cache.stale_reason(obj) is None
    key.co.y = value + 0.3
    addon.cache.on_render_init(scene)   # a render starts: its first cached frame checks again
    assert served(addon, scene, obj, 3) is False and "keyframes" in addon.cache.stale_reason(obj)


@pytest.fixture
def cloth(addon, tmp_path):
    """A saved .blend with a 289-vertex cloth falling onto a cube collider; returns (scene, cloth)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_cube_add(size=1)
    bpy.context.object.modifiers.new("Collision", "COLLISION")
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=16, y_subdivisions=16, size=2, location=(0, 0, 1))
    obj = bpy.context.object
    obj.name = "Cloth"
    obj.modifiers.new("Cloth", "CLOTH")
    obj.hemishadow.enabled = True
    scene = bpy.context.scene
    scene.hemishadow.lighting_source = "BUILTIN"
    scene.frame_set(1)
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "cloth.blend"))
    return scene, obj


def test_a_changed_simulation_makes_the_cache_stale(addon, cloth):
    scene, obj = cloth
    bake(addon, scene, obj, 1, 10)
    assert [f for f in range(1, 11) if not served(addon, scene, obj, f)] == []   # in order: the bake's drape
    obj.modifiers["Cloth"].settings.mass = 2.0
    assert_stale(addon, scene, obj, 10, "the simulation of 'Cloth' changed")


def test_a_disabled_collider_makes_the_cache_stale(addon, cloth):
    scene, obj = cloth
    bake(addon, scene, obj, 1, 6)
    scene.objects["Cube"].modifiers["Collision"].show_viewport = False
    assert "the modifiers of 'Cube' changed" in addon.cache.why_invalid(obj, scene, 4)


# -- the cache folder and the files ---------------------------------------------------------------

@pytest.mark.parametrize("where, message", [
    ("file", "is a file, not a folder"),
    ("file/below", "is a file, not a folder"),
    ("/proc/hemishadow-cache", "cannot write the cache folder /proc/hemishadow-cache"),
])
def test_a_bad_cache_folder_fails_before_the_bake_starts(addon, figure, tmp_path, where, message):
    scene, obj = figure
    (tmp_path / "file").write_text("in the way")
    folder = where if where.startswith("/") else str(tmp_path / where)
    progress = []
    with pytest.raises(ValueError, match=message) as error:
        bake(addon, scene, obj, 1, 3, directory=folder, progress=lambda done, total: progress.append(done))
    assert folder in str(error.value)
    assert progress == [] and scene.frame_current == 1   # not a single frame computed


def test_cache_files_get_the_usual_permissions(addon, figure, tmp_path):
    scene, obj = figure
    old = os.umask(0o027)
    try:
        bake(addon, scene, obj, 1, 2)
    finally:
        os.umask(old)
    mode = (tmp_path / "hemishadow_cache" / f"{obj.name}.npz").stat().st_mode & 0o777
    assert mode == 0o640
    assert [p.name for p in (tmp_path / "hemishadow_cache").iterdir()] == [f"{obj.name}.npz"]   # no temporary left


def test_no_false_alarm_after_renaming_the_object(addon, figure):
    scene, obj = figure
    bake(addon, scene, obj, 1, 3)
    obj.name = "Walker"
    assert addon.cache.is_valid(obj, scene, 2) and served(addon, scene, obj, 2)
    addon.cache.on_playback_start(scene)
    assert addon.cache.stale_reason(obj) is None
