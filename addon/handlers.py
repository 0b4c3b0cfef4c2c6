"""Live updates: frame changes and deformations of enabled objects recompute their outputs.

Loops are impossible by construction, on two levels:
- `_busy` stops a handler from running inside another (anything we call that evaluates the
  depsgraph synchronously would otherwise re-enter).
- Writing attributes tags the mesh, so Blender evaluates it again and calls
  depsgraph_update_post with that object; engine_bridge then sees the same positions as
  last time and computes and writes nothing.

Lighting that changes without a depsgraph update naming it (keyframed or driven lamps and
World inputs, in playback and in animation renders) is caught by comparing a cheap
fingerprint of every lighting input (lighting.py) after each frame change and update; a
change re-shades from the stored transfer. Handlers never render: a World that needs a
Cycles render is rendered from a timer (world_render.py), and `render_init` reports frames
of an animated World that were not precomputed.

No error leaves a handler: engine and input errors go to the object's status line and the
console.

Heavy objects go to a worker thread (jobs.py) when Blender itself changed the frame or the
data in a window; renders, scripts and background mode compute synchronously. A render
waits for the jobs first, and computes synchronously from render_init to its end.
"""

import bpy
from bpy.app.handlers import persistent

from . import cache, casters, engine_bridge, evaluated, jobs, lighting, world_render

_busy = False
#: scene name -> lighting.fingerprint the objects were last shaded with.
_lighting_seen: dict[str, str] = {}


def _cache_handled(obj, scene, depsgraph):
    """True when a bake cache supplied this frame (cache.py, by the bake helper)."""
    try:
        return cache.handled(obj, scene, depsgraph)
    except (ValueError, RuntimeError, OSError) as error:
        print(f"hemishadow: {obj.name}: bake cache not used: {error}")
        return False


def _report(errors):
    for name, message in errors.items():  # engine_bridge's messages start with the object's name
        print(f"hemishadow: {message if message.startswith(f'{name}:') else f'{name}: {message}'}")


def _live_objects(scene, depsgraph=None):
    return [o for o in engine_bridge.enabled_objects(scene) if not _cache_handled(o, scene, depsgraph)]


def _live_and_idle(handler):
    """Runs `handler(scene, depsgraph)` only while Live is on and no handler is running, and
    marks one as running meanwhile (writing attributes triggers depsgraph updates)."""

    def guarded(scene, depsgraph):
        global _busy
        if _busy or not scene.hemishadow.live or world_render.probing():
            return
        _busy = True
        try:
            # Blender cannot start a render from a handler; in animation renders only the
            # render's depsgraph holds this frame's lighting.
            with world_render.no_render(), evaluated.using(depsgraph):
                handler(scene, depsgraph)
        finally:
            _busy = False

    guarded.__name__ = handler.__name__
    return guarded


def _lighting_changed(scene):
    """True (once) when any lighting input differs from the last time: keyframed or driven
    World inputs, moved, hidden or edited lamps, the scene's lighting settings."""
    now = lighting.fingerprint(scene)
    if _lighting_seen.get(scene.name) == now:
        return False
    _lighting_seen[scene.name] = now
    return True


def lighting_seen(scene):
    """The live objects were just computed under the lighting as it is (Live switched on):
    record it, so that the next update does not shade them all again (which would also
    replace the computation's timings with the shading's), and report it."""
    _lighting_seen[scene.name] = lighting.fingerprint(scene)
    lighting.report(scene)


def reshade_live(scene, live=None):
    """Re-shade the live objects with the lighting as it is now (a valid bake cache re-shades
    its own), and tell the user what they must know about that lighting."""
    engine_bridge.reshade_scene(scene, _live_objects(scene) if live is None else live)
    lighting.report(scene)


def _reshade_if_lighting_changed(scene, live=None, named=False):
    if _lighting_changed(scene) or named:
        reshade_live(scene, live)


@persistent
@_live_and_idle
def on_frame_change(scene, depsgraph):
    live = _live_objects(scene, depsgraph)
    jobs.drop([o for o in engine_bridge.enabled_objects(scene) if o not in live], scene.frame_current)  # cached
    _report(jobs.update_scene(scene, depsgraph, live, interactive=jobs.interactive()))
    _reshade_if_lighting_changed(scene, live)


def _deformed_objects(scene, depsgraph):
    """Enabled objects the update re-evaluated geometrically (poses, shape keys, edits), or
    whose shadow casters it moved."""
    uids = {u.id.original.session_uid for u in depsgraph.updates
            if isinstance(u.id, bpy.types.Object) and u.is_updated_geometry}
    enabled = engine_bridge.enabled_objects(scene)
    touched = {o.session_uid for o in casters.receivers_touched(scene, depsgraph, enabled)}  # their casters moved
    return [o for o in enabled if o.session_uid in uids or o.session_uid in touched]


def _lighting_updated(depsgraph):
    return any(isinstance(u.id, (bpy.types.World, bpy.types.Light)) for u in depsgraph.updates)


@persistent
@_live_and_idle
def on_depsgraph_update(scene, depsgraph):
    objects = [o for o in _deformed_objects(scene, depsgraph) if not _cache_handled(o, scene, depsgraph)]
    if objects:
        _report(jobs.update_scene(scene, depsgraph, objects, interactive=jobs.interactive()))
    _reshade_if_lighting_changed(scene, named=_lighting_updated(depsgraph))


@persistent
def on_load(_):
    jobs.reset()
    engine_bridge.forget()
    _lighting_seen.clear()


@persistent
def on_render_init(scene, *_):
    """Renders compute synchronously (jobs.py); they cannot render the World themselves: say
    which frames have no projection."""
    if world_render.probing():
        return
    jobs.set_rendering(True)
    if scene.hemishadow.live:
        lighting.check_before_render(scene)


@persistent
def on_render_pre(scene, *_):
    """A rendered frame is never stale: wait for the heavy objects computing in the background."""
    if not world_render.probing():
        jobs.finish_all(recompute_cancelled=scene.hemishadow.live)


@persistent
def on_render_end(scene, *_):
    if not world_render.probing():
        jobs.set_rendering(False)


@persistent
def on_undo_redo(scene, *_):
    engine_bridge.forget_positions()


_HANDLERS = (
    (bpy.app.handlers.frame_change_post, on_frame_change),
    (bpy.app.handlers.depsgraph_update_post, on_depsgraph_update),
    (bpy.app.handlers.load_post, on_load),
    (bpy.app.handlers.render_init, on_render_init),
    (bpy.app.handlers.render_pre, on_render_pre),
    (bpy.app.handlers.render_complete, on_render_end),
    (bpy.app.handlers.render_cancel, on_render_end),
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
    jobs.reset()
    engine_bridge.forget()
