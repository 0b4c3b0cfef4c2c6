"""Blender meshes <-> numpy: evaluated positions in, attributes out. No numerical loops here.

Which positions the engine sees (the topology rule). The outputs are point attributes of the
ORIGINAL mesh (`obj.data`), so the engine must see one position per original vertex:
- When the evaluated mesh has the original vertex count (armature, shape keys, cloth and any
  other deforming modifiers), its positions are used with the original triangles.
- When later modifiers add vertices (Subdivision Surface after Armature, the common case),
  Blender cannot evaluate "the stack without them" without changing user data (toggling
  `show_viewport` is an edit the user sees, undoes and saves). But Subdivision Surface,
  Multiresolution, Mirror and Triangulate keep the original vertices first, in order, in their
  result, so the first V evaluated vertices are the deformed original vertices (for
  subdivision: the same vertices moved onto the limit surface, which is where the attribute
  is displayed). The engine computes on those with the original triangles; the attribute is
  written on the original mesh and the later modifiers interpolate it.
- Any other topology-changing modifier (Decimate, Remesh, Boolean, Geometry Nodes, ...) has
  no such mapping: the object is skipped with a message saying which modifier is in the way.

Reading an evaluated mesh makes Blender finish a trailing Subdivision Surface on the CPU; an
object whose stack only subdivides it is read once and kept while nothing it depends on
changes (steady.py), though Blender evaluates it every frame (a Collision modifier does that).

Welding (seams, triangle soups such as fox.glb) is the engine's job: it welds by position.
"""

from typing import NamedTuple

import bpy
import numpy as np

RADIANCE = "hemishadow_radiance"
AO = "hemishadow_ao"
SH_PREFIX = "hemishadow_sh_"
PREFIX = "hemishadow_"

# Modifiers whose result starts with the original vertices, in order (see the module notes).
PREFIX_KEEPING = {"SUBSURF", "MULTIRES", "MIRROR", "TRIANGULATE"}

# Modifiers that only refine the surface: the original vertices come first in their result, on
# the limit surface, at every level (see `smooths_only`).
SMOOTHING = {"SUBSURF", "MULTIRES"}

# Modifiers that only move vertices (Blender's "OnlyDeform" types) or leave geometry alone.
DEFORMING = {
    "ARMATURE", "CAST", "CLOTH", "COLLISION", "CORRECTIVE_SMOOTH", "CURVE", "DATA_TRANSFER", "DISPLACE",
    "DYNAMIC_PAINT", "HOOK", "LAPLACIANDEFORM", "LAPLACIANSMOOTH", "LATTICE", "MESH_CACHE", "MESH_DEFORM",
    "NORMAL_EDIT", "PARTICLE_SYSTEM", "SHRINKWRAP", "SIMPLE_DEFORM", "SMOOTH", "SOFT_BODY", "SURFACE",
    "SURFACE_DEFORM", "UV_PROJECT", "UV_WARP", "VERTEX_WEIGHT_EDIT", "VERTEX_WEIGHT_MIX", "VERTEX_WEIGHT_PROXIMITY",
    "WARP", "WAVE", "WEIGHTED_NORMAL", "VOLUME_DISPLACE",
}


class SkipObject(ValueError):
    """The object cannot be computed now (no faces, Edit Mode, unmappable modifier); the
    message says why, for the status line."""


class TopologyChanged(SkipObject):
    """The evaluated mesh no longer maps onto the original vertices: outputs written before
    describe another surface and must not keep rendering as if current."""


# Object types with geometry that hemishadow refuses, and what to do about it.
NOT_A_MESH = {"CURVE": "curve", "SURFACE": "surface", "META": "metaball", "FONT": "text", "CURVES": "hair curves",
              "POINTCLOUD": "point cloud", "VOLUME": "volume", "GREASEPENCIL": "Grease Pencil"}


def not_a_mesh_message(obj):
    kind = NOT_A_MESH.get(obj.type, obj.type.lower())
    return (f"{obj.name}: a {kind} object is not computed: hemishadow writes its results into a mesh's "
            "attributes; convert it to a mesh (Object > Convert > Mesh) to compute it")


def triangles_of(mesh) -> np.ndarray:
    """Loop triangles of a mesh as uint32 (M, 3) vertex indices."""
    tris = mesh.loop_triangles
    out = np.empty(len(tris) * 3, np.uint32)
    tris.foreach_get("vertices", out)
    return out.reshape(-1, 3)


def positions_of(mesh, count=None) -> np.ndarray:
    """Vertex positions (V, 3) float32 in the mesh's local space; the first `count` only."""
    out = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", out)
    out = out.reshape(-1, 3)
    return out if count is None else out[:count]


