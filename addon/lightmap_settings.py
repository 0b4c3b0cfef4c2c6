"""`Scene.hemishadow_lightmaps`: the Lightmaps panel's settings (issue 11), which objects and
how; the Bake Lightmaps operator and `lightmaps.bake_lightmaps` take the same values."""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from . import lightmap_atlas, lightmaps


class HemishadowLightmapSettings(bpy.types.PropertyGroup):
    source: EnumProperty(name="Objects", default="SELECTED", items=[
        ("SELECTED", "Selected", "The selected mesh objects"),
        ("COLLECTION", "Collection", "The mesh objects of a collection")])
    collection: PointerProperty(name="Collection", type=bpy.types.Collection,
                                description="Collection whose mesh objects are baked")
    uv_name: StringProperty(name="UV Map", default=lightmaps.DEFAULT_UV,
                            description="UV map placing the texels (never changed by the bake); in an atlas, "
                                        "the islands packed into hemishadow_lightmap (Lightmap Pack without it)")
    layout: EnumProperty(name="Layout", default="ATLAS", items=[
        ("ATLAS", "Atlas", "Several objects share one image: the bake packs their islands into its own UV map "
                           "hemishadow_lightmap (one object: its UV map as it is)"),
        ("OBJECT", "Per Object", "One image per object, through its UV map as it is")])
    atlas_name: StringProperty(name="Atlas Name", default=lightmap_atlas.DEFAULT_ATLAS,
                               description="The atlas's file <name>.exr and images hemishadow_<name>_<map>")
    size_mode: EnumProperty(name="Size", default="RESOLUTION", items=[
        ("RESOLUTION", "Resolution", "The same number of texels per side for every object"),
        ("DENSITY", "Texel Density", "Texels per metre of surface: each object's size from its area")])
    resolution: IntProperty(name="Resolution", default=256, min=1, max=8192, description="Texels per side")
    texel_density: FloatProperty(name="Texels per Metre", default=32.0, min=0.01, soft_max=512.0,
                                 description="Resolution = density x sqrt(surface area / UV area), a multiple of 4 "
                                             "in [4, 4096]")
    basis: EnumProperty(name="Basis", default="hl2", items=[
        ("hl2", "HL2", "flat, b0, b1, b2 (Half-Life 2 basis) and ao"),
        ("sh", "L1 SH", "flat, sh0..sh3 (world-space L1 SH) and ao"),
        ("flat", "Flat", "flat and ao")])
    bounces: IntProperty(name="Bounces", default=2, min=0, max=16, description="Diffuse bounces (0: direct only)")
    samples: IntProperty(name="Samples", default=4, min=1, max=64, description="Supersamples per texel, in total")
    adaptive: BoolProperty(name="Adaptive Samples", default=True,
                           description="All samples only where a texel's light departs from its neighbours' "
                                       "(shadow and contact edges, island rims); elsewhere one sample at its centre")
    margin: IntProperty(name="Margin", default=2, min=0, max=64, description="Padding around islands, in texels")
    directory: StringProperty(name="Folder", default="", subtype="DIR_PATH",
                              description="Where <object>.exr goes (empty: //lightmaps beside the .blend; "
                                          "packed images when the file was never saved)")


def objects(context, settings):
    """The mesh objects the settings name (selection or collection)."""
    if settings.source == "COLLECTION":
        if settings.collection is None:
            return []
        return [o for o in settings.collection.all_objects if o.type == "MESH"]
    return [o for o in context.selected_objects if o.type == "MESH"]


def bake_arguments(settings):
    """Keyword arguments of lightmaps.prepare / bake_lightmaps (out_dir apart)."""
    density = settings.size_mode == "DENSITY"
    return dict(uv_name=settings.uv_name, resolution=settings.resolution,
                texel_density=settings.texel_density if density else None, basis=settings.basis,
                bounces=settings.bounces, samples=settings.samples, adaptive=settings.adaptive, margin=settings.margin,
                layout=settings.layout,
                atlas_name=settings.atlas_name)


def register():
    bpy.utils.register_class(HemishadowLightmapSettings)
    bpy.types.Scene.hemishadow_lightmaps = PointerProperty(type=HemishadowLightmapSettings)


def unregister():
    del bpy.types.Scene.hemishadow_lightmaps
    bpy.utils.unregister_class(HemishadowLightmapSettings)
