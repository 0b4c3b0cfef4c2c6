"""Point, spot and area lamps -> per-vertex SH lobes, and their irradiance through transfer.

A lamp's light arrives at a vertex from a small cone of directions around the lamp: each lamp
becomes, per vertex, a uniform cap (`world.sun_lobe`'s closed form, vectorised) pointing from
the vertex towards the lamp, of the lamp's angular size seen from there, scaled so a surface
facing it gets the irradiance Blender's conventions give (the design notes' "Units"):
- point lamp of power P and radius r: intensity I = P / (4 pi) W/sr, irradiance I / d^2 facing
  it at distance d, a cap of half-angle asin(r / d);
- spot lamp: the point lamp of the same power masked by its cone, Cycles' smoothstep blend:
  smoothstep((cos a - cos(size/2)) / ((1 - cos(size/2)) blend)), a = angle off the -Z axis;
- area lamp of power P and area A (object scale included): a one-sided Lambertian emitter of
  radiance L = P / (pi A) towards its -Z side; seen from the vertex it is a cap of the solid
  angle of a disk with the lamp's projected area (exact on the axis of a disk lamp), radiance L.
A lamp's colour (times its blackbody colour when used), 2^exposure and diffuse factor multiply
its power. The vertex's transfer then gives irradiance T_v . L_v: shadows, softened by the 25
coefficients like everything else.

What cannot be represented is kept, not dropped in silence: `unsupported(scene)` lists it
(nodes, IES, shadows switched off, a spread under 180 degrees, Normalize off) and the lamp is
used without it.
"""

from __future__ import annotations

import math

import numpy as np

from . import evaluated

__all__ = ["Lamp", "scene_lamps", "lamp_irradiance", "unsupported", "lamp_power_color", "visible_lamps", "lamps_key"]

_KINDS = ("POINT", "SPOT", "AREA")


class Lamp:
    """A lamp's parameters in world space, read once from Blender (numpy only afterwards)."""

    __slots__ = ("name", "kind", "position", "axis", "power", "radius", "cos_half", "blend", "area", "edges",
                 "round", "key")

    def __init__(self, name, kind, position, axis, power, radius=0.0, cos_half=-1.0, blend=0.0, area=0.0,
                 edges=None, round_shape=False):
        self.name, self.kind = name, kind
        self.position = np.asarray(position, np.float64)
        self.axis = np.asarray(axis, np.float64)  # the direction it shines along (its -Z)
        self.power = np.asarray(power, np.float64)  # RGB watts, colour and exposure applied
        self.radius, self.cos_half, self.blend, self.area = float(radius), float(cos_half), float(blend), float(area)
        # Area lamps: the world-space vectors along its two sides (full lengths); disk or ellipse.
        self.edges = None if edges is None else np.asarray(edges, np.float64)
        self.round = bool(round_shape)
        self.key = (name, kind, tuple(np.round(self.position, 7)), tuple(np.round(self.axis, 7)),
                    tuple(np.round(self.power, 7)), self.radius, self.cos_half, self.blend, self.area,
                    None if edges is None else tuple(np.round(self.edges, 7).ravel()), self.round)


def lamp_power_color(light) -> np.ndarray:
    """RGB multiplier of a lamp's energy: energy x colour (x blackbody) x 2^exposure x diffuse factor."""
    color = np.array(light.color, np.float64)
    if getattr(light, "use_temperature", False):
        color = color * np.array(light.temperature_color, np.float64)
    exposure = 2.0 ** float(getattr(light, "exposure", 0.0))
    scale = float(light.energy) * exposure * float(getattr(light, "diffuse_factor", 1.0))
    return color * scale


def visible_lamps(scene, kinds):
    """Evaluated lamp objects (see evaluated.py) of the given types that render and are
    visible, with some power."""
    for obj in scene.objects:
        if obj.type != "LIGHT" or obj.data.type not in kinds or obj.hide_render:
            continue
        try:
            visible = obj.visible_get()
        except (RuntimeError, TypeError):
            visible = not obj.hide_viewport
        obj = evaluated.of(obj)
        if visible and obj.data.energy > 0:
            yield obj


#: An area lamp seen from a vertex at distance d under more than about d/4 is split into up
#: to PATCHES x PATCHES patches, each its own lobe: one lobe aimed at the centre misplaces the
#: light of a lamp that looks large from the vertex.
PATCHES = 4


def _area_lamp(obj, position, axis, power):
    """The area lamp as a Lamp (object scale included), radiance P / (pi A); None when flat."""
    light, matrix = obj.data, obj.matrix_world
    w = light.size
    h = light.size if light.shape in ("SQUARE", "DISK") else light.size_y
    round_shape = light.shape in ("DISK", "ELLIPSE")
    rotation_scale = np.array(matrix.to_3x3(), np.float64)
    edges = np.stack([rotation_scale[:, 0] * w, rotation_scale[:, 1] * h])
    area = np.linalg.norm(edges[0]) * np.linalg.norm(edges[1]) * (math.pi / 4 if round_shape else 1.0)
    if not area > 0:
        return None
    return Lamp(obj.name, "AREA", position, axis, power, area=area, edges=edges, round_shape=round_shape)


