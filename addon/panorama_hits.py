"""Primary visibility of a panorama from Blender (issue 13): what each pixel of an
equirectangular panorama sees first, read from Cycles' data passes.

One Cycles render, 1 sample, pixel filter 0.01 px (no mixing across edges), of a panoramic
equirectangular camera: Position, Normal (shading), Diffuse Color (the Principled BSDF's Base
Color when metallic, transmission and the specular layer are 0: the specular layer is switched
off for the render) and Object Index passes. The geometric normal is that of the first
triangle on each pixel's ray: the engine's own ray cast where it sees the same object as
Cycles, Blender's BVH (a Python loop, about 2 s per 100 000 pixels) for the few pixels on
silhouettes where they differ. A temporary camera (and temporary render settings, pass
indices, specular levels and visibility of non-mesh geometry) is used and everything is put
back afterwards, also on error.

The viewpoint's frame follows docs/panoramas.md: with `--at` (identity) the centre column looks
along +X, the left quarter along +Y, the top row along +Z, which is a panoramic camera rotated
(90, 0, -90) degrees; a camera's frame is its rotation times the inverse of that one, an
Empty's frame its rotation.
"""

from __future__ import annotations

import contextlib
import math
import os
import tempfile

import bpy
import numpy as np

from . import probes

# A panoramic camera with this rotation gives the identity frame (`--at`).
CAMERA_FRAME = ((0.0, 0.0, -1.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0))  # Euler (90, 0, -90) degrees, as a matrix
_GEOMETRY = {"CURVE", "SURFACE", "META", "FONT", "CURVES", "POINTCLOUD", "VOLUME", "GREASEPENCIL", "GPENCIL"}
BACK_FACE_LIMIT = 0.5  # more back faces than this among the hits: the viewpoint is inside a mesh
DEFAULT_ALBEDO = 0.8  # meshes without a material: Blender's default grey


def viewpoint(scene, camera=None, at=None):
    """(origin (3,), rotation (3, 3)) of a camera or Empty (an object or its name) or of a
    point `at` (identity rotation). Raises ValueError naming what is wrong."""
    if at is not None:
        origin = np.asarray(at, np.float64).reshape(-1)
        if origin.shape != (3,) or not np.isfinite(origin).all():
            raise ValueError(f"a viewpoint needs three finite coordinates, got {at!r}")
        return origin, np.eye(3)
    obj = scene.objects.get(camera) if isinstance(camera, str) else camera
    if obj is None:
        if camera is None:
            obj = scene.camera
            if obj is None:
                raise ValueError(f"scene {scene.name!r} has no camera: name one or give a point (--at X,Y,Z)")
        else:
            cameras = ", ".join(o.name for o in scene.objects if o.type in ("CAMERA", "EMPTY")) or "none"
            raise ValueError(f"no camera or Empty named {camera!r} in scene {scene.name!r}; there are: {cameras}")
    if obj.type not in ("CAMERA", "EMPTY"):
        raise ValueError(f"{obj.name}: a viewpoint is a camera or an Empty, not a {obj.type.lower()}")
    matrix = np.array(obj.matrix_world, np.float64)
    rotation = matrix[:3, :3] / np.linalg.norm(matrix[:3, :3], axis=0)
    if obj.type == "CAMERA":
        rotation = rotation @ np.array(CAMERA_FRAME).T
    return matrix[:3, 3].copy(), rotation


def camera_matrix(origin, rotation):
    """World matrix (4, 4) of a panoramic camera whose panorama has this frame."""
    m = np.eye(4)
    m[:3, :3] = np.asarray(rotation, np.float64) @ np.array(CAMERA_FRAME)
    m[:3, 3] = origin
    return m


@contextlib.contextmanager
def overrides(settings):
    """Sets (struct, attribute, value) in order and puts every old value back in the same
    order afterwards (so a format's media type is restored before its file format); the old
    values are all read first (setting one may change another)."""
    settings = [s for s in settings if hasattr(s[0], s[1])]  # leaves out what this Blender does not have
    old = [(struct, attr, getattr(struct, attr)) for struct, attr, _ in settings]  # before any change
    try:
        for struct, attr, value in settings:
            setattr(struct, attr, value)
        yield
    finally:
        for struct, attr, value in old:
            setattr(struct, attr, value)


@contextlib.contextmanager
def temporary_camera(scene, origin, rotation):
    """A panoramic equirectangular camera linked to the scene for the duration, then removed."""
    data = bpy.data.cameras.new("hemishadow_panorama")
    obj = bpy.data.objects.new("hemishadow_panorama", data)
    try:
        data.type = "PANO"
        if hasattr(data, "panorama_type"):
            data.panorama_type = "EQUIRECTANGULAR"
        else:  # Blender before 4.0 kept it in Cycles' settings
            data.cycles.panorama_type = "EQUIRECTANGULAR"
        for attr, value in (("latitude_min", -math.pi / 2), ("latitude_max", math.pi / 2),
                            ("longitude_min", -math.pi), ("longitude_max", math.pi)):
            if hasattr(data, attr):
                setattr(data, attr, value)
        obj.matrix_world = camera_matrix(origin, rotation).T.tolist()
        scene.collection.objects.link(obj)
        yield obj
    finally:
        bpy.data.objects.remove(obj)
        bpy.data.cameras.remove(data)


