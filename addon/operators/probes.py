"""Bake Probes and the probe preview (issue 12).

Thin: `addon.probes` does the work. Blocking for now, with Blender's progress bar (no Esc
yet, as Bake Lightmaps); files are written only once every probe is baked.
"""

import bpy

from .. import probe_lighting, probes


def _volume(context):
    return probes.active_volume(context)


class HEMISHADOW_OT_bake_probes(bpy.types.Operator):
    """Bake ambient cubes and SH9 at the samples of the active Light Probe Volume (or in the active Empty's bounds)"""

    bl_idname = "hemishadow.bake_probes"
    bl_label = "Bake Probes"
    bl_options = {"REGISTER"}

    bounces: bpy.props.IntProperty(name="Bounces", default=2, min=0, max=16)
    resolution: bpy.props.IntVectorProperty(name="Empty Resolution", size=3, default=probes.EMPTY_RESOLUTION, min=1,
                                            max=256, description="Samples per axis when baking an Empty's bounds")
    filepath: bpy.props.StringProperty(name="File", default="", subtype="FILE_PATH",
                                       description="Where the .npz goes (default //probes/<volume>.npz)")

    @classmethod
    def poll(cls, context):
        return _volume(context) is not None

    def execute(self, context):
        volume = _volume(context)
        wm = context.window_manager
        wm.progress_begin(0, 1000)
        try:
            result, path = probes.bake_probes(context.scene, volume, bounces=self.bounces,
                                              resolution=tuple(self.resolution), out=self.filepath or None,
                                              progress=lambda f: wm.progress_update(int(1000 * f)))
        except (ValueError, OSError) as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        for note in result["notes"]:
            self.report({"WARNING"}, f"{volume.name}: {note}")
        self.report({"INFO"}, f"hemishadow: baked {len(result['positions'])} probes of {volume.name}"
                              + (f" to {path}" if path else " (kept in the .blend)"))
        return {"FINISHED"}


class HEMISHADOW_OT_probe_preview(bpy.types.Operator):
    """Show or hide small spheres at the active volume's baked probes, coloured by their lighting"""

    bl_idname = "hemishadow.probe_preview"
    bl_label = "Probe Preview"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return _volume(context) is not None

    def execute(self, context):
        volume = _volume(context)
        if probes.remove_preview(volume):
            return {"FINISHED"}
        try:
            probes.preview(context.scene, volume)
        except ValueError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        # the probes shown are the ones stored (an undo may have brought older ones back)
        probe_lighting.reshade_users(context.scene, volume)
        return {"FINISHED"}


classes = (HEMISHADOW_OT_bake_probes, HEMISHADOW_OT_probe_preview)