def _patches(lamp, vertices):
    """The area lamp itself, or its patches when some vertex is close for its size (equal areas;
    a disk's through the concentric map of the square onto the disk)."""
    if lamp.edges is None:
        return [lamp]
    size = max(np.linalg.norm(lamp.edges[0]), np.linalg.norm(lamp.edges[1]))
    nearest = np.sqrt(np.min(np.einsum("ij,ij->i", vertices - lamp.position, vertices - lamp.position)))
    n = int(min(PATCHES, math.ceil(4 * size / max(nearest, 1e-12))))
    if n <= 1:
        return [lamp]
    u = (np.arange(n) + 0.5) / n - 0.5
    gu, gv = (g.ravel() for g in np.meshgrid(u, u, indexing="ij"))
    if lamp.round:
        gu, gv = _concentric(2 * gu, 2 * gv)
        gu, gv = gu / 2, gv / 2
    centres = lamp.position + gu[:, None] * lamp.edges[0] + gv[:, None] * lamp.edges[1]
    share = 1.0 / len(centres)
    return [Lamp(lamp.name, "AREA", c, lamp.axis, lamp.power * share, area=lamp.area * share) for c in centres]


def scene_lamps(scene) -> list[Lamp]:
    """The scene's visible point, spot and area lamps as `Lamp`s."""
    lamps = []
    for obj in visible_lamps(scene, _KINDS):
        light, matrix = obj.data, obj.matrix_world
        position = np.array(matrix.translation, np.float64)
        axis = -np.array(matrix.to_3x3().col[2], np.float64)
        norm = np.linalg.norm(axis)
        if not norm > 0:
            continue
        axis /= norm
        power = lamp_power_color(light)
        if light.type == "AREA":
            area = _area_lamp(obj, position, axis, power)
            if area is not None:
                lamps.append(area)
            continue
        radius = float(light.shadow_soft_size)
        if light.type == "SPOT":
            cos_half = math.cos(min(float(light.spot_size), math.pi) / 2)
            lamps.append(Lamp(obj.name, "SPOT", position, axis, power, radius, cos_half, float(light.spot_blend)))
        else:
            lamps.append(Lamp(obj.name, "POINT", position, axis, power, radius))
    return lamps


def lamps_key(scene) -> str:
    """A string that changes when any point, spot or area lamp does ("" when there are none)."""
    found = scene_lamps(scene)
    return repr(tuple(lamp.key for lamp in found)) if found else ""


def unsupported(scene) -> list[str]:
    """One message per lamp property that the SH lobes do not represent (the lamp is used without it)."""
    notes = []
    for obj in visible_lamps(scene, _KINDS + ("SUN",)):
        light = obj.data
        if _nodes_change_light(light):
            notes.append(f"lamp {obj.name!r}: its nodes (textures, IES, falloff) are ignored")
        if not light.use_shadow:
            notes.append(f"lamp {obj.name!r}: 'Shadow' off is ignored (it casts shadows here)")
        if light.type == "AREA" and light.spread < math.pi - 1e-4:
            notes.append(f"lamp {obj.name!r}: spread below 180 degrees is ignored")
        if light.type != "SUN" and not getattr(light, "normalize", True):
            notes.append(f"lamp {obj.name!r}: 'Normalize' off is ignored")
        if light.type == "SPOT" and getattr(light, "use_square", False):
            notes.append(f"lamp {obj.name!r}: square spot treated as round")
    return notes


def _nodes_change_light(light) -> bool:
    """Whether the lamp's shader nodes change its light. Up to Blender 5.0 a lamp uses nodes
    only with `use_nodes` on; later ones give every lamp a tree (a white Emission of strength
    1 into the Light Output) and always use it (`use_nodes` deprecated: reading it warns).
    That default tree changes nothing, so it is not reported."""
    tree = light.node_tree
    if tree is None or _default_light_tree(tree):
        return False
    use_nodes = type(light).bl_rna.properties["use_nodes"]
    return getattr(use_nodes, "is_deprecated", False) or light.use_nodes


def _default_light_tree(tree) -> bool:
    nodes = {n.bl_idname: n for n in tree.nodes}
    emission = nodes.get("ShaderNodeEmission")
    if len(tree.nodes) != 2 or emission is None or "ShaderNodeOutputLight" not in nodes or len(tree.links) != 1:
        return False
    link = tree.links[0]
    return (link.from_node == emission and link.to_node.bl_idname == "ShaderNodeOutputLight"
            and not any(i.is_linked for i in emission.inputs)
            and tuple(emission.inputs["Color"].default_value) == (1.0, 1.0, 1.0, 1.0)
            and emission.inputs["Strength"].default_value == 1.0)


