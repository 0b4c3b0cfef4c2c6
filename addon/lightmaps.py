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
import itertools
import os
import re
import time
import types
import warnings

import bpy
import numpy as np

from . import lamps, lightmap_albedo, lightmap_atlas, world

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
    albedo: np.ndarray | None = None
    blocker: tuple | None = None  # (vertices, triangles) before `bisected`, when it split the mesh


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


#: Bounce light is carried per vertex: meshes are split (`bisected`) until no edge is longer than
#: this fraction of the scene's diagonal. The test room (4.4 x 4.4 x 2.9 m, walls and floor of
#: one box each) against Cycles with 2 bounces, mean error over the floor at 64 x 64
#: (docs/lightmaps.md): 24 % with its boxes as they are; 2.15 % at 1/8, 1.44 % at 1/12, 1.16 %
#: at 1/16 (0.68, 0.72, 1.0 s), 1.06 % at 1/20 (1.4 s): past 1/16 the walks cost more than the
#: error saves against Cycles' samples.
BOUNCE_EDGE = 1 / 16

#: `Scene.lod` of the scene direct light walks: a node is drawn through its proxy only where
#: it subtends less than this. At the engine's default (0.15) the test room's floor, lit by
#: the sky alone through its window, baked 4.4 % dark against Cycles (0.7 % at 0.05: proxies
#: of the walls around the window cut into it), and the corner's median error was 0.21 %
#: (0.15 % at 0.05). Through meshes as they are, not split for bounce light, it costs little.
DIRECT_LOD = 0.05


def bounce_edge(objects, depsgraph):
    """The longest edge bounce surfaces keep (`BOUNCE_EDGE` of the objects' world box's
    diagonal); None without objects."""
    corners = [np.array(o.evaluated_get(depsgraph).matrix_world, np.float64)
               @ np.c_[np.array(o.bound_box, np.float64), np.ones(8)].T for o in objects]
    if not corners:
        return None
    points = np.concatenate([c[:3].T for c in corners])
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0))) * BOUNCE_EDGE


def read_mesh(obj, depsgraph, uv_name=None, albedo=False, max_edge=None):
    """The evaluated mesh of `obj` (local space) with its lightmap UVs and tangents per corner,
    its vertices split where faces meet at sharp edges (`split_sharp_vertices`: bounce light is
    carried per vertex).

    Tangents are Blender's MikkTSpace tangents of the active render UV map (the one normal
    maps use); None when the mesh cannot have them (no UV map, n-gons), and the engine falls
    back to per-triangle tangents. Raises ValueError naming the object when `uv_name` is
    asked for and missing. `albedo`: also the Base Color per vertex (lightmap_albedo).
    `max_edge`: triangles are split (`bisected`) until no edge is longer (world units), for
    bounce light, which is carried per vertex; `blocker` keeps the triangles as they were
    (the same surface, for visibility: a mask walk over the split mesh costs 3-4x more)."""
    from hemishadow.lightmap.geometry import bisected, split_sharp_vertices

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
        colour = lightmap_albedo.base_color(obj, mesh) if albedo else None
        triangles, source = split_sharp_vertices(triangles.reshape(m, 3), normals)
        vertices = vertices[source]
        if colour is not None and np.ndim(colour) == 2:
            colour = colour[source]
        matrix = np.array(obj_eval.matrix_world, np.float64)
        given = [a for a in (normals, uv, tangents) if a is not None]
        split = bisected(vertices, triangles, max_edge or 0.0, vertices @ matrix[:3, :3].T + matrix[:3, 3], given,
                         [colour])
        if len(split[1]) == len(triangles):
            return MeshData(vertices, triangles, normals, uv, tangents, colour)
        corners = iter(split[2])
        normals, uv, tangents = (None if a is None else next(corners) for a in (normals, uv, tangents))
        return MeshData(split[0].astype(np.float32), split[1], normals, uv, tangents, split[3][0], (vertices, triangles))
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


