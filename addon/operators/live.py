"""Operators of the live path: compute now, live on/off, clear outputs, one-click material.

Thin: each calls engine_bridge / mesh_io / material, catches the domain error once and
reports it."""

import bpy

from .. import engine_bridge, material, mesh_io
from .. import objects as scope
from .jobs import ComputeInBackground

_TARGETS = [("AUTO", "Auto", "Selected meshes when any are selected, else all enabled objects"),
            ("SELECTED", "Selected", "Selected mesh objects"),
            ("ENABLED", "Enabled", "All objects with hemishadow enabled")]


def _selected(context):
    # Curves, text and the like too, so that the report says why they are not computed.
    return [o for o in context.selected_objects if o.type == "MESH" or o.type in mesh_io.NOT_A_MESH]


def asks_all(context, target):
    """True when the target is every enabled object rather than the selected ones."""
    return target == "ENABLED" or (target == "AUTO" and not _selected(context))


def target_objects(context, target):
    """The objects asked for (the selected ones, or every enabled object of the scene) as they
    are computed: one per shared mesh, its owner (objects.py), and those that are not meshes,
    which update_scene refuses with a message."""
    scene = context.scene
    asked = [o for o in scene.objects if o.hemishadow.enabled] if asks_all(context, target) else _selected(context)
    return scope.owners(scene, asked)[0] + [o for o in asked if o.type != "MESH"]


class HEMISHADOW_OT_compute(ComputeInBackground, bpy.types.Operator):
    """Compute self-shadowing now and write the hemishadow_ attributes"""

    bl_idname = "hemishadow.compute"
    bl_label = "Compute Now"
    bl_options = {"REGISTER", "UNDO"}

    target: bpy.props.EnumProperty(name="Objects", items=_TARGETS, default="AUTO")

    def execute(self, context):
        objects = None if asks_all(context, self.target) else target_objects(context, self.target)
        computed, errors, warnings = engine_bridge.compute_now(context.scene, context.evaluated_depsgraph_get(),
                                                               objects)
        if not computed:
            messages = list(errors.values()) + warnings
            self.report({"ERROR"}, "; ".join(messages) or "No mesh selected and no object has hemishadow enabled")
            return {"CANCELLED"}
        if errors or warnings:
            self.report({"WARNING"}, "; ".join(list(errors.values()) + warnings))
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
        objects = [o for o in target_objects(context, self.target) if o.type == "MESH" and o.mode != "EDIT"]
        removed = 0
        for obj in objects:
            removed += mesh_io.clear_outputs(obj)
            engine_bridge.forget(obj)  # the next computation must write again
            engine_bridge.set_status(obj, "")
        self.report({"INFO"}, f"Removed {removed} attributes from {len(objects)} objects")
        return {"FINISHED"}


class HEMISHADOW_OT_make_single_user(bpy.types.Operator):
    """Give the enabled objects sharing this mesh meshes of their own (copies), so that each is
    computed in its own pose and orientation"""

    bl_idname = "hemishadow.make_single_user"
    bl_label = "Make Single User"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        obj = context.object
        return obj is not None and obj.type == "MESH" and bool(scope.shared_users(context.scene, [obj]))

    def execute(self, context):
        obj = context.object
        users = scope.shared_users(context.scene, [obj]).get(obj.data.session_uid, [])
        changed = scope.make_single_user(context.scene, obj)
        if not changed:
            self.report({"INFO"}, f"No enabled object shares the mesh of '{context.object.name}' with it")
            return {"CANCELLED"}
        enabled = [o for o in users if o.hemishadow.enabled]  # the copies, and the statuses of the rest
        errors = engine_bridge.update_scene(context.scene, context.evaluated_depsgraph_get(), enabled, force=True)
        if errors:
            self.report({"WARNING"}, "; ".join(errors.values()))
        names = ", ".join(f"'{o.name}'" for o in changed)
        self.report({"INFO"}, f"Gave {names} meshes of their own")
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


classes = (HEMISHADOW_OT_compute, HEMISHADOW_OT_live_toggle, HEMISHADOW_OT_clear, HEMISHADOW_OT_make_single_user,
           HEMISHADOW_OT_add_material)