# ----------------------------------------------------------------------------------------
# The lobes


def _cap_bands(cos_h, bands):
    """Per-band factors (V, bands) of a uniform cap of half-angle h whose facing irradiance is 1:
    2 pi integral_{cos h}^1 P_l / (pi sin^2 h), tending to 1 as h -> 0 (see world.sun_lobe)."""
    c = np.clip(cos_h, -1.0, 1.0)
    p = [np.ones_like(c), c]
    for n in range(1, bands):
        p.append(((2 * n + 1) * c * p[n] - n * p[n - 1]) / (n + 1))
    integral = [1 - c] + [(p[l - 1] - p[l + 1]) / (2 * l + 1) for l in range(1, bands)]
    sin2 = 1 - c * c
    small = sin2 < 1e-10
    factors = np.stack(integral, axis=1) * (2.0 / np.where(small, 1.0, sin2))[:, None]
    factors[small] = 1.0
    return factors


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def _concentric(a, b):
    """Shirley and Chiu's equal-area map of the square [-1, 1]^2 onto the unit disk."""
    wide = np.abs(a) > np.abs(b)
    r = np.where(wide, a, b)
    safe_a = np.where(a == 0, 1.0, a)
    safe_b = np.where(b == 0, 1.0, b)
    phi = np.where(wide, math.pi / 4 * b / safe_a, math.pi / 2 - math.pi / 4 * a / safe_b)
    return r * np.cos(phi), r * np.sin(phi)


def _lobe_inputs(lamp, vertices):
    """(direction towards the lamp (V, 3), facing irradiance per watt (V,), cos of the cap half-angle (V,))."""
    offset = lamp.position[None, :] - vertices
    d2 = np.einsum("ij,ij->i", offset, offset)
    d = np.sqrt(np.maximum(d2, 1e-20))
    s = offset / d[:, None]
    # Angle between the lamp's axis and the lamp -> vertex direction; einsum, as numpy < 2 hands
    # this product to BLAS threads that then spin on the engine's cores (hemishadow.products).
    cos_off_axis = -np.einsum("ij,j->i", s, lamp.axis)
    if lamp.kind == "AREA":
        # Projected area seen from the vertex; a disk of that area on the axis subtends
        # 2 pi (1 - 1/sqrt(1 + A cos/(pi d^2))), exact there and bounded by the hemisphere.
        projected = lamp.area * np.maximum(cos_off_axis, 0.0)
        cos_h = 1.0 / np.sqrt(1.0 + projected / (math.pi * np.maximum(d2, 1e-20)))
        radiance = 1.0 / (math.pi * lamp.area)
        per_watt = np.where(cos_off_axis > 0, radiance * math.pi * (1 - cos_h * cos_h), 0.0)
        return s, per_watt, cos_h
    per_watt = 1.0 / (4 * math.pi * np.maximum(d2, 1e-20))
    if lamp.kind == "SPOT":
        spread = (1.0 - lamp.cos_half) * lamp.blend
        if spread > 0:
            per_watt = per_watt * _smoothstep((cos_off_axis - lamp.cos_half) / spread)
        else:
            per_watt = per_watt * (cos_off_axis > lamp.cos_half)
    sin_h = np.minimum(lamp.radius / d, 1.0)
    return s, per_watt, np.sqrt(1 - sin_h * sin_h)


def lamp_irradiance(transfer, vertices, lamps) -> np.ndarray:
    """Irradiance (V, 3) the lamps give through each vertex's transfer: sum over lamps of
    T_v . L_lamp,v, vectorised over vertices (transfer (V, K), vertices (V, 3) world space)."""
    import hemishadow

    transfer = np.asarray(transfer, np.float32)
    vertices = np.asarray(vertices, np.float64)
    count, k = transfer.shape
    bands = int(round(math.sqrt(k)))
    band_of = np.repeat(np.arange(bands), 2 * np.arange(bands) + 1)
    out = np.zeros((count, 3), np.float64)
    if count == 0:
        return out.astype(np.float32)
    pieces = [p for lamp in lamps for p in (_patches(lamp, vertices) if lamp.kind == "AREA" else [lamp])]
    for lamp in pieces:
        s, per_watt, cos_h = _lobe_inputs(lamp, vertices)
        lit = per_watt > 0
        if lit.all():
            lit = slice(None)  # no copies for the usual case
        elif not lit.any():
            continue
        basis = hemishadow.sh_basis(s[lit].astype(np.float32), bands)
        lobe = _cap_bands(cos_h[lit], bands)[:, band_of] * basis
        scalar = np.einsum("vk,vk->v", transfer[lit], lobe) * per_watt[lit]
        out[lit] += scalar[:, None] * lamp.power[None, :]
    return out.astype(np.float32)
