"""UI: the "Panorama" panel of the Hemishadow tab (issue 13): bake a relightable panorama from
a camera or a point, then relight it live in the Image Editor (image 'hemishadow_panorama')."""

import bpy


class HEMISHADOW_PT_panorama(bpy.types.Panel):
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Hemishadow"
    bl_label = "Panorama"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        s = context.scene.hemishadow_panorama
        layout.prop(s, "source", expand=True)
        layout.prop(s, "camera" if s.source == "CAMERA" else "point")
        row = layout.row(align=True)
        row.prop(s, "width")
        row.prop(s, "height")
        layout.prop(s, "coefficients", expand=True)
        layout.prop(s, "bounces")
        layout.prop(s, "filepath")
        layout.operator("hemishadow.bake_panorama", icon="RENDER_STILL")
        box = layout.box()
        box.prop(s, "baked")
        box.prop(s, "live", icon="LIGHT_SUN")
        box.prop(s, "lights", expand=True)
        if s.lights == "DIRECTION":
            box.prop(s, "direction")
            box.prop(s, "strength")
        box.prop(s, "use_world")
        box.prop(s, "exposure")
        row = box.row(align=True)
        row.operator("hemishadow.relight_panorama", icon="FILE_REFRESH")
        row.operator("hemishadow.save_relit_panorama", icon="FILE_IMAGE")


classes = (HEMISHADOW_PT_panorama,)

register, unregister = bpy.utils.register_classes_factory(classes)
