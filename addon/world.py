"""World / Environment Texture / sun lamps -> lighting SH (uniform over the object).

`scene_lighting(scene, bands)` gives the SH coefficients (bands*bands, 3) of the radiance
arriving at the scene, in the project's conventions (Blender world space, +Z up; real
orthonormal SH, index l*(l+1)+m; see the design notes): irradiance on a receiver with transfer
vector T is T . L, as `hemishadow.shade` computes it.

The projection of an environment image is the expensive part (about 0.1 s for a 1k map), so it
is cached per image (file path and modification time, or name, size and pixels), rotation and
band count; intensity, the extra rotation and sun lamps are applied on top, so changing those
re-shades at once.

Which World setups take which path (`lighting_source`):
- an Environment Texture (through Mapping rotations only) straight into the Background that
  feeds the World Output: projected from the image itself ('WORLD', the fast path);
- a Background with a plain colour and strength: a uniform sky, exactly ('WORLD_COLOR');
- anything else (Sky Texture, gradients, mixes, groups, Light Path tricks, Mapping location or
  scale, linked strength, animation): Cycles renders the World and that is projected
  ('WORLD_RENDER', world_render.py). Inside handlers nothing is rendered: a missing
  projection is scheduled for a timer, the nearest one there is stands in meanwhile, and
  `notes(scene)` says so;
- no World at all: the built-in HDRI, and `notes(scene)` says so.
Point, spot and area lamps vary over the object: lamps.py.
"""

from __future__ import annotations

import collections
import dataclasses
import hashlib
import math
import os

import bpy
import numpy as np

from . import evaluated, lamps, world_render