def emission_of(obj):
    """Emitted radiance (3,) from the Principled BSDF's Emission input values (none without
    one; emission textures are not sampled)."""
    node = lightmap_albedo.principled(obj)
    if node is None:
        return np.zeros(3)
    emission = np.zeros(3)
    color = node.inputs.get("Emission Color") or node.inputs.get("Emission")
    strength = node.inputs.get("Emission Strength")
    if color is not None:
        emission = np.array(color.default_value[:3], np.float64) * (strength.default_value if strength else 1.0)
    return emission


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
        made = bpy.data.images.new(name, w, h, alpha=False, float_buffer=True)
        made.colorspace_settings.name = "Non-Color"  # before the pixels: it reloads a generated image
        if image is not None:  # a new size: materials showing the old image show the new one
            image.user_remap(made)
            bpy.data.images.remove(image)
            made.name = name
        image = made
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = data[::-1]  # Blender's pixel rows start at the bottom
    image.pixels.foreach_set(rgba.ravel())
    image.update()
    return image


MIN_RESOLUTION, MAX_RESOLUTION = 4, 4096
BAKED_KEY = "hemishadow_bake"  # on baked images: which bake of the session made them (the newest wins)
_bake_counter = itertools.count(int(time.time() * 1000))


def density_resolution(area, uv_area, texel_density):
    """Texels per side giving `texel_density` texels per metre (world units) along the
    surface: R = density x sqrt(area / uv_area), with `area` the object's surface area in world
    units and `uv_area` the part of the unit UV square its lightmap islands cover (so that
    margins and unused space are paid for), rounded to the nearest multiple of 4 and clamped to
    [4, 4096]."""
    if not texel_density > 0:
        raise ValueError(f"texel density must be > 0 texels per metre, got {texel_density!r}")
    r = texel_density * np.sqrt(area / uv_area) if uv_area > 0 else MIN_RESOLUTION
    return int(np.clip(4 * round(r / 4), MIN_RESOLUTION, MAX_RESOLUTION))


def surface_areas(data, matrix):
    """World surface area and lightmap UV area (absolute, summed) of a read mesh."""
    world = data.vertices @ np.asarray(matrix)[:3, :3].T
    p = world[data.triangles]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
    uv = data.uv
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    return float(area), float(0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum())


def shared_meshes(scene, objects):
    """{baked object name: [other objects of the scene using its mesh]} for the objects whose
    mesh has other users: they cannot have lightmap UVs (or materials) of their own."""
    out = {}
    for obj in objects:
        others = [o for o in scene.objects if o.data == obj.data and o != obj]
        if obj.type == "MESH" and others:
            out[obj.name] = others
    return out


def make_single_user(scene, objects):
    """Gives each of `objects` whose mesh other objects use a copy of that mesh (the last
    user of a mesh keeps it); returns the objects that got one. Only ever asked for."""
    changed = []
    for obj in objects:
        if obj.type == "MESH" and any(o.data == obj.data and o != obj for o in scene.objects):
            obj.data = obj.data.copy()
            changed.append(obj)
    return changed


@dataclasses.dataclass
class Prepared:
    """Everything the engine needs, read from Blender; `compute` uses no bpy (a worker
    thread can run it)."""
    engine_scene: object
    targets: list
    surfaces: list
    lighting: np.ndarray
    suns: list
    resolutions: list
    options: dict
    atlas: str | None = None  # the atlas's name when the targets share one map
    bounce_scene: object = None  # the split meshes that carry bounce light (None: engine_scene's)


LAYOUTS = ("ATLAS", "OBJECT")


def _check_objects(objects):
    if not objects:
        raise ValueError("no objects to bake: select mesh objects or name them")
    for obj in objects:
        if obj.type != "MESH":
            raise ValueError(f"{obj.name}: only mesh objects can have lightmaps")


def _world_and_uv_areas(objects, depsgraph, uv_name):
    total = np.zeros(2)
    for obj in objects:
        data = read_mesh(obj, depsgraph, uv_name)
        total += surface_areas(data, np.array(obj.evaluated_get(depsgraph).matrix_world, np.float64))
    return total


