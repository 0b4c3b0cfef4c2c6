"""Any World -> lighting SH: Cycles renders the World alone into a small equirectangular image.

`world.py` projects a plain Environment Texture directly (its fast path) and a plain
Background colour exactly; every other node setup (Sky Texture, gradients, mixes, groups,
...) is rendered here: a temporary scene holding only a panoramic equirectangular camera, a
temporary copy of the World (so the user's World is never touched; in the copy, Light Path
outputs are replaced by the values a diffuse ray sees, since diffuse rays are what light the
object), 256 x 128 pixels, 16 samples (about a second). The image is projected with
`hemishadow.project_environment`; everything temporary is removed.

Blender cannot start a render inside a frame handler or while rendering, so nothing here
renders by itself from a handler: `cached` only looks up, and `schedule` asks a
`bpy.app.timers` callback to render what is missing (the current frame, then every frame of
the scene's range when the World is animated). `precompute(scene, frames)` does the same at
once, for operators, the bake and scripts.

Projections are cached by the World, a fingerprint of its nodes (types, settings, unlinked
input values, links, node groups, images, animation curves) and, for an animated World, the
frame; a change of any of them (including a keyframed input) asks for a new render.
"""

from __future__ import annotations

import collections
import contextlib
import hashlib
import math
import os
import tempfile

import bpy
import numpy as np

__all__ = ["fingerprint", "animated_values", "value_key", "is_animated", "cached", "nearest", "render_projection", "precompute", "missing_frames",
           "schedule", "no_render", "can_render", "clear"]

WIDTH, HEIGHT, SAMPLES, BANDS = 256, 128, 16, 5  # 128 x 64 leaves 3 % noise on the forest HDRI
_CACHE_SIZE = 1024
_projections: collections.OrderedDict = collections.OrderedDict()
_no_render = 0
_probing = False
_scheduled: dict[str, object] = {}   # scene name -> callback run after each new projection

# Properties of a node that change nothing it emits.
_UI_PROPERTIES = {"rna_type", "type", "location", "location_absolute", "width", "height", "dimensions", "name",
                  "label", "inputs", "outputs", "internal_links", "parent", "warning_propagation",
                  "use_custom_color", "color", "color_tag", "select", "show_options", "show_preview", "hide",
                  "show_texture", "bl_idname", "bl_label", "bl_description", "bl_icon", "bl_static_type",
                  "bl_width_default", "bl_width_min", "bl_width_max", "bl_height_default", "bl_height_min",
                  "bl_height_max", "is_active_output", "texture_mapping", "color_mapping", "image_user"}

# What a diffuse ray leaving a surface sees in the Light Path node's outputs.
_DIFFUSE_RAY = {"Is Camera Ray": 0.0, "Is Shadow Ray": 0.0, "Is Diffuse Ray": 1.0, "Is Glossy Ray": 0.0,
                "Is Singular Ray": 0.0, "Is Reflection Ray": 1.0, "Is Transmission Ray": 0.0,
                "Is Volume Scatter Ray": 0.0, "Ray Length": 1e10, "Ray Depth": 1.0, "Diffuse Depth": 1.0,
                "Glossy Depth": 0.0, "Transparent Depth": 0.0, "Transmission Depth": 0.0, "Portal Depth": 0.0}


def clear():
    _projections.clear()


@contextlib.contextmanager
def no_render():
    """Inside handlers: lookups only, missing projections are scheduled for a timer."""
    global _no_render
    _no_render += 1
    try:
        yield
    finally:
        _no_render -= 1


def can_render() -> bool:
    return not _no_render and not _probing and not bpy.app.is_job_running("RENDER")


def probing() -> bool:
    """True while our own temporary render runs (handlers ignore what it causes)."""
    return _probing


# ----------------------------------------------------------------------------------------
# Fingerprint


def _anim_datas(world):
    return [a for a in (world.animation_data, world.node_tree.animation_data if world.node_tree else None) if a]


def _fcurves(anim):
    action = anim.action
    if action is None:
        return []
    try:
        from bpy_extras import anim_utils

        bag = anim_utils.action_get_channelbag_for_slot(action, anim.action_slot)
        return list(bag.fcurves) if bag is not None else []
    except (ImportError, AttributeError):
        return list(getattr(action, "fcurves", []))


def _animated_paths(world):
    paths = set()
    for anim in _anim_datas(world):
        paths.update(f.data_path for f in _fcurves(anim))
        paths.update(d.data_path for d in anim.drivers)
        if len(anim.nla_tracks):
            paths.add("*")
    return paths


