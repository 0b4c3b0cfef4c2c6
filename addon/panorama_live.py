"""A baked panorama relit live in Blender (issue 13): the image `hemishadow_panorama` follows
the scene's Sun and Point lamps (or the panel's direction) through the engine's native
relight, redrawn whenever a lamp changes (depsgraph_update_post), at most every
`INTERVAL` seconds: an update inside that time is relit once the interval has passed, so the
image always ends on the lamp's last position. "Save Relit Image" writes the current lights'
picture: `.exr` float linear radiance, `.png` sRGB with the Standard view transform.

Lights as `hemishadow.panorama` takes them (DESIGN.md's conventions): a sun's strength and
colour, a point lamp's power and colour (`lamps.lamp_power_color`: energy x colour x exposure);
a point lamp's radius is not used (its shadow is as soft as the SH leave it).
"""

from __future__ import annotations

import os
import time

import bpy
import numpy as np
from bpy.app.handlers import persistent

from . import lamps, lightmaps

IMAGE = "hemishadow_panorama"
INTERVAL = 1.0 / 30.0
_loaded = {}            # absolute path -> (modification time, Panorama)
_state = {"last": 0.0, "pending": False}


def load(path):
    """The Panorama at `path` (.exr or compact .json), read once per modification."""
    import hemishadow.panorama as hp

    path = bpy.path.abspath(path)
    if not os.path.isfile(path):
        raise ValueError(f"no panorama file at {path}: bake one first (Bake Panorama)")
    stamp = os.path.getmtime(path)
    if path not in _loaded or _loaded[path][0] != stamp:
        _loaded.clear()  # one panorama in memory at a time
        _loaded[path] = (stamp, hp.Panorama.load(path))
    return _loaded[path][1]


def lights(scene):
    """The `hemishadow.panorama` lights the panel's settings name."""
    import hemishadow.panorama as hp

    s = scene.hemishadow_panorama
    out = []
    if s.lights == "DIRECTION":
        out.append(hp.Sun(tuple(s.direction), s.strength))
    else:
        for obj in lamps.visible_lamps(scene, ("SUN", "POINT")):
            color = tuple(lamps.lamp_power_color(obj.data))
            if obj.data.type == "SUN":
                out.append(hp.Sun(tuple(obj.matrix_world.to_3x3().col[2]), 1.0, color))
            else:
                out.append(hp.Point(tuple(obj.matrix_world.translation), 1.0, color))
    if s.use_world:
        out.append(hp.Environment(lightmaps.lighting_of(scene)))
    return out


def relit(scene):
    """(H, W, 3) float32 linear radiance of the panel's panorama under its lights."""
    import hemishadow.panorama as hp

    s = scene.hemishadow_panorama
    return hp.relight(load(s.baked), lights(scene), exposure=s.exposure)


def store(rgb):
    """The float image IMAGE holding `rgb` (rows top first), scene-linear colour."""
    h, w = rgb.shape[:2]
    image = bpy.data.images.get(IMAGE)
    if image is None or tuple(image.size) != (w, h) or not image.is_float:
        if image is not None:
            bpy.data.images.remove(image)
        image = bpy.data.images.new(IMAGE, w, h, alpha=False, float_buffer=True)
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = rgb[::-1]  # Blender's rows start at the bottom
    image.pixels.foreach_set(rgba.ravel())
    image.update()
    return image


def update(scene):
    """Relights into IMAGE now and shows it in the open Image Editors; returns the image."""
    image = store(relit(scene))
    _state["last"] = time.perf_counter()
    wm = bpy.context.window_manager
    for window in (wm.windows if wm else ()):
        for area in window.screen.areas:
            if area.type == "IMAGE_EDITOR":
                if area.spaces.active.image is None:
                    area.spaces.active.image = image
                area.tag_redraw()
    return image


def request(scene):
    """A relight when live (settings changed, a lamp moved): now, or once INTERVAL has passed
    since the last one. Errors (no file yet) switch nothing off; they show in the panel."""
    if not scene.hemishadow_panorama.live or not scene.hemishadow_panorama.baked:
        return
    wait = INTERVAL - (time.perf_counter() - _state["last"])
    if wait <= 0:
        _safe_update(scene.name)
    elif not _state["pending"]:
        _state["pending"] = True
        bpy.app.timers.register(lambda: _deferred(scene.name), first_interval=wait)


def _deferred(scene_name):
    _state["pending"] = False
    _safe_update(scene_name)
    return None


def _safe_update(scene_name):
    scene = bpy.data.scenes.get(scene_name)
    if scene is None:
        return
    try:
        update(scene)
    except (ValueError, OSError) as error:
        print(f"hemishadow: panorama relight: {error}")


def save(scene, path):
    """Writes the relit picture: FILE.exr (float linear, R G B) or FILE.png (sRGB, Standard
    view transform), atomically. Returns the path."""
    from hemishadow.environment import write_exr
    from hemishadow.lightmap.encode import write_png
    from hemishadow.meshio import linear_to_srgb8

    path = bpy.path.abspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in (".exr", ".png"):
        raise ValueError(f"{path}: save the relit image as .exr (linear) or .png (sRGB)")
    rgb = relit(scene)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    if ext == ".exr":
        write_exr(path, {"": rgb})
    else:
        rgba = np.concatenate([linear_to_srgb8(rgb), np.full(rgb.shape[:2] + (1,), 255, np.uint8)], axis=2)
        write_png(path, rgba)
    return path


def _is_lamp_update(update):
    target = update.id
    return isinstance(target, bpy.types.Light) or (isinstance(target, bpy.types.Object) and target.type == "LIGHT")


@persistent
def on_depsgraph_update(scene, depsgraph):
    settings = getattr(scene, "hemishadow_panorama", None)
    if settings is None or not settings.live or settings.lights != "LAMPS":
        return
    world = settings.use_world and depsgraph.id_type_updated("WORLD")
    if world or any(_is_lamp_update(u) for u in depsgraph.updates):
        request(scene)


def register():
    if on_depsgraph_update not in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.append(on_depsgraph_update)


def unregister():
    if on_depsgraph_update in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(on_depsgraph_update)
    _loaded.clear()
