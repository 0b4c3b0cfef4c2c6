"""Lightmap baking, the Blender side (issue 11): objects, UVs, tangents, World and suns in;
Blender images and one multi-layer EXR per object out. The numerical work is
`hemishadow.lightmap.bake` (docs/lightmaps.md); this module only reads and writes Blender data.

`bake_lightmaps(scene, objects, ...)` is the plain function the operator (and scripts, and a
farm through `--python`) call. Nothing in the user's meshes changes: the lightmap UV map must
exist (by default the one named `lightmap`); the evaluated meshes (modifiers applied) are what
is baked. Blockers are all visible, renderable meshes of the view layer.
"""

from __future__ import annotations

import dataclasses
import os
import re
import types

import bpy
import numpy as np

from . import lamps, world

DEFAULT_UV = "lightmap"
IMAGE_PREFIX = "hemishadow_"


@dataclasses.dataclass
class MeshData:
    """An evaluated mesh read into numpy: local positions, triangles, per-corner data."""
    vertices: np.ndarray
    triangles: np.ndarray
    corner_normals: np.ndarray
    uv: np.ndarray | None
    tangents: np.ndarray | None


def make_lightmap_uv(obj, name=DEFAULT_UV, method="LIGHTMAP", margin=0.05):
    """Adds a NEW UV map `name` to the object's mesh, unwrapped by Lightmap Pack ('LIGHTMAP')
    or Smart UV Project ('SMART'); the only change made to the mesh: existing UV maps, and
    which one is active and which renders, stay as they were. Returns the new layer's name.
    Raises ValueError when `name` exists already (it is never overwritten)."""
    if obj.type != "MESH":
        raise ValueError(f"{obj.name}: only mesh objects can have lightmap UVs")
    mesh = obj.data
    if name in mesh.uv_layers:
        raise ValueError(f"{obj.name}: a UV map named {name!r} exists already; it is left as it is")
    if not len(mesh.polygons):
        raise ValueError(f"{obj.name}: the mesh has no faces")
    active = mesh.uv_layers.active.name if mesh.uv_layers.active else None
    render = next((u.name for u in mesh.uv_layers if u.active_render), None)
    mesh.uv_layers.active = mesh.uv_layers.new(name=name, do_init=False)
    view_layer = bpy.context.view_layer
    previous_active, previous_mode = view_layer.objects.active, obj.mode
    selected = [o for o in view_layer.objects if o.select_get()]
    try:
        for o in selected:
            o.select_set(False)
        obj.select_set(True)
        view_layer.objects.active = obj
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_all(action="SELECT")
        if method == "SMART":
            bpy.ops.uv.smart_project(island_margin=margin)
        else:
            bpy.ops.uv.lightmap_pack(PREF_CONTEXT="ALL_FACES", PREF_MARGIN_DIV=margin)
        bpy.ops.object.mode_set(mode=previous_mode if previous_mode != "EDIT" else "OBJECT")
    finally:
        obj.select_set(False)
        for o in selected:
            o.select_set(True)
        view_layer.objects.active = previous_active
    if active is not None:
        mesh.uv_layers.active = mesh.uv_layers[active]
    if render is not None:
        mesh.uv_layers[render].active_render = True
    return name  # (`layer` dangles after Edit Mode: Blender reallocates the layers)


def blockers(scene, view_layer=None):
    """Visible, renderable mesh objects of the view layer."""
    layer = view_layer or scene.view_layers[0]
    out = []
    for obj in scene.objects:
        if obj.type != "MESH" or obj.hide_render:
            continue
        try:
            visible = obj.visible_get(view_layer=layer)
        except (RuntimeError, TypeError):
            visible = not obj.hide_viewport
        if visible:
            out.append(obj)
    return out


def _loop_vectors(collection, size, count, attr="vector"):
    out = np.empty(count * size, np.float32)
    collection.foreach_get(attr, out)
    return out.reshape(count, size)


