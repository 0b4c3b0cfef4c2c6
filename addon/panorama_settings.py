"""`Scene.hemishadow_panorama`: the Panorama panel's settings (issue 13): where the panorama is
baked from and how (Bake Panorama, panorama_bake.bake_panorama take the same values), and how
the baked file is relit live in the Image Editor (panorama_live)."""

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty, PointerProperty,
                       StringProperty)


def _relight(self, context):
    from . import panorama_live

    panorama_live.request(context.scene)


def _is_viewpoint(self, obj):
    return obj.type in ("CAMERA", "EMPTY")


class HemishadowPanoramaSettings(bpy.types.PropertyGroup):
    source: EnumProperty(name="From", default="CAMERA", items=[
        ("CAMERA", "Camera", "A camera or an Empty: its position and rotation"),
        ("POINT", "Point", "A point: centre column +X, left quarter +Y, top row +Z")])
    camera: PointerProperty(name="Camera", type=bpy.types.Object, poll=_is_viewpoint,
                            description="Camera or Empty to bake from (empty: the scene camera)")
    point: FloatVectorProperty(name="Point", size=3, subtype="TRANSLATION", default=(0.0, 0.0, 1.0))
    width: IntProperty(name="Width", default=1024, min=8, max=4096)
    height: IntProperty(name="Height", default=512, min=4, max=2048)
    coefficients: EnumProperty(name="Coefficients", default="16", items=[
        ("9", "9", "Bands 0-2"), ("16", "16", "Bands 0-3 (Wong et al.)"), ("25", "25", "Bands 0-4")])
    bounces: IntProperty(name="Bounces", default=0, min=0, max=16,
                         description="Bounce light under the scene's own lighting, stored apart (0: none)")
    filepath: StringProperty(name="File", default="//panoramas/panorama.exr", subtype="FILE_PATH",
                             description="FILE.exr; the compact 8-bit form goes to FILE/panorama.json")
    # live relight
    baked: StringProperty(name="Panorama", default="", subtype="FILE_PATH", update=_relight,
                          description="The panorama relit in the Image Editor (.exr or compact .json)")
    live: BoolProperty(name="Live Relight", default=False, update=_relight,
                       description="Relight the image whenever a lamp moves or the settings change")
    lights: EnumProperty(name="Light", default="LAMPS", update=_relight, items=[
        ("LAMPS", "Lamps", "The scene's visible Sun and Point lamps"),
        ("DIRECTION", "Direction", "One sun from the direction below")])
    direction: FloatVectorProperty(name="Direction", size=3, subtype="DIRECTION", default=(0.4, 0.3, 0.866),
                                   update=_relight, description="Towards the light")
    strength: FloatProperty(name="Strength", default=3.0, min=0.0, soft_max=20.0, update=_relight,
                            description="Irradiance of the sun, W/m^2 (Blender's sun strength)")
    use_world: BoolProperty(name="World", default=False, update=_relight,
                            description="Add the World's lighting (its SH) to the lamps")
    exposure: FloatProperty(name="Exposure", default=0.0, soft_min=-10.0, soft_max=10.0, update=_relight)


def bake_arguments(scene):
    """Keyword arguments of panorama_bake.bake_panorama / prepare (out apart)."""
    s = scene.hemishadow_panorama
    where = dict(at=tuple(s.point)) if s.source == "POINT" else dict(camera=s.camera.name if s.camera else None)
    return dict(where, size=(s.width, s.height), coefficients=int(s.coefficients), bounces=s.bounces)


def register():
    bpy.utils.register_class(HemishadowPanoramaSettings)
    bpy.types.Scene.hemishadow_panorama = PointerProperty(type=HemishadowPanoramaSettings)


def unregister():
    del bpy.types.Scene.hemishadow_panorama
    bpy.utils.unregister_class(HemishadowPanoramaSettings)
