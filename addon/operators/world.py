"""Precompute World Lighting: render the World's lighting projection for the frames that need it.

A render cannot render the World itself (Blender forbids starting a render from a frame
handler or during a render), so an animated World is rendered here, frame by frame, before.
Thin: world_render.precompute does the work."""

import bpy

from .. import handlers, lighting, world_render


class HEMISHADOW_OT_precompute_world(bpy.types.Operator):
    """Render the World's lighting for the current frame, or every frame of the range when it is animated"""

    bl_idname = "hemishadow.precompute_world"
    bl_label = "Precompute World Lighting"
    bl_options = {"REGISTER"}

    def execute(self, context):
        scene = context.scene
        if scene.world is None:
            self.report({"WARNING"}, "The scene has no World: nothing to precompute")
            return {"CANCELLED"}
        wm = context.window_manager
        missing = world_render.missing_frames(scene)
        wm.progress_begin(0, max(len(missing), 1))
        try:
            done = world_render.precompute(scene, progress=lambda i, n: wm.progress_update(i))
        except (RuntimeError, ValueError, OSError) as error:
            self.report({"ERROR"}, f"World {scene.world.name!r}: {error}")
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        handlers.reshade_live(scene)
        for message in lighting.messages(scene):
            self.report({"WARNING"}, message)
        self.report({"INFO"}, f"hemishadow: rendered the World for {done} frames")
        return {"FINISHED"}


classes = (HEMISHADOW_OT_precompute_world,)
