"""UI: the "Hemishadow" tab of the 3D viewport sidebar and a panel in Object properties."""

import bpy

from . import cache, engine_bridge, jobs, mesh_io
from . import objects as scope

# Objects the panels show: meshes, and the kinds hemishadow refuses (to say so).
_SHOWN = {"MESH"} | set(mesh_io.NOT_A_MESH)


class _Sidebar:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Hemishadow"


def draw_object_settings(layout, obj, scene):
    settings = obj.hemishadow
    if obj.type != "MESH":
        _draw_refused(layout, obj)
        return
    layout.prop(settings, "enabled")
    column = layout.column()
    column.active = settings.enabled
    column.prop(settings, "brdf")
    if settings.brdf == "PHONG":
        column.prop(settings, "exponent")
    column.prop(settings, "bands")
    column.prop(settings, "albedo")
    column.prop(settings, "casters")
    column.prop(settings, "probe_volume")
    if settings.probe_volume is not None:
        column.prop(settings, "probe_point")
    outputs = column.column(heading="Outputs", align=True)
    outputs.label(text="Radiance: hemishadow_radiance", icon="COLOR")
    ao = outputs.row()
    ao.active = settings.brdf != "PHONG"
    ao.prop(settings, "write_ao")
    if settings.brdf == "PHONG":
        outputs.label(text="Phong: no AO (a diffuse quantity)", icon="INFO")
    outputs.prop(settings, "write_sh")
    if scope.shared_users(scene, [obj]):
        layout.operator("hemishadow.make_single_user", icon="USER")
    if settings.status:
        column.label(text=settings.status, icon="INFO")
    cache.draw_status(column, obj)
    if jobs.pending([obj]):
        column.operator("hemishadow.cancel_jobs", icon="CANCEL")
    timing = engine_bridge.last_timings.get(obj.name)
    if timing:
        column.label(text=f"{timing[0]} vertices: engine {timing[2] * 1e3:.0f} ms, Blender I/O {timing[1] * 1e3:.0f} ms")


def _draw_refused(layout, obj):
    kind = mesh_io.NOT_A_MESH[obj.type]
    layout.label(text=f"A {kind} object is not computed: convert it to a mesh", icon="ERROR")
    if obj.hemishadow.enabled:  # enabled while it was a mesh, or from Python: let it be switched off
        layout.prop(obj.hemishadow, "enabled")


class HEMISHADOW_PT_lighting(_Sidebar, bpy.types.Panel):
    bl_label = "Lighting"

    def draw(self, context):
        settings = context.scene.hemishadow
        layout = self.layout
        layout.use_property_split = True
        layout.prop(settings, "lighting_source")
        if settings.lighting_source != "UNIFORM":
            layout.prop(settings, "hdri")
        else:
            layout.prop(settings, "uniform_color")
        layout.prop(settings, "intensity")
        layout.prop(settings, "rotation")
        layout.prop(settings, "use_sun_lamps")
        layout.prop(settings, "casters")
        from . import world

        layout.label(text=world.lighting_source(context.scene).label, icon="WORLD")
        for message in world.notes(context.scene):
            layout.label(text=message, icon="ERROR")
        layout.operator("hemishadow.precompute_world", icon="WORLD")


class HEMISHADOW_PT_object(_Sidebar, bpy.types.Panel):
    bl_label = "Object"

    @classmethod
    def poll(cls, context):
        return context.active_object is not None and context.active_object.type in _SHOWN

    def draw(self, context):
        self.layout.use_property_split = True
        draw_object_settings(self.layout, context.active_object, context.scene)


class HEMISHADOW_PT_actions(_Sidebar, bpy.types.Panel):
    bl_label = "Actions"

    def draw(self, context):
        layout = self.layout
        live = context.scene.hemishadow.live
        layout.operator("hemishadow.live_toggle", text="Live: On" if live else "Live: Off",
                        icon="PAUSE" if live else "PLAY", depress=live)
        layout.operator("hemishadow.compute", icon="SHADING_RENDERED")
        row = layout.row(align=True)
        row.operator("hemishadow.add_material", text="Emit Material").mode = "EMIT"
        row.operator("hemishadow.add_material", text="Multiply Material").mode = "MULTIPLY"
        layout.operator("hemishadow.bake_animation", icon="RENDER_ANIMATION")
        row = layout.row(align=True)
        row.operator("hemishadow.clear", icon="TRASH")
        row.operator("hemishadow.clear_bake")


class HEMISHADOW_PT_object_properties(bpy.types.Panel):
    bl_label = "Hemishadow"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "object"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.type in _SHOWN

    def draw(self, context):
        self.layout.use_property_split = True
        draw_object_settings(self.layout, context.object, context.scene)


classes = (HEMISHADOW_PT_lighting, HEMISHADOW_PT_object, HEMISHADOW_PT_actions, HEMISHADOW_PT_object_properties)

register, unregister = bpy.utils.register_classes_factory(classes)