def is_animated(world) -> bool:
    """True when the World's output may change with the frame (keyframes, drivers, NLA)."""
    return world is not None and bool(_animated_paths(world))


def _value(value, depth=0):
    """A comparable, hashable summary of a property value (nested structs such as a Color
    Ramp's elements or an RGB Curves mapping included, a few levels deep)."""
    if isinstance(value, bpy.types.ID):
        return _id_key(value)
    if isinstance(value, (bpy.types.bpy_struct, bpy.types.bpy_prop_collection)):
        return _struct_value(value, depth)
    if hasattr(value, "__len__") and not isinstance(value, str):
        return tuple(_value(v, depth + 1) for v in value)
    if isinstance(value, float):
        return round(value, 7)
    return value


def _struct_value(value, depth):
    if depth > 3:
        return None
    if isinstance(value, bpy.types.bpy_prop_collection):
        return tuple(_value(item, depth + 1) for item in value)
    items = []
    for prop in value.bl_rna.properties:
        name = prop.identifier
        if name in ("rna_type", "id_data") or (prop.type == "POINTER" and not prop.is_never_none
                                               and not isinstance(getattr(value, name, None), bpy.types.ID)):
            continue
        items.append((name, _value(getattr(value, name, None), depth + 1)))
    return tuple(items)


def _id_key(data):
    if isinstance(data, bpy.types.Image):
        key = (data.name_full, data.filepath, data.source, tuple(data.size), data.is_dirty,
               data.colorspace_settings.name)
        path = bpy.path.abspath(data.filepath, library=data.library) if data.source == "FILE" else ""
        return key + ((os.stat(path).st_mtime_ns,) if path and os.path.isfile(path) else ())
    if isinstance(data, bpy.types.NodeTree):
        return (data.name_full, _tree_key(data, set(), data.name_full))
    return (type(data).__name__, data.name_full)


def _tree_key(tree, animated, prefix=""):
    items = []
    for node in sorted(tree.nodes, key=lambda n: n.name):
        path = f'nodes["{node.name}"]'
        props = []
        for prop in node.bl_rna.properties:
            name = prop.identifier
            if name in _UI_PROPERTIES or f"{path}.{name}" in animated:
                continue
            props.append((name, _value(getattr(node, name, None))))
        inputs = []
        for i, socket in enumerate(node.inputs):
            value = None
            keyed = f"{path}.inputs[{i}].default_value" in animated
            if not socket.is_linked and hasattr(socket, "default_value") and not keyed:
                value = _value(socket.default_value)
            inputs.append((socket.identifier, socket.is_linked, value))
        items.append((node.name, node.bl_idname, node.mute, tuple(props), tuple(inputs)))
    links = sorted((l.from_node.name, l.from_socket.identifier, l.to_node.name, l.to_socket.identifier, l.is_muted)
                   for l in tree.links)
    return (tuple(items), tuple(links))


def _curves_key(world):
    keys = []
    for anim in _anim_datas(world):
        for curve in _fcurves(anim):
            points = np.empty(len(curve.keyframe_points) * 2, np.float32)
            curve.keyframe_points.foreach_get("co", points)
            keys.append((curve.data_path, curve.array_index, points.tobytes(), len(curve.modifiers),
                         tuple(k.interpolation for k in curve.keyframe_points)))
        for driver in anim.drivers:
            keys.append((driver.data_path, driver.array_index, driver.driver.expression,
                         tuple((v.name, v.type, tuple((t.id_type, str(t.id), t.data_path) for t in v.targets))
                               for v in driver.driver.variables)))
        keys.append(("nla", len(anim.nla_tracks)))
    return tuple(keys)


def animated_values(world) -> tuple:
    """The current values of the World's animated properties (which `fingerprint` leaves out)."""
    values = []
    for owner in (world, world.node_tree):
        if owner is None or owner.animation_data is None:
            continue
        for path in sorted(_animated_paths(world) - {"*"}):
            try:
                values.append((path, _value(owner.path_resolve(path))))
            except (ValueError, AttributeError):
                continue
    return tuple(values)


def value_key(value):
    """A comparable summary of a property value (see `fingerprint`)."""
    return _value(value)


def fingerprint(world) -> str:
    """A digest of everything in the World that changes what it emits, except the values of
    animated inputs (those are keyed by frame; their curves are in the digest)."""
    animated = _animated_paths(world)
    key = (world.name_full, _tree_key(world.node_tree, animated) if world.node_tree else None, _curves_key(world))
    return hashlib.blake2b(repr(key).encode(), digest_size=16).hexdigest()


