"""Bake Lightmaps: the selected mesh objects' directional lightmaps (issue 11).

Thin: `addon.lightmaps.bake_lightmaps` does the work. Blocking for now, with Blender's
progress bar (no Esc: a modal driver with a worker thread is still to come); files are
written only after every map is baked, so a failure leaves nothing half-written.
"""

import bpy

from .. import lightmaps


class HEMISHADOW_OT_bake_lightmaps(bpy.types.Operator):
    """Bake directional lightmaps (flat, HL2 basis or L1 SH, AO) of the selected mesh objects"""

    bl_idname = "hemishadow.bake_lightmaps"
    bl_label = "Bake Lightmaps"
    bl_options = {"REGISTER"}

    uv_name: bpy.props.StringProperty(name="UV Map", default=lightmaps.DEFAULT_UV,
                                      description="UV map placing the texels (not changed)")
    resolution: bpy.props.IntProperty(name="Resolution", default=256, min=1, max=8192)
    basis: bpy.props.EnumProperty(name="Basis", default="hl2", items=[
        ("hl2", "HL2", "flat, b0, b1, b2 (Half-Life 2 basis) and ao"),
        ("sh", "L1 SH", "flat, sh0..sh3 (world-space L1 SH) and ao"),
        ("flat", "Flat", "flat and ao")])
    bounces: bpy.props.IntProperty(name="Bounces", default=2, min=0, max=16)
    samples: bpy.props.IntProperty(name="Samples", default=4, min=1, max=64, description="Supersamples per texel")
    margin: bpy.props.IntProperty(name="Margin", default=2, min=0, max=64, description="Padding in texels")
    directory: bpy.props.StringProperty(name="Folder", default="", subtype="DIR_PATH",
                                        description="Where <object>.exr goes (default //lightmaps beside the .blend)")

    @classmethod
    def poll(cls, context):
        return any(o.type == "MESH" for o in context.selected_objects)

    def execute(self, context):
        objects = [o for o in context.selected_objects if o.type == "MESH"]
        wm = context.window_manager
        wm.progress_begin(0, 1000)
        try:
            written = lightmaps.bake_lightmaps(
                context.scene, objects, uv_name=self.uv_name, resolution=self.resolution, basis=self.basis,
                bounces=self.bounces, samples=self.samples, margin=self.margin, out_dir=self.directory or None,
                progress=lambda f: wm.progress_update(int(1000 * f)))
        except (ValueError, OSError) as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        skipped = lightmaps.unsupported_lamps(context.scene)
        if skipped:
            self.report({"WARNING"}, f"lamps not baked yet (point, spot, area): {', '.join(skipped)}")
        where = sorted({p.rsplit('/', 1)[0] for p in written.values() if p}) or ["packed images"]
        self.report({"INFO"}, f"hemishadow: baked {len(written)} lightmap(s) to {', '.join(where)}")
        return {"FINISHED"}


class HEMISHADOW_OT_make_lightmap_uv(bpy.types.Operator):
    """Add a new UV map for lightmaps to the selected meshes (Lightmap Pack or Smart UV Project); existing UV maps are not touched"""

    bl_idname = "hemishadow.make_lightmap_uv"
    bl_label = "Make Lightmap UVs"
    bl_options = {"REGISTER", "UNDO"}

    uv_name: bpy.props.StringProperty(name="UV Map", default=lightmaps.DEFAULT_UV)
    method: bpy.props.EnumProperty(name="Method", default="LIGHTMAP", items=[
        ("LIGHTMAP", "Lightmap Pack", "one island per face, packed"),
        ("SMART", "Smart UV Project", "islands by angle")])

    @classmethod
    def poll(cls, context):
        return context.mode == "OBJECT" and any(o.type == "MESH" for o in context.selected_objects)

    def execute(self, context):
        made, kept = [], []
        for obj in [o for o in context.selected_objects if o.type == "MESH"]:
            if self.uv_name in obj.data.uv_layers:
                kept.append(obj.name)
                continue
            try:
                lightmaps.make_lightmap_uv(obj, self.uv_name, self.method)
            except ValueError as error:
                self.report({"ERROR"}, str(error))
                return {"CANCELLED"}
            made.append(obj.name)
        if kept:
            self.report({"INFO"}, f"already have {self.uv_name!r} (left as is): {', '.join(kept)}")
        self.report({"INFO"}, f"hemishadow: made {self.uv_name!r} for {len(made)} object(s)")
        return {"FINISHED"}


classes = (HEMISHADOW_OT_bake_lightmaps, HEMISHADOW_OT_make_lightmap_uv)
