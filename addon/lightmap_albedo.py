"""Albedo for the lightmap bake's bounce light: the Base Color of the object's first
Principled BSDF, its value, or the Image Texture feeding it sampled per vertex.

Per vertex because bounce light is carried by vertex radiance (docs/lightmaps.md): each
corner samples the image bilinearly at its UV (the Image Texture's UV Map node, else the
active render UV map; Repeat, or clamped for the other extensions), and a vertex takes the
mean of its corners. Byte images in sRGB are converted to linear; alpha is ignored. Anything
else feeding Base Color (a Mix node, ...) is not evaluated: 0.8 grey and a warning.
"""

import warnings

import numpy as np

DEFAULT = 0.8


def principled(obj):
    """The first Principled BSDF of the object's materials, or None."""
    for slot in obj.material_slots:
        mat = slot.material
        if mat is not None and mat.node_tree is not None:
            for node in mat.node_tree.nodes:
                if node.type == "BSDF_PRINCIPLED":
                    return node
    return None


def _source(socket):
    """The node feeding `socket`, through reroutes; None when unlinked."""
    while socket.is_linked:
        node = socket.links[0].from_node
        if node.type != "REROUTE":
            return node
        socket = node.inputs[0]
    return None


def _warn(message):
    warnings.warn(message, RuntimeWarning, stacklevel=3)


def base_color(obj, mesh):
    """(3,) or per vertex (V, 3) linear albedo of `obj`, whose evaluated mesh is `mesh`."""
    node = principled(obj)
    if node is None:
        return np.full(3, DEFAULT)
    socket = node.inputs["Base Color"]
    value = np.array(socket.default_value[:3], np.float64)
    source = _source(socket)
    if source is None:
        return value
    if source.type != "TEX_IMAGE":
        _warn(f"{obj.name}: Base Color comes from a '{source.name}' node, which the bake does not evaluate: "
              f"albedo {DEFAULT} used for bounce light")
        return np.full(3, DEFAULT)
    pixels = _pixels(obj, source.image)
    if pixels is None:
        return np.full(3, DEFAULT)
    uv = _corner_uv(obj, mesh, source)
    if uv is None:
        return np.full(3, DEFAULT)
    colours = _bilinear(pixels, uv, source.extension == "REPEAT")
    loops_vertex = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", loops_vertex)
    count = np.bincount(loops_vertex, minlength=len(mesh.vertices))
    out = np.stack([np.bincount(loops_vertex, colours[:, c], len(mesh.vertices)) for c in range(3)], axis=1)
    return np.where(count[:, None] > 0, out / np.maximum(count, 1)[:, None], DEFAULT)


def _pixels(obj, image):
    """(H, W, 3) linear pixels, or None (with a warning naming the object) when missing."""
    if image is None:
        _warn(f"{obj.name}: the Image Texture feeding Base Color has no image: albedo {DEFAULT} used")
        return None
    w, h = image.size
    if not (w and h) or not image.has_data and not _load(image):
        where = image.filepath or "no file"
        _warn(f"{obj.name}: image '{image.name}' ({where}) cannot be read: albedo {DEFAULT} used for bounce light")
        return None
    data = np.empty(w * h * image.channels, np.float32)
    image.pixels.foreach_get(data)
    data = data.reshape(h, w, image.channels).astype(np.float64)
    rgb = data[..., :3] if image.channels >= 3 else np.repeat(data[..., :1], 3, axis=2)
    if not image.is_float and image.colorspace_settings.name == "sRGB":
        rgb = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    return rgb


def _load(image):
    try:
        image.pixels[0]  # reading a pixel loads the file
    except (RuntimeError, IndexError):
        return False
    return image.has_data


def _corner_uv(obj, mesh, texture):
    vector = _source(texture.inputs["Vector"])
    name = vector.uv_map if vector is not None and vector.type == "UVMAP" else ""
    if vector is not None and vector.type != "UVMAP":
        _warn(f"{obj.name}: the Base Color texture's Vector comes from a '{vector.name}' node: "
              "sampled on the render UV map")
    layer = mesh.uv_layers.get(name) if name else next((u for u in mesh.uv_layers if u.active_render), None)
    if layer is None:
        _warn(f"{obj.name}: no UV map {name!r} for its Base Color texture: albedo {DEFAULT} used")
        return None
    uv = np.empty(len(mesh.loops) * 2, np.float32)
    layer.uv.foreach_get("vector", uv)
    return uv.reshape(-1, 2).astype(np.float64)


def _bilinear(rgb, uv, repeat):
    """Bilinear samples of (H, W, 3) pixels (rows from the bottom, as Blender stores them)."""
    h, w = rgb.shape[:2]
    x, y = uv[:, 0] * w - 0.5, uv[:, 1] * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]

    def at(ix, iy):
        ix, iy = ix.astype(np.int64), iy.astype(np.int64)
        ix, iy = (ix % w, iy % h) if repeat else (np.clip(ix, 0, w - 1), np.clip(iy, 0, h - 1))
        return rgb[iy, ix]

    return ((at(x0, y0) * (1 - fx) + at(x0 + 1, y0) * fx) * (1 - fy)
            + (at(x0, y0 + 1) * (1 - fx) + at(x0 + 1, y0 + 1) * fx) * fy)
