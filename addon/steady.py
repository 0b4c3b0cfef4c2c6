"""First evaluated positions of subdivided objects that cannot have moved, without asking Blender.

Reading an evaluated mesh from Python (`Object.data` of an evaluated object) makes Blender
finish a Subdivision Surface on the CPU, which it otherwise leaves for drawing: 3.6 ms for the
demo's Suzanne (507 vertices, level 1). And Blender evaluates an object again at every frame
when anything in its stack depends on time, a Collision modifier so that cloth can fall on it
for one, though its geometry cannot change. hemishadow reads every enabled object and every
caster each frame, so a static subdivided collider paid a subdivision per frame, twice over
when it was a caster too.

When an object's stack can only subdivide its own mesh (enabled modifiers: Subdivision Surface
and ones that leave the geometry as it is; no shape keys; no animation on the mesh), its first
V evaluated vertices (the ones hemishadow uses, mesh_io) follow from its mesh and the
modifiers' settings alone. `first_positions` keeps them with a signature of those inputs and
answers from it while the signature holds; any other object is read every time. The mesh
signed is the depsgraph's copy of it (`Mesh.evaluated_get`), what the modifiers were given:
an edit Blender has not evaluated yet (`foreach_set` without `update()` in Blender 4.2) is
signed when Blender evaluates it, not before, so no stale read is ever kept as current.
"""

import numpy as np

from . import mesh_io, staleness

# Modifiers that record the geometry for simulations and pass it on unchanged.
_PASSIVE = {"COLLISION", "SURFACE"}

# Mesh attributes Subdivision Surface reads besides positions and faces.
_CREASES = ("crease_vert", "crease_edge")

#: ID.session_uid of the original object -> (signature, read-only positions (V, 3) float32)
_known: dict[int, tuple] = {}


def first_positions(obj, depsgraph, read):
    """The object's first evaluated positions: `read()` (which may return None: nothing is
    kept), or the last ones read when nothing they depend on changed since."""
    signature = _signature(obj, depsgraph)
    if signature is None:
        return read()
    known = _known.get(obj.session_uid)
    if known is not None and known[0] == signature:
        return known[1]
    positions = read()
    if positions is not None:
        positions = np.array(positions, np.float32)
        positions.flags.writeable = False
        _known[obj.session_uid] = (signature, positions)
    return positions


def forget(alive=None):
    """Drop what is kept: all of it, or that of objects whose session_uid is not in `alive`."""
    for uid in [u for u in _known if alive is None or u not in alive]:
        del _known[uid]


def applies(obj, depsgraph):
    """True when the object's stack only subdivides it (its positions can be kept)."""
    return _subdivisions(obj, depsgraph) is not None


def _subdivisions(obj, depsgraph):
    """The object's enabled Subdivision Surface modifiers (this frame's settings) when its
    stack only subdivides it, else None."""
    if obj.type != "MESH" or obj.mode in ("EDIT", "SCULPT"):  # edits not yet in (or not only in) obj.data
        return None
    if obj.data.shape_keys is not None or obj.data.animation_data is not None:
        return None
    enabled = mesh_io.enabled_modifiers(obj.evaluated_get(depsgraph), depsgraph.mode == "RENDER")
    kinds = {m.type for m in enabled}
    if "SUBSURF" not in kinds or not kinds <= _PASSIVE | {"SUBSURF"}:
        return None
    return [m for m in enabled if m.type == "SUBSURF"]


def _signature(obj, depsgraph):
    """A hash of everything the first evaluated positions depend on, or None when the stack
    may move them (then they are read every time)."""
    subdivisions = _subdivisions(obj, depsgraph)
    if subdivisions is None:
        return None
    mesh = obj.data.evaluated_get(depsgraph)
    settings = [staleness.settings(m) for m in subdivisions]
    return hash((depsgraph.mode, repr(settings), _values(mesh.vertices, "co", 3, np.float32),
                 _values(mesh.loops, "vertex_index", 1, np.int32), _values(mesh.polygons, "loop_total", 1, np.int32),
                 *(_crease(mesh, name) for name in _CREASES)))


def _values(collection, name, width, dtype):
    out = np.empty(len(collection) * width, dtype)
    collection.foreach_get(name, out)
    return out.tobytes()


def _crease(mesh, name):
    attribute = mesh.attributes.get(name)
    if attribute is None or attribute.data_type != "FLOAT":
        return None
    return _values(attribute.data, "value", 1, np.float32)