def read_mesh(obj, depsgraph, uv_name=None):
    """The evaluated mesh of `obj` (local space) with its lightmap UVs and tangents per corner.

    Tangents are Blender's MikkTSpace tangents of the active render UV map (the one normal
    maps use); None when the mesh cannot have them (no UV map, n-gons), and the engine falls
    back to per-triangle tangents. Raises ValueError naming the object when `uv_name` is
    asked for and missing."""
    obj_eval = obj.evaluated_get(depsgraph)
    mesh = obj_eval.to_mesh()
    try:
        mesh.calc_loop_triangles()
        tris = mesh.loop_triangles
        m = len(tris)
        vertices = _loop_vectors(mesh.vertices, 3, len(mesh.vertices), "co")
        triangles = np.empty(m * 3, np.int32)
        tris.foreach_get("vertices", triangles)
        loops = np.empty(m * 3, np.int32)
        tris.foreach_get("loops", loops)
        loops = loops.reshape(m, 3)
        normals = _loop_vectors(mesh.corner_normals, 3, len(mesh.loops))[loops]
        uv = None
        if uv_name is not None:
            layer = mesh.uv_layers.get(uv_name)
            if layer is None:
                names = [u.name for u in mesh.uv_layers] or ["none"]
                raise ValueError(f"{obj.name}: no UV map named {uv_name!r} (it has: {', '.join(names)}); "
                                 "add one (UV > Lightmap Pack into a new UV map) or choose another")
            uv = _loop_vectors(layer.uv, 2, len(mesh.loops))[loops]
        tangents = _tangents(mesh, loops)
        return MeshData(vertices, triangles.reshape(m, 3), normals, uv, tangents)
    finally:
        obj_eval.to_mesh_clear()


def _tangents(mesh, loops):
    render = next((u for u in mesh.uv_layers if u.active_render), None)
    if render is None:
        return None
    try:
        mesh.calc_tangents(uvmap=render.name)
    except RuntimeError:  # n-gons: MikkTSpace needs triangles and quads
        return None
    count = len(mesh.loops)
    t = _loop_vectors(mesh.loops, 3, count, "tangent")
    sign = np.empty(count, np.float32)
    mesh.loops.foreach_get("bitangent_sign", sign)
    return np.concatenate([t, sign[:, None]], axis=1)[loops]


def _principled(obj):
    """The first Principled BSDF of the object's first material, or None."""
    for slot in obj.material_slots:
        mat = slot.material
        if mat is not None and mat.use_nodes and mat.node_tree is not None:
            for node in mat.node_tree.nodes:
                if node.type == "BSDF_PRINCIPLED":
                    return node
    return None


def albedo_and_emission(obj):
    """Diffuse albedo (3,) and emitted radiance (3,) from the Principled BSDF's input values
    (0.8 grey and no emission without one). Textures feeding them are not sampled yet."""
    node = _principled(obj)
    if node is None:
        return np.full(3, 0.8), np.zeros(3)
    albedo = np.array(node.inputs["Base Color"].default_value[:3], np.float64)
    emission = np.zeros(3)
    color = node.inputs.get("Emission Color") or node.inputs.get("Emission")
    strength = node.inputs.get("Emission Strength")
    if color is not None:
        emission = np.array(color.default_value[:3], np.float64) * (strength.default_value if strength else 1.0)
    return albedo, emission


def lighting_of(scene, bands=5):
    """The World's SH as Cycles sees it (no live-path intensity or rotation), suns apart."""
    settings = types.SimpleNamespace(**dict(world.DEFAULTS, lighting_source="WORLD", use_sun_lamps=False))
    return world.scene_lighting(scene, bands, settings)


def suns_of(scene):
    import hemishadow.lightmap as lm

    out = []
    for obj in lamps.visible_lamps(scene, ("SUN",)):
        direction = np.array(obj.matrix_world.to_3x3().col[2], np.float64)
        if np.linalg.norm(direction) > 0:
            out.append(lm.Sun(direction, lamps.lamp_power_color(obj.data), float(obj.data.angle)))
    return out


def lamps_of(scene):
    """Point, spot and area lamps as the engine's lamps (size scaled by the object's scale)."""
    import hemishadow.lightmap as lm

    out = []
    for obj in lamps.visible_lamps(scene, ("POINT", "SPOT", "AREA")):
        m, light = obj.matrix_world, obj.data
        pos, power = np.array(m.translation, np.float64), lamps.lamp_power_color(light)
        axis = [np.array(m.to_3x3().col[k], np.float64) for k in range(3)]
        if light.type == "POINT":
            out.append(lm.Point(pos, power, float(light.shadow_soft_size)))
        elif light.type == "SPOT":
            out.append(lm.Spot(pos, -axis[2], power, float(light.shadow_soft_size), float(light.spot_size),
                               float(light.spot_blend)))
        else:
            sx, sy = np.linalg.norm(axis[0]), np.linalg.norm(axis[1])
            y = light.size_y if light.shape in ("RECTANGLE", "ELLIPSE") else light.size
            shape = "ELLIPSE" if light.shape in ("DISK", "ELLIPSE") else "RECTANGLE"  # scale may stretch it
            out.append(lm.Area(pos, -axis[2], axis[0], power, shape, float(light.size) * sx, float(y) * sy))
    return out


