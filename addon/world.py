"""World / Environment Texture / sun lamps -> lighting SH.

`scene_lighting(scene, bands)` gives the SH coefficients (bands*bands, 3) of the radiance
arriving at the scene, in the project's conventions (Blender world space, +Z up; real
orthonormal SH, index l*(l+1)+m; see the design notes): irradiance on a receiver with transfer
vector T is T . L, as `hemishadow.shade` computes it.

The projection of an environment image is the expensive part (about 0.1 s for a 1k map), so it
is cached per image (file path and modification time, or name, size and pixels), rotation and
band count; intensity, the extra rotation and sun lamps are applied on top, so changing those
re-shades at once. This module never imports the add-on's other modules: the tests load it on
its own.
"""

from __future__ import annotations

import collections
import dataclasses
import hashlib
import math
import os

import bpy
import numpy as np

__all__ = ["LightingSource", "lighting_source", "scene_lighting", "sun_lobe", "clear_cache"]

# Defaults for the scene settings (`scene.hemishadow`, defined in properties.py) when they
# are not registered; the same values as the properties' defaults.
DEFAULTS = {
    "lighting_source": "WORLD",  # 'WORLD', 'BUILTIN' or 'UNIFORM'
    "hdri": "forest",            # a key of hemishadow.environment.builtin_hdris()
    "intensity": 1.0,            # scales the environment (World, HDRI or uniform sky)
    "rotation": 0.0,             # radians about world +Z, applied to the environment
    "use_sun_lamps": True,       # add the scene's sun lamps as SH lobes
    "uniform_color": (1.0, 1.0, 1.0),  # radiance of the uniform sky
}

_CACHE_SIZE = 16
_cache: collections.OrderedDict = collections.OrderedDict()


@dataclasses.dataclass
class LightingSource:
    """Where the environment part of the lighting comes from.

    kind: 'WORLD' (the World's Environment Texture), 'BUILTIN' (a built-in HDRI) or 'UNIFORM'.
    label: one line for the user interface, e.g. "World: forest.exr, strength 1.0".
    image: the bpy Image (WORLD) or None; path: the EXR path read directly, or None when the
    image's pixels are used (packed, generated, not EXR).
    rotation: 3x3 matrix meaning what the Mapping node (type Point) does: the image is looked
    up at rotation @ d for the radiance arriving from d.
    scale: RGB factor (the Background strength; the uniform sky's colour).
    """

    kind: str
    label: str
    image: object = None
    path: str | None = None
    rotation: np.ndarray = dataclasses.field(default_factory=lambda: np.eye(3))
    scale: np.ndarray = dataclasses.field(default_factory=lambda: np.ones(3))


def clear_cache() -> None:
    """Forget every cached projection (the next `scene_lighting` projects again)."""
    _cache.clear()


def _settings_value(settings, name):
    return getattr(settings, name, DEFAULTS[name]) if settings is not None else DEFAULTS[name]


def scene_lighting(scene, bands=5, settings=None) -> np.ndarray:
    """Lighting SH of the scene: float32 (bands*bands, 3), radiance coefficients.

    Environment (radiance, per `lighting_source`): the World's Environment Texture when one
    feeds the World output's Background (its Mapping node rotation and Background strength
    honoured), else the built-in HDRI named by `hdri`, else a uniform sky of radiance
    `uniform_color` (band 0 only: L_00 = sqrt(4 pi) c, so an open surface gets irradiance pi c).
    The environment is scaled by `intensity` and rotated by `rotation` radians about +Z
    (counter-clockwise seen from above: what lit +X then lights cos(r) X + sin(r) Y).

    Sun lamps (when `use_sun_lamps`): each visible sun adds `sun_lobe(direction, strength *
    color, angle, bands)`, direction = towards the sun (the lamp's +Z axis; it shines along
    -Z), not scaled or rotated by the settings above: a lamp's strength is its own.

    settings: an object with the attributes of `scene.hemishadow` (see DEFAULTS); by default
    `scene.hemishadow`, or DEFAULTS when the add-on's properties are not registered.
    """
    import hemishadow

    if settings is None:
        settings = getattr(scene, "hemishadow", None)
    source = lighting_source(scene, settings)
    if source.kind == "UNIFORM":
        lighting = np.zeros((bands * bands, 3), np.float64)
        lighting[0] = math.sqrt(4 * math.pi) * source.scale
    else:
        lighting = _projection(source, bands).astype(np.float64) * source.scale
    lighting *= float(_settings_value(settings, "intensity"))
    angle = float(_settings_value(settings, "rotation"))
    if angle:
        lighting = hemishadow.rotate_sh(lighting, hemishadow.rotation_matrix((0, 0, 1), angle)).astype(np.float64)
    if _settings_value(settings, "use_sun_lamps"):
        for obj in _sun_lamps(scene):
            direction = np.array(obj.matrix_world.to_3x3().col[2], np.float64)
            if not np.linalg.norm(direction) > 0:
                continue
            light = obj.data
            lighting += sun_lobe(direction, float(light.energy) * np.array(light.color, np.float64),
                                 float(light.angle), bands)
    return np.ascontiguousarray(lighting, dtype=np.float32)