__all__ = ["LightingSource", "lighting_source", "scene_lighting", "sun_lobe", "clear_cache", "notes"]

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

    kind: 'WORLD' (the World's Environment Texture), 'WORLD_COLOR' (its plain Background colour),
    'WORLD_RENDER' (the World rendered by Cycles), 'BUILTIN' (a built-in HDRI) or 'UNIFORM'.
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
    world: object = None
    note: str = ""  # something the user must know (fallback, pending render), else ""


#: scene name -> what the last `scene_lighting` had to tell (see `notes`).
_notes: dict[str, list[str]] = {}


def clear_cache() -> None:
    """Forget every cached projection (the next `scene_lighting` projects again)."""
    _cache.clear()
    world_render.clear()


def notes(scene) -> list[str]:
    """Messages about the scene's lighting for the status bar and operator reports: a
    fallback, a World not rendered yet, lamp features that are not represented."""
    return list(_notes.get(scene.name, [])) + lamps.unsupported(scene)


def _settings_value(settings, name):
    return getattr(settings, name, DEFAULTS[name]) if settings is not None else DEFAULTS[name]


def scene_lighting(scene, bands=5, settings=None) -> np.ndarray:
    """Lighting SH of the scene: float32 (bands*bands, 3), radiance coefficients.

    Environment (radiance, per `lighting_source`): what the World emits (see the module notes:
    an Environment Texture or a plain colour directly, any other node setup through a Cycles
    render), the built-in HDRI named by `hdri` when there is no World or when asked, else a
    uniform sky of radiance `uniform_color` (band 0 only: L_00 = sqrt(4 pi) c, so an open
    surface gets irradiance pi c). What the user must know about it goes to `notes(scene)`.
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
    if source.kind in ("UNIFORM", "WORLD_COLOR"):
        lighting = np.zeros((bands * bands, 3), np.float64)
        lighting[0] = math.sqrt(4 * math.pi) * source.scale
    elif source.kind == "WORLD_RENDER":
        lighting, note = _rendered(scene, source.world, bands)
        if note:
            source.note = note
    else:
        lighting = _projection(source, bands).astype(np.float64) * source.scale
    lighting *= float(_settings_value(settings, "intensity"))
    angle = float(_settings_value(settings, "rotation"))
    if angle:
        lighting = hemishadow.rotate_sh(lighting, hemishadow.rotation_matrix((0, 0, 1), angle)).astype(np.float64)
    if _settings_value(settings, "use_sun_lamps"):
        for obj in lamps.visible_lamps(scene, ("SUN",)):
            direction = np.array(obj.matrix_world.to_3x3().col[2], np.float64)
            if not np.linalg.norm(direction) > 0:
                continue
            lighting += sun_lobe(direction, lamps.lamp_power_color(obj.data), float(obj.data.angle), bands)
    _notes[scene.name] = [source.note] if source.note else []
    return np.ascontiguousarray(lighting, dtype=np.float32)


def _rendered(scene, world, bands):
    """(the World's rendered projection at this frame, note): rendered now when allowed, else
    scheduled for a timer with the nearest projection (or darkness) meanwhile."""
    frame = scene.frame_current
    world = world.original
    found = world_render.cached(world, frame)
    if found is not None:
        return found[: bands * bands], ""
    if world_render.can_render():
        try:
            return world_render.render_projection(world, frame)[: bands * bands], ""
        except (RuntimeError, ValueError, OSError) as error:
            note = f"World {world.name!r} could not be rendered for lighting: {error}"
    else:
        world_render.schedule(scene, _projection_ready)
        animated = " (animated World: use Precompute World Lighting before rendering)" \
            if world_render.is_animated(world) else ""
        note = f"World {world.name!r} not rendered for frame {frame} yet{animated}"
    found = world_render.nearest(world, frame)
    if found is None:
        return np.zeros((bands * bands, 3)), note + ": no World light meanwhile"
    return found[: bands * bands], note + ": its nearest projection meanwhile"


def _projection_ready(scene, remaining):
    """Timer callback: a new World projection is cached; re-shade the live objects with it."""
    from . import handlers

    handlers.reshade_live(scene)
    if remaining:
        print(f"hemishadow: World lighting: {remaining} frames left to render")


def lighting_source(scene, settings=None) -> LightingSource:
    """The environment the settings pick, with its fallbacks (see `scene_lighting`)."""
    if settings is None:
        settings = getattr(scene, "hemishadow", None)
    kind = _settings_value(settings, "lighting_source")
    fallback_note = ""
    if kind == "WORLD":
        if scene.world is not None:
            return _world_source(evaluated.of(scene.world))
        fallback_note = " (no World)"
    if kind in ("WORLD", "BUILTIN"):
        builtin = _builtin_source(_settings_value(settings, "hdri"))
        if builtin is not None:
            builtin.label += fallback_note
            if fallback_note:
                builtin.note = f"the scene has no World: lit by the built-in HDRI '{os.path.basename(builtin.path)}'"
            return builtin
        fallback_note += " (no built-in HDRI found)"
    color = np.array(_settings_value(settings, "uniform_color"), np.float64)
    source = LightingSource("UNIFORM", f"Uniform sky{fallback_note}", scale=color)
    if fallback_note:
        source.note = f"lit by a uniform sky{fallback_note}"
    return source


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
            notes.append("linked rotation")
        if kind in ("POINT", "TEXTURE"):
            location = node.inputs["Location"]
            if location.is_linked or any(abs(v) > 1e-6 for v in location.default_value):
                notes.append("Mapping location")
        if kind != "NORMAL":
            scale = node.inputs["Scale"]
            if scale.is_linked or any(abs(v - 1) > 1e-6 for v in scale.default_value):
                notes.append("Mapping scale")
        # The node nearest the texture acts last: lookup = R_near ... R_far d.
        matrix = matrix @ rotation
        node = _upstream(node.inputs["Vector"])
    if node is not None and node.type != "TEX_COORD":
        notes.append(f"{node.name} before the texture")
    return matrix, notes


def _world_source(world):
    """The World's LightingSource: the fast paths when they are exact, else a Cycles render."""
    found, why = _world_environment(world)
    if found is not None:
        return found
    return LightingSource("WORLD_RENDER", f"World: {world.name}, rendered by Cycles ({why})", world=world)


def needs_render(world) -> bool:
    """True when the World takes no fast path: its lighting comes from a Cycles render."""
    return _world_environment(world)[0] is None


def _plain_background(world):
    """(the Background feeding the World Output directly, or None, why not)."""
    tree = world.node_tree
    output = _world_output(tree) if tree is not None else None
    if output is None:
        return None, "no World Output node"
    background = _upstream(output.inputs["Surface"])
    if background is None or background.type != "BACKGROUND" or background.mute:
        return None, "not a plain Background shader"
    if background.inputs["Strength"].is_linked:
        return None, "linked strength"
    return background, None


def _world_environment(world):
    """(LightingSource of a fast path, None), or (None, why the World must be rendered)."""
    if bpy.app.version < (5, 0) and not world.use_nodes:  # 5.0 always uses the nodes
        color = np.array(world.color, np.float64)
        return LightingSource("WORLD_COLOR", f"World: colour {tuple(np.round(color, 3))}", scale=color,
                              world=world), None
    background, why = _plain_background(world)
    if background is None:
        return None, why
    strength = float(background.inputs["Strength"].default_value)
    color_input = background.inputs["Color"]
    if not color_input.is_linked:
        color = np.array(color_input.default_value[:3], np.float64)
        return LightingSource("WORLD_COLOR", f"World: colour ({', '.join(f'{c:.3g}' for c in color)}), "
                                             f"strength {strength:g}", scale=color * strength, world=world), None
    env = _upstream(color_input)
    if env is None or env.type != "TEX_ENVIRONMENT":
        return None, "not an Environment Texture"
    image = env.image
    if image is None:
        return None, "the Environment Texture has no image"
    if env.projection != "EQUIRECTANGULAR":
        return None, f"{env.projection.lower().replace('_', ' ')} projection"
    if image.source not in ("FILE", "GENERATED"):
        return None, f"{image.source.lower()} image"
    path = _exr_path(image)
    if path is None and not _has_pixels(image):
        return None, f"image {image.name!r} has no pixels (missing file?)"
    rotation, notes = _mapping_rotation(env)
    if notes:
        return None, ", ".join(notes)
    label = f"World: {image.name}, strength {strength:g}"
    return LightingSource("WORLD", label, image=image, path=path, rotation=rotation,
                          scale=np.full(3, strength), world=world), None


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