def matmul(a, b) -> np.ndarray:
    """a @ b in this thread: numpy's BLAS would leave threads spinning on the cores the
    engine's next solve needs (hemishadow.products)."""
    from hemishadow.products import matmul as product

    return product(a, b)


def to_world(points, matrix) -> np.ndarray:
    m = np.asarray(matrix, np.float32)
    return np.ascontiguousarray(matmul(points, m[:3, :3].T) + m[:3, 3], dtype=np.float32)


def mirrors(matrix) -> bool:
    """True when the matrix turns space inside out (an odd number of negative scales)."""
    return float(np.linalg.det(np.asarray(matrix, np.float64)[:3, :3])) < 0.0


def oriented(triangles, matrix) -> np.ndarray:
    """Triangles wound for positions transformed by `matrix`: a mirroring matrix reverses the
    winding, which would turn the area normals (the engine's surface side) inwards."""
    return np.ascontiguousarray(triangles[:, ::-1]) if mirrors(matrix) else triangles


def check_computable(obj):
    """Raise SkipObject when the object cannot be computed at all."""
    if obj.type != "MESH":
        raise SkipObject(not_a_mesh_message(obj))
    if obj.mode == "EDIT":
        raise SkipObject(f"{obj.name}: skipped while in Edit Mode")
    if len(obj.data.polygons) == 0:
        raise SkipObject(f"{obj.name}: the mesh has no faces, nothing can cast or receive shadows")
    if obj.data.library is not None:
        raise SkipObject(f"{obj.name}: the mesh is linked from a library and cannot take attributes")


def enabled_modifiers(obj, render):
    """The modifiers the viewport (or a render) evaluates."""
    return [mod for mod in obj.modifiers if (mod.show_render if render else mod.show_viewport)]


def _blocking_modifier(obj, render):
    for mod in enabled_modifiers(obj, render):
        if mod.type not in DEFORMING and mod.type not in PREFIX_KEEPING:
            return mod
    return None


def smooths_only(obj, render):
    """True when the object's enabled modifiers deform it and smooth it (Subdivision Surface,
    Multiresolution) and do nothing else, at least one smoothing: its original faces through
    the first evaluated vertices are then the surface it computes on, a coarser version of
    what it draws, the same in the viewport and in renders whatever their levels."""
    enabled = [mod.type for mod in enabled_modifiers(obj, render)]
    return any(t in SMOOTHING for t in enabled) and all(t in SMOOTHING or t in DEFORMING for t in enabled)


def _evaluated_local(obj, depsgraph):
    """(positions (V, 3) in the object's local space, world matrix) of the evaluated mesh on
    its original topology (see the module notes). Raises SkipObject."""
    from . import steady

    check_computable(obj)
    count = len(obj.data.vertices)
    obj_eval = obj.evaluated_get(depsgraph)
    render = depsgraph.mode == "RENDER"

    def read():
        mesh_eval = obj_eval.data
        if len(mesh_eval.vertices) != count:
            blocker = _blocking_modifier(obj, render)
            if blocker is not None or len(mesh_eval.vertices) < count:
                name = f"modifier '{blocker.name}' ({blocker.type})" if blocker else "a modifier"
                raise TopologyChanged(f"{obj.name}: {name} changes the vertices in a way hemishadow cannot map "
                                      "back to the original mesh; move it below the result or apply it")
        return positions_of(mesh_eval, count)

    return steady.first_positions(obj, depsgraph, read), obj_eval.matrix_world


def read_evaluated(obj, depsgraph):
    """(vertices (V, 3) float32 world space, triangles (M, 3) uint32, None) of an object's
    evaluated mesh on its original topology (see the module notes). Raises SkipObject."""
    local, matrix = _evaluated_local(obj, depsgraph)
    return to_world(local, matrix), oriented(triangles_of(obj.data), matrix), None


class Frame(NamedTuple):
    """An object's world matrix split as world = rotation @ (matrix @ local) + offset:
    `rotation` the orthogonal part (a mirror when the object is mirrored), None when there is
    none (then `matrix` is the world matrix and `offset` zero); `matrix` (4, 4) the scale and
    shear, symmetric positive (semi)definite, with no translation."""

    rotation: np.ndarray | None
    matrix: np.ndarray
    offset: np.ndarray