def lighting_source(scene, settings=None) -> LightingSource:
    """The environment the settings pick, with its fallbacks (see `scene_lighting`)."""
    if settings is None:
        settings = getattr(scene, "hemishadow", None)
    kind = _settings_value(settings, "lighting_source")
    fallback_note = ""
    if kind == "WORLD":
        found, why = _world_environment(scene.world)
        if found is not None:
            return found
        fallback_note = f" ({why})"
    if kind in ("WORLD", "BUILTIN"):
        builtin = _builtin_source(_settings_value(settings, "hdri"))
        if builtin is not None:
            builtin.label += fallback_note
            return builtin
        fallback_note = " (no built-in HDRI found)"
    color = np.array(_settings_value(settings, "uniform_color"), np.float64)
    return LightingSource("UNIFORM", f"Uniform sky{fallback_note}", scale=color)


def sun_lobe(direction, irradiance, angle, bands=5) -> np.ndarray:
    """SH (bands*bands, C) of a sun: a uniform cap of directions around `direction`.

    direction: towards the sun (normalised here). irradiance: E, scalar or (C,) per channel,
    the irradiance the sun gives a surface facing it (W/m^2 for a Blender sun's Strength).
    angle: the sun's angular diameter a (radians, 0 to pi); the cap's half-angle is h = a/2.

    The radiance is L0 inside the cap and 0 outside, with L0 = E / (pi sin^2 h), since a cap
    of half-angle h seen by a surface facing it subtends integral cos(t) dw = pi sin^2 h: the
    surface facing the sun gets exactly E.

    A function of the angle t from an axis s only (zonal) has zonal coefficients
        z_l = 2 pi integral_{cos h}^{1} Y_l0(x) dx,  Y_l0(x) = sqrt((2l+1)/(4 pi)) P_l(x),
    and for the cap, with integral_c^1 P_0 = 1 - c and, for l >= 1,
        integral_c^1 P_l(x) dx = (P_{l-1}(c) - P_{l+1}(c)) / (2l+1)   (Legendre identity),
    rotated to point at s its coefficients are (the addition theorem)
        L_lm = L0 sqrt(4 pi/(2l+1)) z_l Y_lm(s),
    Y_lm(s) from hemishadow.sh_basis. As h -> 0 this tends to E Y_lm(s), the projection of a
    point light, used below h = 1e-6.

    The SH series is truncated, so the irradiance of the facing surface, sum_l L_l . T_l, is E
    times the band-limited clamped cosine at 0 degrees: 0.969 E with 25 coefficients, 1.0625 E
    with 9 or 16 (for small suns; see tests/addon/test_world.py).
    """
    import hemishadow

    s = np.asarray(direction, np.float64)
    s = s / np.linalg.norm(s)
    e = np.atleast_1d(np.asarray(irradiance, np.float64))
    h = min(max(float(angle), 0.0), math.pi) / 2
    l = np.arange(bands)
    if h < 1e-6:
        per_band = np.ones(bands)  # L0 sqrt(4pi/(2l+1)) z_l -> 1 (times E)
    else:
        c = math.cos(h)
        legendre = _legendre(c, bands + 1)  # P_0(c) .. P_bands(c)
        integral = np.empty(bands)
        integral[0] = 1 - c
        integral[1:] = (legendre[:bands - 1] - legendre[2:bands + 1]) / (2 * l[1:] + 1)
        # L0 sqrt(4pi/(2l+1)) z_l = L0 sqrt(4pi/(2l+1)) 2pi sqrt((2l+1)/(4pi)) integral = L0 2pi integral
        per_band = 2 * math.pi * integral / (math.pi * math.sin(h) ** 2)
    basis = hemishadow.sh_basis(s[None], bands)[0].astype(np.float64)  # Y_lm(s)
    coefficients = np.repeat(per_band, 2 * l + 1) * basis
    return coefficients[:, None] * e[None, :]


