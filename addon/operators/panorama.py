"""Panorama operators (issue 13): Bake Panorama (modal, with progress and Esc), Relight
Panorama and Save Relit Image. Thin: panorama_bake.py, panorama_job.py and panorama_live.py do
the work; the settings are the scene's (`Scene.hemishadow_panorama`, the Panorama panel)."""

import bpy

from .. import panorama_bake, panorama_job, panorama_live, panorama_settings
from .modal_job import ModalJob


def _path(context):
    return bpy.path.abspath(context.scene.hemishadow_panorama.filepath or "//panoramas/panorama.exr")


class HEMISHADOW_OT_bake_panorama(ModalJob, bpy.types.Operator):
    """Bake a relightable panorama (SH coefficients per pixel) from the chosen camera or point (Esc cancels, writing nothing)"""

    bl_idname = "hemishadow.bake_panorama"
    bl_label = "Bake Panorama"
    bl_options = {"REGISTER"}

    noun = "panorama"

    @classmethod
    def poll(cls, context):
        return getattr(context.scene, "hemishadow_panorama", None) is not None

    def execute(self, context):
        """The blocking path (background mode, scripts): the plain function."""
        wm = context.window_manager
        wm.progress_begin(0, 1000)
        try:
            _, paths = panorama_bake.bake_panorama(context.scene, out=_path(context),
                                                   progress=lambda f: wm.progress_update(int(1000 * f)),
                                                   **panorama_settings.bake_arguments(context.scene))
        except (ValueError, OSError, RuntimeError) as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        return self.finished(context, paths)

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        try:
            job = panorama_job.PanoramaBake(context.scene, _path(context),
                                            **panorama_settings.bake_arguments(context.scene))
        except (ValueError, OSError, RuntimeError) as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        return self.start_modal(context, job)

    def finished(self, context, paths):
        settings = context.scene.hemishadow_panorama
        settings.baked = paths[1]  # relight from the compact 8-bit maps
        self.report({"INFO"}, f"hemishadow: panorama written to {paths[0]} and {paths[1]}")
        return {"FINISHED"}


class HEMISHADOW_OT_relight_panorama(bpy.types.Operator):
    """Relight the baked panorama with the panel's lights into the image 'hemishadow_panorama'"""

    bl_idname = "hemishadow.relight_panorama"
    bl_label = "Relight Panorama"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        settings = getattr(context.scene, "hemishadow_panorama", None)
        return settings is not None and bool(settings.baked)

    def execute(self, context):
        try:
            panorama_live.update(context.scene)
        except (ValueError, OSError) as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        return {"FINISHED"}


class HEMISHADOW_OT_save_relit_panorama(bpy.types.Operator):
    """Save the panorama relit with the panel's lights: .exr (float linear) or .png (sRGB, Standard view)"""

    bl_idname = "hemishadow.save_relit_panorama"
    bl_label = "Save Relit Image"
    bl_options = {"REGISTER"}

    filepath: bpy.props.StringProperty(subtype="FILE_PATH", default="//panoramas/relit.png")
    filter_glob: bpy.props.StringProperty(default="*.png;*.exr", options={"HIDDEN"})

    @classmethod
    def poll(cls, context):
        return HEMISHADOW_OT_relight_panorama.poll(context)

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        try:
            path = panorama_live.save(context.scene, self.filepath)
        except (ValueError, OSError) as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        self.report({"INFO"}, f"hemishadow: relit panorama saved to {path}")
        return {"FINISHED"}


classes = (HEMISHADOW_OT_bake_panorama, HEMISHADOW_OT_relight_panorama, HEMISHADOW_OT_save_relit_panorama)