def _view_layer(scene):
    layer = bpy.context.view_layer
    return layer if bpy.context.scene == scene and layer.name in scene.view_layers else scene.view_layers[0]


def render_settings(scene, camera, layer, size, path):
    """The temporary settings of a data-pass render (see the module docstring)."""
    r, c, f = scene.render, scene.cycles, scene.render.image_settings
    out = [(scene, "camera", camera), (r, "engine", "CYCLES"), (r, "resolution_x", int(size[0])),
           (r, "resolution_y", int(size[1])), (r, "resolution_percentage", 100), (r, "pixel_aspect_x", 1.0),
           (r, "pixel_aspect_y", 1.0), (r, "use_border", False), (r, "use_compositing", False),
           (r, "use_sequencer", False), (r, "use_motion_blur", False), (r, "use_multiview", False),
           (r, "use_single_layer", True), (r, "use_persistent_data", False), (r, "filepath", path),
           (c, "samples", 1), (c, "use_adaptive_sampling", False), (c, "use_denoising", False),
           (c, "filter_width", 0.01), (c, "max_bounces", 0), (c, "use_light_tree", False),
           (f, "media_type", "MULTI_LAYER_IMAGE"), (f, "file_format", "OPEN_EXR_MULTILAYER"),
           (f, "color_depth", "32"), (f, "exr_codec", "ZIP"), (layer, "use", True)]
    out += [(layer, f"use_pass_{name}", True) for name in ("position", "normal", "diffuse_color", "object_index",
                                                          "z")]
    if bpy.context.view_layer != layer and bpy.context.window is not None:
        out.append((bpy.context.window, "view_layer", layer))
    return out


def read_passes(path, layer_name):
    """{pass: (H, W, C) float32} of a multi-layer (multi-part) EXR, rows top first."""
    import OpenEXR

    channels = {}
    with OpenEXR.File(path, separate_channels=True) as exr:
        for part in exr.parts:  # Blender 5 writes one part per pass
            channels.update({name: np.asarray(ch.pixels, np.float32) for name, ch in part.channels.items()})
    out = {}
    for key, spellings, components in _PASSES:
        for spelling in spellings:
            names = [f"{layer_name}.{spelling}.{c}" for c in components]
            if all(n in channels for n in names):
                out[key] = np.stack([channels[n] for n in names], axis=-1)
                break
        else:
            raise RuntimeError(f"Cycles wrote no {key} pass to {path} (it has {sorted(channels)})")
    return out


# (key, names in the file: Blender 5 spells out the short names of 4.x, components)
_PASSES = (("Position", ("Position",), "XYZ"), ("Normal", ("Normal",), "XYZ"),
           ("DiffCol", ("Diffuse Color", "DiffCol"), "RGB"), ("IndexOB", ("Object Index", "IndexOB"), "X"),
           ("Depth", ("Depth", "Z"), "Z"))


def render_passes(scene, origin, rotation, size, meshes):
    """Cycles' data passes of a panorama at `origin` with frame `rotation`, `size` (W, H);
    object index i + 1 for meshes[i]. Nothing stays changed: settings, pass indices, the
    hidden non-mesh geometry and the camera are put back, the temporary file removed."""
    layer = _view_layer(scene)
    hidden = [(o, "hide_render", True) for o in scene.objects if o.type in _GEOMETRY and not o.hide_render]
    indices = [(o, "pass_index", i + 1) for i, o in enumerate(meshes)] + _no_specular(meshes)
    with tempfile.TemporaryDirectory(prefix="hemishadow_panorama_") as folder:
        path = os.path.join(folder, "passes.exr")
        with temporary_camera(scene, origin, rotation) as camera, \
                overrides(render_settings(scene, camera, layer, size, path) + hidden + indices):
            bpy.ops.render.render(write_still=True, scene=scene.name, layer=layer.name)
        return read_passes(path, layer.name)


def _no_specular(meshes):
    """Specular IOR Level 0 on the meshes' Principled BSDFs while the passes render: Cycles'
    Diffuse Color is the Base Color less what the dielectric layer reflects (angle-dependent),
    without it the Base Color itself."""
    out, seen = [], set()
    for obj in meshes:
        for slot in obj.material_slots:
            mat = slot.material
            if mat is None or mat.node_tree is None or mat.name in seen:
                continue
            seen.add(mat.name)
            for node in mat.node_tree.nodes:
                socket = node.inputs.get("Specular IOR Level") if node.type == "BSDF_PRINCIPLED" else None
                if socket is not None and not socket.is_linked and socket.default_value != 0:
                    out.append((socket, "default_value", 0.0))
    return out