def unsupported_lamps(scene):
    """Names of lamps the bake leaves out: none since point, spot and area lamps are baked."""
    return []


def _safe(name):
    return re.sub(r"[^\w.-]+", "_", name)


def output_folder(out_dir=None):
    """`out_dir`, or `//lightmaps` beside a saved .blend; None when neither (images are packed)."""
    if out_dir:
        return bpy.path.abspath(out_dir)
    if bpy.data.filepath:
        return bpy.path.abspath("//lightmaps")
    return None


def store_image(name, rgb):
    """A float Blender image `name` holding an (R, R, 3) or (R, R) map (rows top to bottom)."""
    data = np.asarray(rgb, np.float32)
    if data.ndim == 2:
        data = np.repeat(data[..., None], 3, axis=2)
    h, w = data.shape[:2]
    image = bpy.data.images.get(name)
    if image is None or tuple(image.size) != (w, h) or not image.is_float:
        if image is not None:
            bpy.data.images.remove(image)
        image = bpy.data.images.new(name, w, h, alpha=False, float_buffer=True)
        image.colorspace_settings.name = "Non-Color"  # before the pixels: it reloads a generated image
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = data[::-1]  # Blender's pixel rows start at the bottom
    image.pixels.foreach_set(rgba.ravel())
    image.update()
    return image


def bake_lightmaps(scene, objects, *, uv_name=DEFAULT_UV, resolution=256, basis="hl2", bounces=2, samples=4,
                   margin=2, out_dir=None, depsgraph=None, progress=None, images=True):
    """Bakes the objects' lightmaps; returns {object name: EXR path or None}.

    Writes `DIR/<object>.exr` (layers as docs/lightmaps.md) when a folder is known
    (`output_folder`) and Blender images `hemishadow_<object>_<map>` when `images`. Raises
    ValueError naming the object for unusable input; `hemishadow.Cancelled` when `progress`
    returns False (nothing is written: files are written only once every map is baked)."""
    import hemishadow
    import hemishadow.lightmap as lm

    objects = list(objects)
    if not objects:
        raise ValueError("no objects to bake: select mesh objects or name them")
    for obj in objects:
        if obj.type != "MESH":
            raise ValueError(f"{obj.name}: only mesh objects can have lightmaps")
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    scene_ = hemishadow.Scene()
    surfaces, targets = {}, []
    for obj in set(blockers(scene)) | set(objects):
        data = read_mesh(obj, depsgraph, uv_name if obj in objects else None)
        if not len(data.triangles):
            if obj in objects:
                raise ValueError(f"{obj.name}: the mesh has no faces")
            continue
        mesh_id = scene_.add_mesh(data.vertices, data.triangles.astype(np.uint32))
        matrix = np.array(obj.evaluated_get(depsgraph).matrix_world, np.float64)
        scene_.add_instance(mesh_id, matrix)
        albedo, emission = albedo_and_emission(obj)
        surfaces[obj.name] = lm.Surface(mesh_id, data.vertices, data.triangles, matrix, albedo, emission, obj.name)
        if obj in objects:
            targets.append(lm.Target(surfaces[obj.name], data.uv, data.corner_normals, data.tangents, name=obj.name))
    others = [s for name, s in surfaces.items() if name not in {t.name for t in targets}]
    maps = lm.bake(scene_, targets, resolution=resolution, lighting=lighting_of(scene), suns=suns_of(scene), lamps=lamps_of(scene),
                   surfaces=others, bounces=bounces, samples=samples, margin=margin, basis=basis, progress=progress)
    folder = output_folder(out_dir)
    written = {}
    for target, result in zip(targets, maps):
        path = None
        if folder is not None:
            path = os.path.join(folder, f"{_safe(target.name)}.exr")
            lm.write_exr(path, result)
        written[target.name] = path
        if images:
            for name, data in result.items():
                if name != "valid":
                    image = store_image(f"{IMAGE_PREFIX}{target.name}_{name}", data)
                    if folder is None:
                        image.file_format = "OPEN_EXR"  # float pixels packed as float
                        image.pack()
    return written