def _key(world, frame):
    world = world.original
    return (world.session_uid, fingerprint(world), int(frame) if is_animated(world) else None)


# ----------------------------------------------------------------------------------------
# Lookups


def cached(world, frame) -> np.ndarray | None:
    """The projection (25, 3) of the World as it is at `frame`, or None when not rendered yet."""
    found = _projections.get(_key(world, frame))
    return None if found is None else found.copy()


def nearest(world, frame) -> np.ndarray | None:
    """The closest projection of this World there is (another frame, or before the last edit), or None."""
    uid, best, best_distance = world.original.session_uid, None, None
    for (w, _fp, f), value in reversed(_projections.items()):
        if w != uid:
            continue
        distance = 0 if f is None else abs(f - int(frame))
        if best is None or distance < best_distance:
            best, best_distance = value, distance
    return None if best is None else best.copy()


def missing_frames(scene, frames=None) -> list[int]:
    """Frames (default: the current one, or the whole range for an animated World) not projected yet."""
    from .world import needs_render

    world = scene.world
    if world is None or not needs_render(world):
        return []
    if frames is None:
        frames = range(scene.frame_start, scene.frame_end + 1) if is_animated(world) else [scene.frame_current]
    animated = is_animated(world)
    if not animated:
        frames = list(frames)[:1]
    uid, digest = world.original.session_uid, fingerprint(world.original)
    return [f for f in frames if (uid, digest, int(f) if animated else None) not in _projections]


# ----------------------------------------------------------------------------------------
# Rendering


def _as_diffuse_rays(tree):
    """In a (temporary) tree: Light Path outputs -> the constants a diffuse ray sees."""
    for node in [n for n in tree.nodes if n.type == "LIGHT_PATH"]:
        for output in node.outputs:
            for link in list(output.links):
                value = tree.nodes.new("ShaderNodeValue")
                value.outputs[0].default_value = _DIFFUSE_RAY.get(output.name, 0.0)
                target = link.to_socket
                tree.links.remove(link)
                tree.links.new(value.outputs[0], target)


def _freeze_animation(copy, frame):
    """In the (temporary) copy: every F-curve's value at `frame` written in, the animation
    removed. A still render does not evaluate the copy's animation at the probe's frame."""
    for owner in (copy, copy.node_tree):
        anim = owner.animation_data if owner is not None else None
        if anim is None:
            continue
        for curve in _fcurves(anim):
            base, _, name = curve.data_path.rpartition(".")
            try:
                target = owner.path_resolve(base) if base else owner
                value = curve.evaluate(frame)
                current = getattr(target, name)
                if hasattr(current, "__len__") and not isinstance(current, str):
                    current[curve.array_index] = value
                else:
                    setattr(target, name, type(current)(value) if isinstance(current, (bool, int)) else value)
            except (ValueError, AttributeError, TypeError):
                continue
        owner.animation_data_clear()


def _probe_scene(world_copy, frame):
    scene = bpy.data.scenes.new("hemishadow_world_probe")
    scene.world = world_copy
    scene.frame_start = scene.frame_end = scene.frame_current = int(frame)
    render = scene.render
    try:
        render.engine = "CYCLES"
    except TypeError:
        bpy.data.scenes.remove(scene)
        raise RuntimeError("Cycles is not available (enable the Cycles add-on) to render the World") from None
    render.resolution_x, render.resolution_y, render.resolution_percentage = WIDTH, HEIGHT, 100
    render.use_compositing = render.use_sequencer = False
    render.image_settings.file_format = "OPEN_EXR"
    render.film_transparent = False
    scene.view_settings.view_transform = "Standard"
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.samples = SAMPLES
    cycles.use_denoising = cycles.use_adaptive_sampling = False
    cycles.pixel_filter_type, cycles.filter_width = "BOX", 1.0
    cycles.sample_clamp_direct = cycles.sample_clamp_indirect = 0.0
    camera_data = bpy.data.cameras.new("hemishadow_world_probe")
    camera_data.type = "PANO"
    camera_data.panorama_type = "EQUIRECTANGULAR"
    camera = bpy.data.objects.new("hemishadow_world_probe", camera_data)
    # Rotated (90, 0, -90) degrees: the image maps to directions as an Environment Texture does.
    camera.rotation_euler = (math.pi / 2, 0.0, -math.pi / 2)
    scene.collection.objects.link(camera)
    scene.camera = camera
    return scene, camera, camera_data