def _legendre(x, count):
    """P_0(x) .. P_{count-1}(x) by Bonnet's recursion."""
    p = np.empty(count)
    p[0] = 1.0
    if count > 1:
        p[1] = x
    for n in range(1, count - 1):
        p[n + 1] = ((2 * n + 1) * x * p[n] - n * p[n - 1]) / (n + 1)
    return p


# ----------------------------------------------------------------------------------------
# The World's node graph


def _upstream(socket):
    """The node feeding `socket` (through reroutes and muted links), or None."""
    seen = 0
    while socket.is_linked and seen < 64:
        link = socket.links[0]
        if link.is_muted or not link.is_valid:
            return None
        node = link.from_node
        if node.type == "REROUTE":
            socket = node.inputs[0]
            seen += 1
            continue
        return node
    return None


def _world_output(tree):
    outputs = [n for n in tree.nodes if n.type == "OUTPUT_WORLD"]
    for node in outputs:
        if node.is_active_output:
            return node
    return outputs[0] if outputs else None


def _find_background(node, depth=0):
    """The first Background shader reachable from `node` (through Mix and Add Shader nodes)."""
    if node is None or depth > 16:
        return None
    if node.type == "BACKGROUND":
        return node
    if node.type in ("MIX_SHADER", "ADD_SHADER"):
        for socket in node.inputs:
            if socket.type == "SHADER":
                found = _find_background(_upstream(socket), depth + 1)
                if found is not None:
                    return found
    return None


def _mapping_rotation(env):
    """Rotation the env node's lookup vector goes through: chained Mapping nodes composed."""
    import hemishadow

    matrix = np.eye(3)
    notes = []
    node = _upstream(env.inputs["Vector"])
    while node is not None and node.type == "MAPPING":
        if node.mute:  # a muted node passes its input through
            node = _upstream(node.inputs["Vector"])
            continue
        rotation = hemishadow.euler_to_matrix(tuple(node.inputs["Rotation"].default_value))
        kind = node.vector_type
        if kind == "TEXTURE":  # the inverse transform
            rotation = rotation.T
        if node.inputs["Rotation"].is_linked:
            notes.append("linked rotation ignored")
        if kind in ("POINT", "TEXTURE"):
            location = node.inputs["Location"]
            if location.is_linked or any(abs(v) > 1e-6 for v in location.default_value):
                notes.append("location ignored")
        if kind != "NORMAL":
            scale = node.inputs["Scale"]
            if scale.is_linked or any(abs(v - 1) > 1e-6 for v in scale.default_value):
                notes.append("scale ignored")
        # The node nearest the texture acts last: lookup = R_near ... R_far d.
        matrix = matrix @ rotation
        node = _upstream(node.inputs["Vector"])
    return matrix, notes


def _world_environment(world):
    """(LightingSource, None) for the World's Environment Texture, or (None, why not)."""
    if world is None:
        return None, "no World"
    # Before Blender 5.0 a World could switch its nodes off; 5.0 always uses them (and
    # deprecates `use_nodes`).
    uses_nodes = bpy.app.version >= (5, 0) or world.use_nodes
    tree = world.node_tree if uses_nodes else None
    if tree is None:
        return None, "the World uses no nodes"
    output = _world_output(tree)
    if output is None:
        return None, "no World Output node"
    background = _find_background(_upstream(output.inputs["Surface"]))
    if background is None:
        return None, "no Background shader"
    env = _upstream(background.inputs["Color"])
    if env is None or env.type != "TEX_ENVIRONMENT":
        return None, "no Environment Texture"
    image = env.image
    if image is None:
        return None, "the Environment Texture has no image"
    if env.projection != "EQUIRECTANGULAR":
        return None, f"{env.projection.lower().replace('_', ' ')} projection unsupported"
    if image.source not in ("FILE", "GENERATED"):
        return None, f"{image.source.lower()} images unsupported"
    path = _exr_path(image)
    if path is None and not _has_pixels(image):
        return None, f"image {image.name!r} has no pixels (missing file?)"
    rotation, notes = _mapping_rotation(env)
    strength = float(background.inputs["Strength"].default_value)
    if background.inputs["Strength"].is_linked:
        notes.append("linked strength ignored")
    label = f"World: {image.name}, strength {strength:g}" + (f" ({', '.join(notes)})" if notes else "")
    return LightingSource("WORLD", label, image=image, path=path, rotation=rotation,
                          scale=np.full(3, strength)), None


