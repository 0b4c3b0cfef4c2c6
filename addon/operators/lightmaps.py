"""Lightmap operators (issue 11): Bake Lightmaps (modal, with progress and Esc), Make
Lightmap UVs, Add to Materials, Make Single User (Lightmaps).

Thin: lightmaps.py, lightmap_job.py and lightmap_nodes.py do the work. The settings are the
scene's (`Scene.hemishadow_lightmaps`, the Lightmaps panel); an operator property set by a
caller (a script, a test) overrides its setting.
"""

import bpy

from .. import lightmap_atlas, lightmap_job, lightmap_nodes, lightmap_settings, lightmaps
from .modal_job import ModalJob

_OVERRIDABLE = ("uv_name", "resolution", "basis", "bounces", "samples", "adaptive", "margin", "layout", "atlas_name")


def _report_warnings(operator, messages):
    for message in messages:
        operator.report({"WARNING"}, message)


def _arguments(operator, context):
    settings = context.scene.hemishadow_lightmaps
    kwargs = lightmap_settings.bake_arguments(settings)
    for name in _OVERRIDABLE:
        if operator.properties.is_property_set(name):
            kwargs[name] = getattr(operator, name)
            if name == "resolution":
                kwargs["texel_density"] = None
    if operator.properties.is_property_set("texel_density"):
        kwargs["texel_density"] = operator.texel_density
    directory = operator.directory if operator.properties.is_property_set("directory") else settings.directory
    return lightmap_settings.objects(context, settings), kwargs, directory or None


def _summary(written):
    where = sorted({p.rsplit("/", 1)[0] for p in written.values() if p}) or ["packed images"]
    return f"hemishadow: baked {len(written)} lightmap(s) to {', '.join(where)}"


class HEMISHADOW_OT_bake_lightmaps(ModalJob, bpy.types.Operator):
    """Bake directional lightmaps (flat, HL2 basis or L1 SH, AO) of the chosen mesh objects (Esc cancels, writing nothing)"""

    bl_idname = "hemishadow.bake_lightmaps"
    bl_label = "Bake Lightmaps"
    bl_options = {"REGISTER"}

    uv_name: bpy.props.StringProperty(name="UV Map", default=lightmaps.DEFAULT_UV,
                                      description="UV map placing the texels (not changed)")
    resolution: bpy.props.IntProperty(name="Resolution", default=256, min=1, max=8192)
    texel_density: bpy.props.FloatProperty(name="Texels per Metre", default=32.0, min=0.01)
    basis: bpy.props.EnumProperty(name="Basis", default="hl2", items=[
        ("hl2", "HL2", "flat, b0, b1, b2 (Half-Life 2 basis) and ao"),
        ("sh", "L1 SH", "flat, sh0..sh3 (world-space L1 SH) and ao"),
        ("flat", "Flat", "flat and ao")])
    bounces: bpy.props.IntProperty(name="Bounces", default=2, min=0, max=16)
    samples: bpy.props.IntProperty(name="Samples", default=4, min=1, max=64, description="Supersamples per texel")
    adaptive: bpy.props.BoolProperty(name="Adaptive Samples", default=True,
                                     description="All samples only where a texel's light departs from its "
                                                 "neighbours' (shadow and contact edges, island rims); elsewhere "
                                                 "one sample at its centre")
    margin: bpy.props.IntProperty(name="Margin", default=2, min=0, max=64, description="Padding in texels")
    layout: bpy.props.EnumProperty(name="Layout", default="ATLAS", items=[
        ("ATLAS", "Atlas", "Several objects share one image through the UV map hemishadow_lightmap"),
        ("OBJECT", "Per Object", "One image per object through its UV map as it is")])
    atlas_name: bpy.props.StringProperty(name="Atlas Name", default=lightmap_atlas.DEFAULT_ATLAS)
    directory: bpy.props.StringProperty(name="Folder", default="", subtype="DIR_PATH",
                                        description="Where <object>.exr goes (default //lightmaps beside the .blend)")

    noun = "lightmap"

    @classmethod
    def poll(cls, context):
        settings = getattr(context.scene, "hemishadow_lightmaps", None)
        return settings is not None and bool(lightmap_settings.objects(context, settings))

    def execute(self, context):
        """The blocking path (background mode, scripts, redo): the plain function."""
        objects, kwargs, directory = _arguments(self, context)
        wm = context.window_manager
        wm.progress_begin(0, 1000)
        try:
            import warnings

            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                written = lightmaps.bake_lightmaps(context.scene, objects, out_dir=directory,
                                                   progress=lambda f: wm.progress_update(int(1000 * f)), **kwargs)
        except (ValueError, OSError) as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        _report_warnings(self, [str(w.message) for w in caught])
        return self.finished(context, written)

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        objects, kwargs, directory = _arguments(self, context)
        try:
            job = lightmap_job.LightmapBake(context.scene, objects, out_dir=directory, **kwargs)
        except (ValueError, OSError) as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        return self.start_modal(context, job)

    def status(self, job):
        return f"Baking lightmaps of {len(job.names)} object(s): {100 * job.fraction:.0f} % (Esc cancels)"

    def finished(self, context, written):
        skipped = lightmaps.unsupported_lamps(context.scene)
        if skipped:
            self.report({"WARNING"}, f"lamps not baked yet (point, spot, area): {', '.join(skipped)}")
        self.report({"INFO"}, _summary(written))
        return {"FINISHED"}