#: The Render Result slot our renders go to, when the user has a Render Result.
SLOT_NAME = "Hemishadow World Lighting"


@contextlib.contextmanager
def _own_render_slot():
    """Render into a slot of our own, so the images in the user's Render Result slots stay
    and the slot shown is restored; a Render Result that did not exist before is removed
    afterwards. (Blender cannot remove the slot last rendered into without an Image editor,
    so that one slot stays for the session; Render Results are not saved in files.)"""
    result = bpy.data.images.get("Render Result")
    previous = None
    if result is not None and result.type == "RENDER_RESULT":
        slots = result.render_slots
        previous = slots.active_index
        slots.active = next((s for s in slots if s.name == SLOT_NAME), None) or slots.new(name=SLOT_NAME)
    try:
        yield
    finally:
        after = bpy.data.images.get("Render Result")
        if result is None and after is not None:
            bpy.data.images.remove(after)
        elif previous is not None:
            result.render_slots.active_index = previous


def render_image(world, frame) -> np.ndarray:
    """The World at `frame` as Cycles shows it to diffuse rays: float32 (HEIGHT, WIDTH, 3),
    top row first, mapped like an Environment Texture. Raises RuntimeError when a render is
    running or from inside a handler."""
    global _probing
    from hemishadow.environment import read_exr

    if not can_render():
        raise RuntimeError("the World cannot be rendered now (inside a handler or during a render)")
    _probing = True
    copy = world.original.copy()
    scene = camera = camera_data = None
    try:
        _freeze_animation(copy, frame)
        if copy.node_tree is not None:
            _as_diffuse_rays(copy.node_tree)
        if hasattr(copy, "visibility"):
            copy.visibility.camera = True
        scene, camera, camera_data = _probe_scene(copy, frame)
        with tempfile.TemporaryDirectory(prefix="hemishadow_world_") as folder:
            scene.render.filepath = os.path.join(folder, "world.exr")
            with _own_render_slot():
                bpy.ops.render.render(write_still=True, scene=scene.name)
            return np.ascontiguousarray(read_exr(scene.render.filepath)[..., :3], np.float32)
    finally:
        for collection, item in ((bpy.data.objects, camera), (bpy.data.cameras, camera_data),
                                 (bpy.data.scenes, scene), (bpy.data.worlds, copy)):
            if item is not None:
                collection.remove(item)
        _probing = False


def render_projection(world, frame) -> np.ndarray:
    """Render the World at `frame`, project it (BANDS bands) and cache it; returns (25, 3)."""
    import hemishadow

    lighting = hemishadow.project_environment(render_image(world, frame), BANDS).astype(np.float64)
    _projections[_key(world, frame)] = lighting
    while len(_projections) > _CACHE_SIZE:
        _projections.popitem(last=False)
    return lighting.copy()


def precompute(scene, frames=None, progress=None) -> int:
    """Render every missing projection of the scene's World (see `missing_frames`); returns
    how many were rendered. progress(done, count) after each."""
    missing = missing_frames(scene, frames)
    for i, frame in enumerate(missing):
        render_projection(scene.world, frame)
        if progress is not None:
            progress(i + 1, len(missing))
    return len(missing)


# ----------------------------------------------------------------------------------------
# The timer


def schedule(scene, on_ready=None):
    """Render the scene's missing projections from a timer (current frame first), calling
    on_ready(scene) after each; several calls schedule one timer."""
    _scheduled[scene.name] = on_ready
    if not bpy.app.timers.is_registered(_tick):
        bpy.app.timers.register(_tick, first_interval=0.05)


def _playing() -> bool:
    """True during playback: a render of about a second per tick would stall it."""
    windows = getattr(bpy.context.window_manager, "windows", [])
    return any(w.screen is not None and w.screen.is_animation_playing for w in windows)


def _tick():
    while _scheduled:
        name, on_ready = next(iter(_scheduled.items()))
        scene = bpy.data.scenes.get(name)
        if scene is None or scene.world is None:
            _scheduled.pop(name)
            continue
        if not can_render() or _playing():
            return 0.5
        now = missing_frames(scene, [scene.frame_current])
        todo = now or missing_frames(scene)
        if not todo:
            _scheduled.pop(name)
            continue
        try:
            render_projection(scene.world, todo[0])
        except (RuntimeError, ValueError, OSError) as error:
            print(f"hemishadow: World {scene.world.name!r}: could not be rendered for lighting: {error}")
            _scheduled.pop(name)
            continue
        if on_ready is not None:
            on_ready(scene, len(missing_frames(scene)))
        return 0.01
    return None