def object_frame(matrix) -> Frame:
    """The polar decomposition of the world matrix. Positions in the frame (`matrix` applied to
    local positions) are the same however the object is moved, turned or mirrored, so the
    engine computes the same transfer for them (and nothing when only that changed), and
    `rotation` turns it into world space: exactly the turned or mirrored result."""
    m = np.asarray(matrix, np.float64)
    u, scales, vt = np.linalg.svd(m[:3, :3])
    rotation = u @ vt
    if np.abs(rotation - np.eye(3)).max() < 1e-6:  # not turned: the world matrix as it is
        return Frame(None, m, np.zeros(3))
    frame = np.eye(4)
    if np.ptp(scales) <= 1e-6 * scales.max():  # a uniform scale: exactly, as turning must not move vertices
        frame[:3, :3] *= np.float32(scales.mean())
    else:
        frame[:3, :3] = rotation.T @ m[:3, :3]
    return Frame(rotation, frame, m[:3, 3].copy())


def frame_to_world(vertices, frame) -> np.ndarray:
    """Positions in an object's frame, back in world space (float32)."""
    if frame.rotation is None:
        return vertices
    return np.ascontiguousarray(matmul(vertices, frame.rotation.T) + frame.offset, dtype=np.float32)


def read_in_frame(obj, depsgraph):
    """(vertices (V, 3) float32 in the object's frame (see `object_frame`), triangles (M, 3)
    uint32, None, Frame): what the live path computes on. The frame never mirrors, so the
    triangles keep their winding."""
    local, matrix = _evaluated_local(obj, depsgraph)
    frame = object_frame(matrix)
    return to_world(local, frame.matrix), triangles_of(obj.data), None, frame


def read_rest(obj, matrix=None):
    """Positions (V, 3) float32 of the original (undeformed) mesh, by default in world space:
    the rest pose the solver builds its hierarchy from, the same whichever frame is computed
    first. Use it with the triangles of `read_evaluated`, which are wound for the object's
    (mirroring or not) matrix, or with `matrix` = the `Frame.matrix` of `read_in_frame`."""
    return to_world(positions_of(obj.data), obj.matrix_world if matrix is None else matrix)


def _attribute(mesh, name, data_type):
    attr = mesh.attributes.get(name)
    if attr is not None and (attr.data_type != data_type or attr.domain != "POINT"):
        mesh.attributes.remove(attr)
        attr = None
    return attr or mesh.attributes.new(name, data_type, "POINT")


def _set_display_color(mesh, name):
    colors = mesh.color_attributes
    if colors.active_color_name != name:
        colors.active_color_name = name
    if colors.default_color_name != name:
        colors.default_color_name = name


def write_outputs(obj, radiance, ao=None, transfer=None):
    """Write per-vertex outputs onto the original mesh `obj.data` (geometry untouched):
    radiance (V, 3) -> FLOAT_COLOR `hemishadow_radiance` (made the active and render color),
    ao (V,) -> FLOAT `hemishadow_ao`, transfer (V, K) -> FLOAT `hemishadow_sh_00` ... `_{K-1}`.
    Missing (None) outputs are left as they are, except AO on a Phong object: AO is defined
    by diffuse transfer (T_0 of a Phong lobe is not an occlusion), so it is never written
    there and one left from a diffuse computation is removed."""
    mesh = obj.data
    if obj.hemishadow.brdf == "PHONG":
        ao = None
        remove_ao(obj)
    rgba = np.ones((len(radiance), 4), np.float32)
    rgba[:, :3] = radiance
    _attribute(mesh, RADIANCE, "FLOAT_COLOR").data.foreach_set("color", rgba.ravel())
    _set_display_color(mesh, RADIANCE)
    if ao is not None:
        _attribute(mesh, AO, "FLOAT").data.foreach_set("value", np.ascontiguousarray(ao, np.float32))
    if transfer is not None:
        columns = np.ascontiguousarray(np.asarray(transfer, np.float32).T)
        for i, column in enumerate(columns):
            _attribute(mesh, f"{SH_PREFIX}{i:02d}", "FLOAT").data.foreach_set("value", column)
    # foreach_set does not tag the mesh: without this, modifiers after the deform ones
    # (Subdivision) and renders would keep showing the previous values.
    mesh.update_tag()


def remove_ao(obj):
    attr = obj.data.attributes.get(AO)
    if attr is not None:
        obj.data.attributes.remove(attr)


def remove_sh_layers(obj, keep=0):
    """Remove transfer layers with index >= keep (after a change of bands, or when not wanted)."""
    attrs = obj.data.attributes
    suffixes = {a.name: a.name[len(SH_PREFIX):] for a in attrs if a.name.startswith(SH_PREFIX)}
    for name in [n for n, s in suffixes.items() if s.isdigit() and int(s) >= keep]:
        attrs.remove(attrs[name])


def clear_outputs(obj):
    """Remove every `hemishadow_` attribute of the object's mesh; nothing else."""
    attrs = obj.data.attributes
    names = [a.name for a in attrs if a.name.startswith(PREFIX)]
    for name in names:
        attrs.remove(attrs[name])
    if names:
        obj.data.update_tag()
    return len(names)