class HEMISHADOW_OT_make_lightmap_uv(bpy.types.Operator):
    """Add a new UV map for lightmaps to the chosen meshes (Lightmap Pack or Smart UV Project); existing UV maps are not touched"""

    bl_idname = "hemishadow.make_lightmap_uv"
    bl_label = "Make Lightmap UVs"
    bl_options = {"REGISTER", "UNDO"}

    uv_name: bpy.props.StringProperty(name="UV Map", default=lightmaps.DEFAULT_UV)
    method: bpy.props.EnumProperty(name="Method", default="LIGHTMAP", items=[
        ("LIGHTMAP", "Lightmap Pack", "one island per face, packed"),
        ("SMART", "Smart UV Project", "islands by angle")])

    @classmethod
    def poll(cls, context):
        return context.mode == "OBJECT" and bool(_chosen(context))

    def invoke(self, context, event):
        if not self.properties.is_property_set("uv_name"):
            self.uv_name = context.scene.hemishadow_lightmaps.uv_name
        return self.execute(context)

    def execute(self, context):
        made, kept = [], []
        for obj in _chosen(context):
            if self.uv_name in obj.data.uv_layers:
                kept.append(obj.name)
                continue
            try:
                lightmaps.make_lightmap_uv(obj, self.uv_name, self.method)
            except ValueError as error:
                self.report({"ERROR"}, str(error))
                return {"CANCELLED"}
            made.append(obj.name)
        shared = lightmaps.shared_meshes(context.scene, _chosen(context))
        for name, others in shared.items():
            self.report({"WARNING"}, f"{name}: its mesh is shared with {', '.join(o.name for o in others)}, "
                                     "which got the same UV map")
        if kept:
            self.report({"INFO"}, f"already have {self.uv_name!r} (left as is): {', '.join(kept)}")
        self.report({"INFO"}, f"hemishadow: made {self.uv_name!r} for {len(made)} object(s)")
        return {"FINISHED"}


def _chosen(context):
    settings = getattr(context.scene, "hemishadow_lightmaps", None)
    if settings is None:
        return [o for o in context.selected_objects if o.type == "MESH"]
    return lightmap_settings.objects(context, settings)


class HEMISHADOW_OT_add_lightmap_nodes(bpy.types.Operator):
    """Add the baked lightmaps ("Hemishadow Lightmap" node group, times Base Color, as Emission into a new active Material Output) to the baked objects' materials; nothing is removed"""

    bl_idname = "hemishadow.add_lightmap_nodes"
    bl_label = "Add to Materials"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return bool(_chosen(context))

    def execute(self, context):
        objects = _chosen(context)
        uv_name = context.scene.hemishadow_lightmaps.uv_name
        try:
            added, warnings = lightmap_nodes.add_to_objects(context.scene, objects, uv_name)
        except ValueError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        _report_warnings(self, warnings)
        self.report({"INFO"}, f"hemishadow: lightmaps added to {len(added)} material(s)")
        return {"FINISHED"}


class HEMISHADOW_OT_lightmap_single_user(bpy.types.Operator):
    """Give each object to bake whose mesh other objects share a copy of the mesh, so that it can have lightmap UVs of its own"""

    bl_idname = "hemishadow.lightmap_single_user"
    bl_label = "Make Single User (Lightmaps)"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return bool(lightmaps.shared_meshes(context.scene, _chosen(context)))

    def execute(self, context):
        changed = lightmaps.make_single_user(context.scene, _chosen(context))
        self.report({"INFO"}, f"hemishadow: gave {', '.join(o.name for o in changed) or 'no object'} "
                              "a mesh of its own")
        return {"FINISHED"}


classes = (HEMISHADOW_OT_bake_lightmaps, HEMISHADOW_OT_make_lightmap_uv, HEMISHADOW_OT_add_lightmap_nodes,
           HEMISHADOW_OT_lightmap_single_user)
