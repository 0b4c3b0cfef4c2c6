"""Settings stored in the .blend: `Scene.hemishadow` and `Object.hemishadow`.

What `world.scene_lighting(scene, bands)` reads from `scene.hemishadow`
(a `HemishadowSceneSettings`):
- `lighting_source`: 'WORLD' (what the World emits, for any node setup: an Environment Texture
  and a plain colour directly, anything else through a small Cycles render; `hdri` only when
  the scene has no World), 'BUILTIN' (the HDRI named by `hdri`) or 'UNIFORM' (a uniform sky).
- `hdri`: name of one of the HDRIs that ship with Blender
  (`hemishadow.environment.builtin_hdris()` keys, e.g. 'forest').
- `uniform_color`: radiance of the uniform sky (RGB).
- `intensity`: scale of the lighting radiance (>= 0).
- `rotation`: rotation of the lighting about world +Z in radians, applied after the
  World's own Mapping rotation.
- `use_sun_lamps`: add the scene's sun lamps as soft SH lobes (point, spot and area lamps
  are always added, per vertex: lamps.py).
- `casters`: the default "Shadow casters" collection (casters.py) of objects without their own.
Changing any of these re-shades the objects from their last transfer vectors
(`engine_bridge.reshade_scene`), without recomputing transfer.

`scene.hemishadow.live` switches the frame-change and depsgraph handlers on.
"""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, PointerProperty, StringProperty


def _lighting_changed(self, context):
    from . import engine_bridge

    engine_bridge.reshade_scene(context.scene)


def _shading_changed(self, context):
    from . import engine_bridge

    engine_bridge.reshade_object(self.id_data, context.scene)


def _casters_changed(self, context):
    if context.scene.hemishadow.live:
        from . import engine_bridge

        engine_bridge.update_scene(context.scene, context.evaluated_depsgraph_get())


def _probe_changed(self, context):
    """The object's lighting source changed: shade it again (its transfer stays)."""
    if context.scene.hemishadow.live and self.id_data.hemishadow.enabled:
        from . import engine_bridge

        engine_bridge.update_scene(context.scene, context.evaluated_depsgraph_get(), [self.id_data], force=True)


def _live_changed(self, context):
    if self.live:
        from . import engine_bridge, handlers

        engine_bridge.update_scene(context.scene, context.evaluated_depsgraph_get())
        handlers.lighting_seen(context.scene)
    else:
        from . import jobs

        jobs.cancel()  # heavy objects computing in the background stop, keeping their (stale) result


# Enum items built by a callback must stay referenced, or Blender shows garbage names.
_hdri_items = []


def _hdri_enum(self, context):
    if not _hdri_items:
        try:
            from hemishadow.environment import builtin_hdris

            # Forest first: index 0 is a dynamic enum's default, and forest is the project's.
            names = sorted(builtin_hdris(), key=lambda n: (n != "forest", n))
        except (ImportError, OSError, ValueError):
            names = []
        _hdri_items.extend((n, n.title(), f"Blender's built-in '{n}' HDRI") for n in names or ["forest"])
    return _hdri_items


