"""UI: the "Lightmaps" panel of the Hemishadow tab (issue 11): which objects, UV map, size,
basis and quality, the output folder, and the Make Lightmap UVs, Bake Lightmaps and Add to
Materials buttons; warns of shared meshes and of objects without the UV map."""

import bpy

from . import lightmap_settings, lightmaps


class HEMISHADOW_PT_lightmaps(bpy.types.Panel):
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Hemishadow"
    bl_label = "Lightmaps"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        settings = context.scene.hemishadow_lightmaps
        layout = self.layout
        layout.use_property_split = True
        layout.prop(settings, "source")
        if settings.source == "COLLECTION":
            layout.prop(settings, "collection")
        objects = lightmap_settings.objects(context, settings)
        layout.prop(settings, "layout")
        atlas = settings.layout == "ATLAS" and len(objects) > 1
        if settings.layout == "ATLAS":
            layout.prop(settings, "atlas_name")
        layout.prop(settings, "uv_name")
        missing = [o.name for o in objects if settings.uv_name not in o.data.uv_layers]
        if missing and atlas:
            layout.label(text=f"No '{settings.uv_name}' UV map (Lightmap Pack in the atlas): {', '.join(missing[:3])}"
                              f"{' ...' if len(missing) > 3 else ''}", icon="INFO")
        elif missing:
            layout.label(text=f"No '{settings.uv_name}' UV map: {', '.join(missing[:3])}"
                              f"{' ...' if len(missing) > 3 else ''}", icon="ERROR")
        layout.operator("hemishadow.make_lightmap_uv", icon="UV")
        shared = lightmaps.shared_meshes(context.scene, objects)
        if shared:
            layout.label(text=f"Shared meshes: {', '.join(shared)}", icon="ERROR")
            layout.operator("hemishadow.lightmap_single_user", icon="USER")
        layout.prop(settings, "size_mode")
        layout.prop(settings, "resolution" if settings.size_mode == "RESOLUTION" else "texel_density")
        layout.prop(settings, "basis")
        layout.prop(settings, "bounces")
        layout.prop(settings, "samples")
        layout.prop(settings, "adaptive")
        layout.prop(settings, "margin")
        layout.prop(settings, "directory")
        layout.label(text=f"{len(objects)} mesh object(s)", icon="OBJECT_DATA")
        layout.operator("hemishadow.bake_lightmaps", icon="RENDER_STILL")
        layout.operator("hemishadow.add_lightmap_nodes", icon="NODETREE")


classes = (HEMISHADOW_PT_lightmaps,)

register, unregister = bpy.utils.register_classes_factory(classes)
