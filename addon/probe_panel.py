"""UI: the "Probes" panel of the Hemishadow tab (issue 12): bake the active Light Probe
Volume (or Empty) and show its probes; objects take their light from it through their own
Probe Lighting (Object panel)."""

import bpy

from . import probes


class HEMISHADOW_PT_probes(bpy.types.Panel):
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Hemishadow"
    bl_label = "Probes"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        volume = probes.active_volume(context)
        if volume is None:
            layout.label(text="Select a Light Probe Volume or an Empty", icon="INFO")
            return
        data = probes.stored(volume)
        baked = f"{len(data['positions'])} probes baked" if data is not None else "not baked yet"
        layout.label(text=f"{volume.name}: {baked}", icon="LIGHTPROBE_VOLUME")
        layout.operator("hemishadow.bake_probes", icon="RENDER_STILL")
        if data is not None:
            layout.operator("hemishadow.probe_preview", icon="SHADING_SOLID")
            users = [o.name for o in context.scene.objects
                     if getattr(getattr(o, "hemishadow", None), "probe_volume", None) == volume]
            layout.label(text=f"Lights {', '.join(users)}" if users else "Lights no object yet (Object panel: "
                         "Probe Lighting)", icon="OBJECT_DATA")


classes = (HEMISHADOW_PT_probes,)

register, unregister = bpy.utils.register_classes_factory(classes)