class HemishadowSceneSettings(bpy.types.PropertyGroup):
    live: BoolProperty(
        name="Live", default=False, update=_live_changed,
        description="Recompute self-shadowing of enabled objects on every frame change and deformation")
    lighting_source: EnumProperty(
        name="Lighting", default="WORLD", update=_lighting_changed,
        items=[("WORLD", "World", "What the World emits, any node setup (the built-in HDRI only without a World)"),
               ("BUILTIN", "Built-in HDRI", "One of the HDRIs that ship with Blender"),
               ("UNIFORM", "Uniform Sky", "Constant radiance 1 from every direction")])
    hdri: EnumProperty(name="HDRI", items=_hdri_enum, update=_lighting_changed,
                       description="Built-in HDRI, used by 'Built-in HDRI' and when the scene has no World")
    uniform_color: FloatVectorProperty(name="Sky Color", subtype="COLOR", size=3, default=(1.0, 1.0, 1.0), min=0.0,
                                       update=_lighting_changed, description="Radiance of the uniform sky")
    intensity: FloatProperty(name="Intensity", default=1.0, min=0.0, soft_max=10.0, update=_lighting_changed,
                             description="Scale of the lighting's radiance")
    rotation: FloatProperty(name="Rotation", default=0.0, subtype="ANGLE", unit="ROTATION", update=_lighting_changed,
                            description="Rotation of the lighting about the world Z axis")
    use_sun_lamps: BoolProperty(name="Sun Lamps", default=True, update=_lighting_changed,
                                description="Add the scene's sun lamps as soft lobes of their angular diameter")
    casters: PointerProperty(name="Shadow Casters", type=bpy.types.Collection, update=_casters_changed,
                             description="Objects that shadow every enabled object without casters of its own "
                                         "(empty: self-shadowing only)")


class HemishadowObjectSettings(bpy.types.PropertyGroup):
    enabled: BoolProperty(name="Enable", default=False,
                          description="Compute self-shadowing of this object (live, Compute and Bake)")
    brdf: EnumProperty(name="BRDF", default="DIFFUSE",
                       items=[("DIFFUSE", "Diffuse", "Lambertian transfer, view independent"),
                              ("PHONG", "Phong", "Normalised Phong lobe towards the active camera")])
    exponent: FloatProperty(name="Exponent", default=16.0, min=0.0, soft_max=128.0,
                            description="Phong exponent (sharper highlights when larger)")
    bands: EnumProperty(name="SH Coefficients", default="25",
                        items=[("9", "9", "3 bands: softest shadows, fastest"),
                               ("16", "16", "4 bands"),
                               ("25", "25", "5 bands: the paper's 4th order")])
    albedo: FloatVectorProperty(name="Albedo", subtype="COLOR", size=3, default=(0.8, 0.8, 0.8), min=0.0, max=1.0,
                                update=_shading_changed,
                                description="Diffuse reflectance in the radiance (use white when a material multiplies "
                                            "its own base color)")
    write_ao: BoolProperty(name="Ambient Occlusion", default=True,
                           description="Write the float point attribute hemishadow_ao")
    write_sh: BoolProperty(name="SH Transfer Layers", default=False,
                           description="Write the transfer coefficients as float point attributes hemishadow_sh_00, ...")
    casters: PointerProperty(name="Shadow Casters", type=bpy.types.Collection, update=_casters_changed,
                             description="Objects that shadow this one, besides itself (empty: the scene's "
                                         "Shadow Casters)")
    probe_volume: PointerProperty(name="Probe Lighting", type=bpy.types.Object, update=_probe_changed,
                                  poll=lambda self, obj: obj.type in {"LIGHT_PROBE", "EMPTY"},
                                  description="A volume with baked probes whose light, at this object's place, "
                                              "replaces the World and lamps for it (empty: the World)")
    probe_point: EnumProperty(name="Probe Point", default="CENTER", update=_probe_changed,
                              items=[("CENTER", "Bounds Centre", "The centre of the object's bounds"),
                                     ("ORIGIN", "Origin", "The object's origin")],
                              description="Where the object takes its light from the probe grid")
    status: StringProperty(name="Status", default="", description="Outcome of the last computation")

    @property
    def band_count(self):
        """SH bands l = 0..band_count-1 (3, 4 or 5), as the engine takes them."""
        return {"9": 3, "16": 4, "25": 5}[self.bands]


classes = (HemishadowSceneSettings, HemishadowObjectSettings)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.hemishadow = PointerProperty(type=HemishadowSceneSettings)
    bpy.types.Object.hemishadow = PointerProperty(type=HemishadowObjectSettings)


def unregister():
    del bpy.types.Object.hemishadow
    del bpy.types.Scene.hemishadow
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