def atlas_resolution(objects, source_uv, resolution, texel_density, margin):
    """Lays the objects' islands out in `hemishadow_lightmap` (lightmap_atlas.layout) and
    returns the atlas's texels per side: `resolution`, or from `texel_density` over all the
    objects' area (laid out twice: the margin between islands depends on the resolution)."""
    for obj in objects:
        if not len(obj.data.polygons):
            raise ValueError(f"{obj.name}: the mesh has no faces")
    if texel_density is None:
        lightmap_atlas.layout(objects, source_uv, lightmap_atlas.margin_fraction(resolution, margin))
        return resolution
    size = MIN_RESOLUTION
    for guess in (0.01, None):
        lightmap_atlas.layout(objects, source_uv, guess or lightmap_atlas.margin_fraction(size, margin))
        area, uv_area = _world_and_uv_areas(objects, bpy.context.evaluated_depsgraph_get(), lightmap_atlas.ATLAS_UV)
        size = density_resolution(area, uv_area, texel_density)
    return size


def prepare(scene, objects, *, uv_name=DEFAULT_UV, resolution=256, texel_density=None, basis="hl2", bounces=2,
            samples=4, adaptive=True, margin=2, layout="ATLAS", atlas_name=None, depsgraph=None):
    """Reads the objects, blockers, materials, World and suns (warnings for shared meshes,
    missing textures); raises ValueError naming the object for unusable input. Changes nothing,
    except for an atlas (layout="ATLAS" and several objects): the baker's own UV map
    `hemishadow_lightmap` is remade on their meshes (lightmap_atlas), `uv_name` giving the
    islands."""
    import hemishadow
    import hemishadow.lightmap as lm

    objects = list(objects)
    _check_objects(objects)
    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {LAYOUTS}, got {layout!r}")
    if texel_density is None and not (isinstance(resolution, int) and resolution >= 1):
        raise ValueError(f"resolution must be at least 1 texel, got {resolution!r}")
    atlas = lightmap_atlas.atlas_name(atlas_name) if layout == "ATLAS" and len(objects) > 1 else None
    for name, others in shared_meshes(scene, objects).items():
        warnings.warn(f"{name}: its mesh '{scene.objects[name].data.name}' is shared with "
                      f"{', '.join(repr(o.name) for o in others)}: they have one lightmap UV layout; "
                      "Make Single User (Lightmaps) gives it a mesh of its own", RuntimeWarning, stacklevel=2)
    if atlas is not None:
        resolution = atlas_resolution(objects, uv_name, resolution, texel_density, margin)
        uv_name, texel_density, depsgraph = lightmap_atlas.ATLAS_UV, None, None  # evaluated after the layout
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    engine_scene = hemishadow.Scene(lod=DIRECT_LOD)
    surfaces, pairs = {}, []
    baked = {o.name for o in objects}
    meshes = sorted(set(blockers(scene)) | set(objects), key=lambda o: (o.name not in baked, o.name))
    max_edge = bounce_edge(meshes, depsgraph) if bounces else None
    bounce_scene = hemishadow.Scene() if max_edge else None  # gets every mesh in the same order: same ids
    for obj in meshes:
        data = read_mesh(obj, depsgraph, uv_name if obj.name in baked else None, albedo=True, max_edge=max_edge)
        if not len(data.triangles):
            if obj.name in baked:
                raise ValueError(f"{obj.name}: the mesh has no faces")
            continue
        matrix = np.array(obj.evaluated_get(depsgraph).matrix_world, np.float64)
        mesh_id = _add_mesh(engine_scene, *(data.blocker or (data.vertices, data.triangles)), matrix)
        if bounce_scene is not None:
            _add_mesh(bounce_scene, data.vertices, data.triangles, matrix)
        surface = lm.Surface(mesh_id, data.vertices, data.triangles, matrix, data.albedo, emission_of(obj), obj.name)
        surfaces[obj.name] = surface
        if obj.name in baked:
            size = resolution if texel_density is None else density_resolution(*surface_areas(data, matrix),
                                                                                  texel_density)
            pairs.append((lm.Target(surface, data.uv, data.corner_normals, data.tangents, name=obj.name), size))
    order = [o.name for o in objects]
    pairs.sort(key=lambda pair: order.index(pair[0].name))  # results in the caller's order
    targets, resolutions = [p[0] for p in pairs], [p[1] for p in pairs]
    others = [s for name, s in surfaces.items() if name not in baked]
    return Prepared(engine_scene, targets, others, lighting_of(scene), suns_of(scene), resolutions,
                    dict(bounces=bounces, samples=samples, adaptive=adaptive, margin=margin, basis=basis,
                         lamps=lamps_of(scene),
                         atlas=atlas is not None), atlas, bounce_scene)