def geometric_normals(world, origin, points):
    """Winding normal (P, 3) of the first triangle hit on the way from `origin` to each point
    (the pixel's ray: the same first surface Cycles saw), zero where the ray misses."""
    from mathutils import Vector
    from mathutils.bvhtree import BVHTree

    verts = world.reshape(-1, 3)
    tree = BVHTree.FromPolygons(verts.tolist(), np.arange(len(verts)).reshape(-1, 3).tolist(), epsilon=0.0)
    rays = points - np.asarray(origin, np.float64)
    reach = np.linalg.norm(rays, axis=1) * 1.001 + 1e-4
    normals = np.zeros((len(points), 3))
    start, cast = Vector(origin), tree.ray_cast
    for i, (ray, limit) in enumerate(zip(rays.tolist(), reach.tolist())):
        _, n, _, _ = cast(start, Vector(ray), limit)
        if n is not None:
            normals[i] = n
    return normals


def hits(scene, origin, rotation, size=(1024, 512), depsgraph=None):
    """(hemishadow.panorama.Hits, engine scene, surfaces) of the panorama at `origin` with
    frame `rotation`: Cycles' passes for the pixels, the engine scene of the same meshes (mesh
    id i = surfaces[i] = object id i). The shading normal faces the viewpoint, the geometric
    one is the triangle's modelled front (as in `primary_hits`). Raises ValueError for an
    empty scene or a viewpoint inside a mesh (naming it)."""
    from hemishadow.panorama import Hits

    engine_scene, surfaces, world = probes.scene_geometry(scene, depsgraph, live=True,
                                                          purpose="bake a panorama of")
    meshes = [scene.objects[s.name] for s in surfaces]
    passes = render_passes(scene, origin, rotation, size, meshes)
    object_id = np.rint(passes["IndexOB"][..., 0]).astype(np.int32) - 1
    mask = (object_id >= 0) & (passes["Depth"][..., 0] < 1e9)
    object_id[~mask] = -1
    position = np.where(mask[..., None], passes["Position"], 0).astype(np.float32)
    shading = np.where(mask[..., None], passes["Normal"], 0)
    ng = np.zeros_like(shading)
    winding = _winding(engine_scene, world, origin, rotation, size, position, object_id)[mask]
    towards = np.asarray(origin, np.float64) - position[mask]
    back = (winding * towards).sum(axis=1) < 0
    _check_inside(origin, back, object_id[mask], surfaces)
    ng[mask] = winding  # the triangle's modelled front, as the engine's primary_hits gives it
    shading[mask] *= np.where((shading[mask] * towards).sum(axis=1) < 0, -1.0, 1.0)[:, None]
    albedo = np.where(mask[..., None], passes["DiffCol"], 0).astype(np.float32)
    for i, obj in enumerate(meshes):
        if not any(slot.material for slot in obj.material_slots):
            albedo[object_id == i] = DEFAULT_ALBEDO  # Cycles' default surface has a specular layer in 5.x
    return (Hits(position, _unit(ng), _unit(shading), albedo, object_id, mask), engine_scene, surfaces)


def _winding(engine_scene, world, origin, rotation, size, position, object_id):
    """(H, W, 3) winding normals: the engine's own primary hits where they see the same object
    (a native ray cast, the same triangle but on silhouettes), Blender's BVH for the rest
    (edges, and every pixel when the engine finds the viewpoint inside geometry: then
    `_check_inside` names the mesh)."""
    from hemishadow.panorama import primary_hits

    out = np.zeros(position.shape, np.float64)
    same = np.zeros(object_id.shape, bool)
    try:
        ref = primary_hits(engine_scene, origin, size=size, rotation=rotation)
        same = ref.mask & (ref.object_id == object_id)
        out[same] = ref.geometric_normal[same]
    except ValueError:
        pass
    rest = (object_id >= 0) & ~same
    out[rest] = geometric_normals(world, origin, position[rest].astype(np.float64))
    return out


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n > 0, v / np.where(n > 0, n, 1), 0).astype(np.float32)


def _check_inside(origin, back, object_id, surfaces):
    """ValueError when most of what the viewpoint sees are back faces: it is inside a mesh."""
    if len(back) and back.mean() > BACK_FACE_LIMIT:
        worst = np.bincount(object_id[back], minlength=len(surfaces)).argmax()
        x, y, z = (float(v) for v in origin)
        raise ValueError(f"{surfaces[worst].name}: the viewpoint ({x:.3g}, {y:.3g}, {z:.3g}) is inside it: "
                         f"{100 * back.mean():.0f} % of what it sees are back faces; move the camera or --at point")
