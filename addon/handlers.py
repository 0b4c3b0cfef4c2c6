"""Live updates: frame changes and deformations of enabled objects recompute their outputs.

Loops are impossible by construction, on two levels:
- `_busy` stops a handler from running inside another (anything we call that evaluates the
  depsgraph synchronously would otherwise re-enter).
- Writing attributes tags the mesh, so Blender evaluates it again and calls
  depsgraph_update_post with that object; engine_bridge then sees the same positions as
  last time and computes and writes nothing.

No error leaves a handler: engine and input errors go to the object's status line and the
console.
"""

import bpy
from bpy.app.handlers import persistent

from . import cache, engine_bridge

_busy = False


def _cache_handled(obj, scene, depsgraph):
    """True when a bake cache supplied this frame (cache.py, by the bake helper)."""
    try:
        return cache.handled(obj, scene, depsgraph)
    except (ValueError, RuntimeError, OSError) as error:
        print(f"hemishadow: {obj.name}: bake cache not used: {error}")
        return False


def _report(errors):
    for name, message in errors.items():
        print(f"hemishadow: {name}: {message}")


def _live_objects(scene, depsgraph):
    return [o for o in engine_bridge.enabled_objects(scene) if not _cache_handled(o, scene, depsgraph)]


def _live_and_idle(handler):
    """Runs `handler(scene, depsgraph)` only while Live is on and no handler is running, and
    marks one as running meanwhile (writing attributes triggers depsgraph updates)."""

    def guarded(scene, depsgraph):
        global _busy
        if _busy or not scene.hemishadow.live:
            return
        _busy = True
        try:
            handler(scene, depsgraph)
        finally:
            _busy = False

    guarded.__name__ = handler.__name__
    return guarded


@persistent
@_live_and_idle
def on_frame_change(scene, depsgraph):
    _report(engine_bridge.update_scene(scene, depsgraph, _live_objects(scene, depsgraph)))


def _deformed_objects(scene, depsgraph):
    """Enabled objects the update re-evaluated geometrically (poses, shape keys, edits)."""
    uids = {u.id.original.session_uid for u in depsgraph.updates
            if isinstance(u.id, bpy.types.Object) and u.is_updated_geometry}
    return [o for o in engine_bridge.enabled_objects(scene) if o.session_uid in uids]


def _lighting_updated(depsgraph):
    return any(isinstance(u.id, (bpy.types.World, bpy.types.Light)) for u in depsgraph.updates)


@persistent
@_live_and_idle
def on_depsgraph_update(scene, depsgraph):
    objects = [o for o in _deformed_objects(scene, depsgraph) if not _cache_handled(o, scene, depsgraph)]
    if objects:
        _report(engine_bridge.update_scene(scene, depsgraph, objects))
    if _lighting_updated(depsgraph):
        engine_bridge.reshade_scene(scene)


@persistent
def on_load(_):
    engine_bridge.forget()


@persistent
def on_undo_redo(scene, *_):
    engine_bridge.forget_positions()


_HANDLERS = (
    (bpy.app.handlers.frame_change_post, on_frame_change),
    (bpy.app.handlers.depsgraph_update_post, on_depsgraph_update),
    (bpy.app.handlers.load_post, on_load),
    (bpy.app.handlers.undo_post, on_undo_redo),
    (bpy.app.handlers.redo_post, on_undo_redo),
) + cache.HANDLERS   # stale-cache checks: playback and render start, edits, undo, loads


def register():
    for handlers, function in _HANDLERS:
        if function not in handlers:
            handlers.append(function)


def unregister():
    for handlers, function in _HANDLERS:
        # Compare by name too: a reloaded module has new function objects.
        for old in [h for h in handlers if getattr(h, "__name__", None) == function.__name__
                    and getattr(h, "__module__", None) == function.__module__]:
            handlers.remove(old)
    engine_bridge.forget()