def _add_mesh(engine_scene, vertices, triangles, matrix):
    mesh_id = engine_scene.add_mesh(vertices, triangles.astype(np.uint32))
    engine_scene.add_instance(mesh_id, matrix)
    return mesh_id


def baked_names(targets):
    return [t.name for t in targets]


def output_names(prepared):
    """The names of the bake's files and images: the atlas's, or each object's."""
    return [prepared.atlas] if prepared.atlas else baked_names(prepared.targets)


def compute(prepared, progress=None):
    """The engine's bake (no bpy): one dict of maps per target. `progress(fraction)`
    returning False raises hemishadow.Cancelled."""
    import hemishadow.lightmap as lm

    return lm.bake(prepared.engine_scene, prepared.targets, resolution=prepared.resolutions,
                   lighting=prepared.lighting, suns=prepared.suns, surfaces=prepared.surfaces, progress=progress,
                   bounce_scene=prepared.bounce_scene,
                   **prepared.options)


def write_files(folder, named_maps):
    """Writes every `<name>.exr` or none: each to a temporary file first, renamed into place
    only once all are written (a failure removes the temporary files)."""
    import hemishadow.lightmap as lm

    os.makedirs(folder, exist_ok=True)
    pending = []
    try:
        for name, maps in named_maps:
            final = os.path.join(folder, f"{_safe(name)}.exr")
            temporary = os.path.join(folder, f".{_safe(name)}.hemishadow-partial.exr")
            lm.write_exr(temporary, maps)
            pending.append((temporary, final))
    except BaseException:
        for temporary, _ in pending:
            os.remove(temporary)
        raise
    for temporary, final in pending:
        os.replace(temporary, final)
    return {name: final for (name, _), (_, final) in zip(named_maps, pending)}


def finish(prepared, results, out_dir=None, images=True):
    """Writes the files (all or none) and then the Blender images; returns {object: path}."""
    named = list(zip(output_names(prepared), results))
    folder = output_folder(out_dir)
    written = write_files(folder, named) if folder is not None else {name: None for name, _ in named}
    if images:
        for name, result in named:
            for map_name, data in result.items():
                if map_name != "valid":
                    image = store_image(f"{IMAGE_PREFIX}{name}_{map_name}", data)
                    image[lightmap_atlas.OBJECTS_KEY] = baked_names(prepared.targets) if prepared.atlas else []
                    image[BAKED_KEY] = float(next(_bake_counter))
                    if folder is None:
                        image.file_format = "OPEN_EXR"  # float pixels packed as float
                        image.pack()
    return written


def bake_lightmaps(scene, objects, *, uv_name=DEFAULT_UV, resolution=256, texel_density=None, basis="hl2", bounces=2,
                   samples=4, adaptive=True, margin=2, layout="ATLAS", atlas_name=None, out_dir=None, depsgraph=None,
                   progress=None, images=True):
    """Bakes the objects' lightmaps; returns {object or atlas name: EXR path or None}.

    Writes `DIR/<object>.exr` (layers as docs/lightmaps.md) when a folder is known
    (`output_folder`) and Blender images `hemishadow_<object>_<map>` when `images`.
    layout="ATLAS" with several objects: one map for all, `DIR/<atlas_name>.exr` and images
    `hemishadow_<atlas_name>_<map>`, read through the UV map `hemishadow_lightmap` (made by
    the bake from `uv_name`'s islands; lightmap_atlas); "OBJECT": `uv_name` as it is.
    `texel_density` (texels per metre) replaces `resolution` (`density_resolution`, per
    object). Raises ValueError naming the object for unusable input; `hemishadow.Cancelled`
    when `progress` returns False (nothing is written: files and images are written only once
    every map is baked). The plain path of the modal operator (lightmap_job.py)."""
    prepared = prepare(scene, objects, uv_name=uv_name, resolution=resolution, texel_density=texel_density,
                       basis=basis, bounces=bounces, samples=samples, adaptive=adaptive, margin=margin, layout=layout,
                       atlas_name=atlas_name, depsgraph=depsgraph)
    return finish(prepared, compute(prepared, progress), out_dir, images)