def _exr_path(image):
    """The image's EXR file when its pixels can be read from the file itself, else None."""
    if image.source != "FILE" or image.packed_file is not None or image.is_dirty:
        return None
    path = bpy.path.abspath(image.filepath, library=image.library)
    if not path.lower().endswith(".exr") or not os.path.isfile(path):
        return None
    return os.path.normpath(path)


def _has_pixels(image):
    width, height = image.size  # loads the image when needed; (0, 0) when it cannot
    return width > 0 and height > 0


def _builtin_source(name):
    from hemishadow.environment import builtin_hdris, default_hdri

    hdris = builtin_hdris()
    if not hdris:
        return None
    path = hdris.get(name)
    if path is None:
        path = default_hdri()
        name = path.stem
    return LightingSource("BUILTIN", f"Built-in HDRI: {name}", path=str(path))


# ----------------------------------------------------------------------------------------
# Projection, cached


def _projection(source, bands):
    """project_environment of the source's image with its rotation, cached."""
    import hemishadow

    rotation_key = tuple(np.round(np.asarray(source.rotation, np.float64), 7).ravel())
    if source.path is not None:
        stat = os.stat(source.path)
        image_key = ("file", source.path, stat.st_mtime_ns, stat.st_size)
    else:
        image_key = _pixels_key(source.image)
    key = (image_key, rotation_key, bands)
    cached = _cache.get(key)
    if cached is not None:
        _cache.move_to_end(key)
        return cached.copy()
    data = source.path if source.path is not None else _image_pixels(source.image)
    try:
        lighting = hemishadow.project_environment(data, bands, rotation=np.asarray(source.rotation))
    except ValueError:
        if source.path is None or source.image is None:
            raise
        # An EXR that OpenEXR's reader rejects (e.g. multi-part): Blender's pixels instead.
        lighting = hemishadow.project_environment(_image_pixels(source.image), bands,
                                                  rotation=np.asarray(source.rotation))
    _cache[key] = lighting
    while len(_cache) > _CACHE_SIZE:
        _cache.popitem(last=False)
    return lighting.copy()


def _pixels_key(image):
    """Cache key of an image read through its pixels: its identity, size and provenance;
    plus a digest of the pixels when it has unsaved edits (painting), which nothing else
    would reveal."""
    key = ["pixels", image.name_full, tuple(image.size), image.source, image.filepath,
           image.colorspace_settings.name]
    if image.packed_file is not None:
        key.append(("packed", image.packed_file.size))
    if image.source == "GENERATED":
        key.append((image.generated_type, tuple(image.generated_color), image.use_generated_float))
    if image.is_dirty:
        key.append(hashlib.blake2b(_image_pixels(image).tobytes(), digest_size=16).hexdigest())
    return tuple(key)


def _image_pixels(image):
    """The image as float32 (H, W, 3), scene-linear, top row first (as image files store it).

    Blender's `image.pixels` run bottom row first; byte images hold their colour space's
    values (sRGB for ordinary 8-bit files), which are decoded to linear here as Cycles does.
    """
    width, height = image.size
    channels = image.channels
    buffer = np.empty(width * height * channels, np.float32)
    image.pixels.foreach_get(buffer)
    pixels = buffer.reshape(height, width, channels)[::-1]
    if channels >= 3:
        rgb = pixels[..., :3]
    else:
        rgb = np.repeat(pixels[..., :1], 3, axis=2)
    if not image.is_float and image.colorspace_settings.name == "sRGB":
        rgb = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    return np.ascontiguousarray(rgb, dtype=np.float32)


# ----------------------------------------------------------------------------------------
# Sun lamps


def _sun_lamps(scene):
    for obj in scene.objects:
        if obj.type != "LIGHT" or obj.data.type != "SUN" or obj.hide_render:
            continue
        try:
            visible = obj.visible_get()
        except (RuntimeError, TypeError):
            visible = not obj.hide_viewport
        if visible and obj.data.energy > 0:
            yield obj
