"""Operators of the live path: compute now, live on/off, clear outputs, one-click material.

Thin: each calls engine_bridge / mesh_io / material, catches the domain error once and
reports it."""

import bpy

from .. import engine_bridge, material, mesh_io
from .jobs import ComputeInBackground

_TARGETS = [("AUTO", "Auto", "Selected meshes when any are selected, else all enabled objects"),
            ("SELECTED", "Selected", "Selected mesh objects"),
            ("ENABLED", "Enabled", "All objects with hemishadow enabled")]


def target_objects(context, target):
    selected = [o for o in context.selected_objects if o.type == "MESH"]
    if target == "SELECTED" or (target == "AUTO" and selected):
        return selected
    return engine_bridge.enabled_objects(context.scene)


class HEMISHADOW_OT_compute(ComputeInBackground, bpy.types.Operator):
    """Compute self-shadowing now and write the hemishadow_ attributes"""

    bl_idname = "hemishadow.compute"
    bl_label = "Compute Now"
    bl_options = {"REGISTER", "UNDO"}

    target: bpy.props.EnumProperty(name="Objects", items=_TARGETS, default="AUTO")

    def execute(self, context):
        objects = target_objects(context, self.target)
        if not objects:
            self.report({"ERROR"}, "No mesh selected and no object has hemishadow enabled")
            return {"CANCELLED"}
        errors = engine_bridge.update_scene(context.scene, context.evaluated_depsgraph_get(), objects, force=True)
        if len(errors) == len(objects):
            self.report({"ERROR"}, "; ".join(errors.values()))
            return {"CANCELLED"}
        if errors:
            self.report({"WARNING"}, "; ".join(errors.values()))
        from .. import lighting

        for message in lighting.report(context.scene):  # fallbacks, lamps not represented
            self.report({"WARNING"}, message)
        return {"FINISHED"}


class HEMISHADOW_OT_live_toggle(bpy.types.Operator):
    """Switch live self-shadowing on or off (frame changes and deformations recompute)"""

    bl_idname = "hemishadow.live_toggle"
    bl_label = "Toggle Live"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        settings = context.scene.hemishadow
        settings.live = not settings.live  # its update callback computes at once when switched on
        return {"FINISHED"}


class HEMISHADOW_OT_clear(bpy.types.Operator):
    """Remove the hemishadow_ attributes (and only those) from the objects' meshes"""

    bl_idname = "hemishadow.clear"
    bl_label = "Clear Outputs"
    bl_options = {"REGISTER", "UNDO"}

    target: bpy.props.EnumProperty(name="Objects", items=_TARGETS, default="AUTO")

    def execute(self, context):
        objects = [o for o in target_objects(context, self.target) if o.mode != "EDIT"]
        removed = 0
        for obj in objects:
            removed += mesh_io.clear_outputs(obj)
            engine_bridge.forget(obj)  # the next computation must write again
            engine_bridge.set_status(obj, "")
        self.report({"INFO"}, f"Removed {removed} attributes from {len(objects)} objects")
        return {"FINISHED"}


class HEMISHADOW_OT_add_material(bpy.types.Operator):
    """Show the result in Material Preview and Rendered mode (EEVEE and Cycles)"""

    bl_idname = "hemishadow.add_material"
    bl_label = "Add Material"
    bl_options = {"REGISTER", "UNDO"}

    mode: bpy.props.EnumProperty(
        name="Mode", default="EMIT",
        items=[("EMIT", "Emit Radiance", "Replace the materials with one that emits hemishadow_radiance"),
               ("MULTIPLY", "Multiply Base Color", "Keep each material's base color (textures too) and emit it "
                                                   "multiplied by hemishadow_radiance; set Albedo to white")])

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "MESH"

    def execute(self, context):
        obj = context.active_object
        if self.mode == "EMIT":
            material.assign_emission(obj)
        else:
            material.assign_multiply(obj)
        return {"FINISHED"}


classes = (HEMISHADOW_OT_compute, HEMISHADOW_OT_live_toggle, HEMISHADOW_OT_clear, HEMISHADOW_OT_add_material)
