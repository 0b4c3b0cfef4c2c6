"""What a bake was made from, so that a cache whose animation changed is never served.

A bake cache (cache.py) is only right while the evaluated geometry of every cached frame is
what it was at the bake. Two records are stored with it, because neither alone is enough:

- `inputs(obj)`: digests of what drives the evaluated geometry and can be read without
  evaluating a frame, per object the cached one depends on (itself, its parents, the objects
  its modifiers and constraints point to, the colliders and force fields of its simulations)
  and per part: keyframes (actions, NLA), drivers, constraints, modifiers, simulation settings,
  the armature's bones and pose, shape keys. Properties that animation or drivers write are
  left out (their current value follows the frame; their curves are hashed instead). Cheap
  enough to compare whenever a cached frame is served, and at playback and render start,
  before any frame is evaluated: a key changed at frame 50 is caught at frame 1.
- `fingerprint(vertices)`: per frame, eight random-sign sums of the evaluated world positions
  and their bounding box. It catches what the digests cannot see (vertex weights, textures of
  a Displace modifier, Geometry Nodes inputs, a moved object, a simulation that re-ran
  differently) on the frame being served, with the positions Blender already evaluated.
  Any vertex that moved by more than `TOLERANCE` of the object's size changes at least one
  sum by that much.
"""

from __future__ import annotations

import functools
import hashlib

import numpy as np

import bpy

from . import mesh_io

__all__ = ["TOLERANCE", "changed_inputs", "evaluated_positions", "fingerprint", "fingerprint_mismatch", "inputs",
           "settings"]

#: A vertex that moved by more than this fraction of the object's bounding-box diagonal makes
#: the cache stale: well below what shading can show, well above float noise.
TOLERANCE = 1e-4

_SUMS = 8
_MAX_DEPENDENCIES = 64

# Properties that say nothing about the evaluated geometry (UI state, runtime results, names;
# a renamed modifier still deforms the same), or are handled apart (point caches).
_SKIP = {
    "rna_type", "name", "show_expanded", "show_in_editmode", "show_on_cage", "is_active", "persistent_uid",
    "use_apply_on_spline", "solver_result", "point_cache", "is_override_data_editable", "active",
}

#: Modifier settings that are the simulation's, reported as such.
_SIMULATION_STRUCTS = {"settings", "collision_settings"}
_SIMULATIONS = {"CLOTH", "SOFT_BODY", "COLLISION", "DYNAMIC_PAINT", "PARTICLE_SYSTEM", "FLUID"}


# ---------------------------------------------------------------------------------------
# Evaluated positions

def evaluated_positions(obj, depsgraph) -> np.ndarray | None:
    """World positions (V, 3) float32 of the object's first V evaluated vertices (V = the
    original count, as mesh_io.read_evaluated uses them), or None when there are fewer."""
    from . import steady

    count = len(obj.data.vertices)
    obj_eval = obj.evaluated_get(depsgraph)

    def read():
        return mesh_io.positions_of(obj_eval.data, count) if len(obj_eval.data.vertices) >= count else None

    local = steady.first_positions(obj, depsgraph, read)
    return None if local is None else mesh_io.to_world(local, obj_eval.matrix_world)


@functools.lru_cache(maxsize=4)
def _signs(count: int) -> np.ndarray:
    rng = np.random.default_rng(count)
    return rng.integers(0, 2, (_SUMS, count)).astype(np.float64) * 2.0 - 1.0


def random_signs(count: int) -> np.ndarray:
    """(8, count) of +-1, the same for the same count: sums that any one changed row shows in."""
    return _signs(count)


def fingerprint(vertices: np.ndarray, eye=None) -> np.ndarray:
    """(_SUMS + 2 [+ 1], 3) float64: random-sign sums of the positions, their minimum and
    maximum, and the camera position when the shading depends on it (Phong)."""
    points = np.asarray(vertices, np.float64).reshape(-1, 3)
    rows = [mesh_io.matmul(_signs(len(points)), points), points.min(axis=0, keepdims=True), points.max(axis=0, keepdims=True)]
    if eye is not None:
        rows.append(np.asarray(eye, np.float64).reshape(1, 3))
    return np.concatenate(rows)


def fingerprint_mismatch(stored: np.ndarray, current: np.ndarray) -> float | None:
    """None when the fingerprints agree; else their largest difference, in units of the
    object's size (the bake's bounding-box diagonal): a bound from below on how far the
    vertex that moved most has moved."""
    stored, current = np.asarray(stored, np.float64), np.asarray(current, np.float64)
    if stored.shape != current.shape:
        return float("inf")
    size = max(float(np.linalg.norm(stored[_SUMS + 1] - stored[_SUMS])), 1e-30)
    difference = float(np.abs(stored - current).max()) / size
    return difference if difference > TOLERANCE else None


# ---------------------------------------------------------------------------------------
# Input digests

def inputs(obj, scene) -> dict[str, str]:
    """{"<object>/<part>": digest} for the object and everything its geometry depends on. The
    object itself is "" (renaming it keeps its cache), the others go by name."""
    found = {}
    for dependency in _dependencies(obj, scene):
        name = "" if dependency == obj else dependency.name
        for part, values in _parts(dependency, scene).items():
            if values:
                found[f"{name}/{part}"] = _digest(values)
    return found


def changed_inputs(stored: dict, current: dict, name: str = "") -> str | None:
    """None when equal; else a sentence saying what changed, for the status line (`name`: the
    cached object's)."""
    if stored == current:
        return None
    for key in sorted(set(stored) | set(current)):
        if stored.get(key) != current.get(key):
            owner, part = key.rsplit("/", 1)
            owner = owner or name
            if key not in stored:
                return f"'{owner}' has new {part} since the bake"
            if key not in current:
                return f"the {part} of '{owner}' were removed since the bake"
            return f"the {part} of '{owner}' changed since the bake"
    return "the animation changed since the bake"


def _digest(values) -> str:
    digest = hashlib.blake2b(digest_size=12)
    for value in values:
        digest.update(value if isinstance(value, bytes) else repr(value).encode())
        digest.update(b"\x00")   # "ab", "c" is not "a", "bc"
    return digest.hexdigest()


def _dependencies(obj, scene) -> list:
    """The object, then what it depends on: parents, Object pointers of modifiers and
    constraints (also of the pose bones), driver targets, and for simulations the scene's
    colliders and force fields."""
    found, todo = {}, [obj]
    while todo and len(found) < _MAX_DEPENDENCIES:
        current = todo.pop(0)
        if not isinstance(current, bpy.types.Object) or current.name in found:
            continue
        found[current.name] = current
        todo.append(current.parent)
        for struct in _constraints(current) + list(current.modifiers):
            todo.extend(_object_pointers(struct))
        for variable in _driver_variables(current):
            todo.extend(target.id for target in variable.targets)
        if any(m.type in ("CLOTH", "SOFT_BODY", "DYNAMIC_PAINT") for m in current.modifiers):
            todo.extend(o for o in scene.objects
                        if any(m.type == "COLLISION" for m in o.modifiers) or (o.field and o.field.type != "NONE"))
    return list(found.values())


def _constraints(obj) -> list:
    found = list(obj.constraints)
    if obj.pose is not None:
        for bone in obj.pose.bones:
            found.extend(bone.constraints)
    return found


def _object_pointers(struct) -> list:
    return [getattr(struct, p.identifier) for p in struct.bl_rna.properties
            if p.type == "POINTER" and p.fixed_type.identifier == "Object"]


def _anim_ids(obj) -> list:
    """The object and the data blocks whose animation moves its geometry."""
    ids = [obj]
    if obj.data is not None:
        ids.append(obj.data)
        keys = getattr(obj.data, "shape_keys", None)
        if keys is not None:
            ids.append(keys)
    return ids


def _driver_variables(obj) -> list:
    variables = []
    for owner in _anim_ids(obj):
        animation = getattr(owner, "animation_data", None)
        if animation is not None:
            for curve in animation.drivers:
                variables.extend(curve.driver.variables)
    return variables


def _parts(obj, scene) -> dict[str, list]:
    """Per part, the values to hash."""
    animated = _animated_paths(obj)
    parts = {"keyframes": [], "drivers": [], "constraints": [], "modifiers": [], "simulation": [],
             "bones": [], "shape keys": [], "parenting": []}
    for owner in _anim_ids(obj):
        animation = getattr(owner, "animation_data", None)
        if animation is not None:
            parts["keyframes"] += _action_values(animation)
            parts["drivers"] += [v for curve in animation.drivers for v in _driver_values(curve)]
    for constraint in _constraints(obj):
        parts["constraints"] += [constraint.path_from_id(), constraint.type]
        parts["constraints"] += _struct_values(constraint, constraint.path_from_id(), animated["object"])
    for modifier in obj.modifiers:
        path = modifier.path_from_id()
        parts["modifiers"] += [path, modifier.type]
        parts["modifiers"] += _struct_values(modifier, path, animated["object"], skip=_SIMULATION_STRUCTS)
        if modifier.type == "NODES":
            parts["modifiers"] += _node_inputs(modifier)
        if modifier.type in _SIMULATIONS:
            parts["simulation"] += _simulation_values(modifier, path, animated["object"], scene)
    if any(m.type == "COLLISION" for m in obj.modifiers) and obj.collision is not None:
        parts["simulation"] += _struct_values(obj.collision, "collision", animated["object"])
    if obj.field is not None and obj.field.type != "NONE":
        parts["simulation"] += _struct_values(obj.field, "field", animated["object"])
    if obj.type == "ARMATURE":
        parts["bones"] += _bone_values(obj, animated["object"])
    keys = getattr(obj.data, "shape_keys", None)
    if keys is not None:
        parts["shape keys"] += _shape_key_values(keys, animated.get("keys", set()))
    parts["parenting"] += [obj.parent.name if obj.parent else None, obj.parent_type, obj.parent_bone,
                           _floats(obj.matrix_parent_inverse)]
    return parts


# -- animation ------------------------------------------------------------------------------

def _channelbags(action) -> list:
    """Every channel bag of a layered action (Blender 4.4+), all slots."""
    return [bag for layer in action.layers for strip in layer.strips for bag in getattr(strip, "channelbags", ())]


def _action_fcurves(action) -> list:
    if bpy.app.version < (4, 4):  # before layered actions, an Action holds its F-Curves
        return list(action.fcurves)
    return [curve for bag in _channelbags(action) for curve in bag.fcurves]


def _action_values(animation) -> list:
    values = []
    actions = [animation.action] if animation.action is not None else []
    slot = getattr(animation, "action_slot", None)  # Blender 4.4+
    values += [animation.action.name if animation.action else None, slot.identifier if slot else None,
               animation.action_extrapolation, animation.action_blend_type, animation.action_influence,
               animation.use_nla]
    for track in animation.nla_tracks:
        values += [track.name, track.mute, track.is_solo]
        for strip in track.strips:
            values += _struct_values(strip, "strip", set())
            if strip.action is not None:
                actions.append(strip.action)
    for action in dict.fromkeys(actions):   # once each, in order
        values += [action.name, action.use_cyclic, action.use_frame_range, tuple(action.frame_range)]
        values += [v for curve in _action_fcurves(action) for v in _fcurve_values(curve)]
    return values


def _fcurve_values(curve) -> list:
    points = curve.keyframe_points
    count = len(points)
    values = [curve.data_path, curve.array_index, curve.mute, curve.extrapolation, count]
    for name, width, kind in (("co", 2, np.float32), ("handle_left", 2, np.float32), ("handle_right", 2, np.float32),
                              ("interpolation", 1, np.int32), ("easing", 1, np.int32)):
        buffer = np.empty(count * width, kind)
        points.foreach_get(name, buffer)
        values.append(buffer.tobytes())
    for modifier in curve.modifiers:
        values += [modifier.type] + _struct_values(modifier, "modifier", set())
    return values


def _driver_values(curve) -> list:
    driver = curve.driver
    values = _fcurve_values(curve) + [driver.type, driver.expression, driver.use_self, driver.is_valid]
    for variable in driver.variables:
        values += [variable.name, variable.type]
        for target in variable.targets:
            values += [target.id.name if target.id else None, target.data_path, target.bone_target,
                       target.transform_type, target.transform_space, target.rotation_mode]
    return values


def _animated_paths(obj) -> dict[str, set]:
    """Data paths written by animation or drivers, per role: "object", "data", "keys"."""
    found = {}
    for role, owner in zip(("object", "data", "keys"), _anim_ids(obj)):
        paths = set()
        animation = getattr(owner, "animation_data", None)
        if animation is not None:
            actions = [animation.action] + [s.action for t in animation.nla_tracks for s in t.strips]
            for action in (a for a in actions if a is not None):
                paths.update(curve.data_path for curve in _action_fcurves(action))
            paths.update(curve.data_path for curve in animation.drivers)
        found[role] = paths
    return found


# -- settings ---------------------------------------------------------------------------------

def _floats(value) -> bytes:
    return np.asarray(value, np.float32).tobytes()


def settings(struct) -> list:
    """(name, value) of a struct's settings, as the digests read them (none left out as animated)."""
    return _struct_values(struct, "", set())


def _struct_values(struct, path: str, animated: set, *, skip=frozenset(), depth=0) -> list:
    """(name, value) of a struct's settings, recursing into nested settings (cloth settings,
    effector weights); ID pointers by name. Read-only runtime values, UI state and animated
    properties (`path.name` in `animated`) are left out."""
    values = []
    for prop in struct.bl_rna.properties:
        name = prop.identifier
        if name in _SKIP or name in skip or f"{path}.{name}" in animated:
            continue
        try:
            value = getattr(struct, name)
        except (AttributeError, RuntimeError):
            continue
        if prop.type == "POINTER":
            if isinstance(value, bpy.types.ID) or value is None:
                values.append((name, getattr(value, "name", None)))
            elif depth < 2:
                values += _struct_values(value, f"{path}.{name}", animated, depth=depth + 1)
        elif prop.type == "COLLECTION" or (prop.is_readonly and name != "type"):
            continue
        elif prop.type == "ENUM" and prop.is_enum_flag:
            values.append((name, tuple(sorted(value))))
        elif prop.type in ("FLOAT", "INT", "BOOLEAN") and getattr(prop, "array_length", 0):
            values.append((name, _floats(value)))
        else:
            values.append((name, value))
    return values


def _node_inputs(modifier) -> list:
    """A Geometry Nodes modifier's inputs, stored as ID properties on it."""
    values = []
    for key in sorted(modifier.keys()):
        value = modifier[key]
        if isinstance(value, bpy.types.ID):
            value = value.name
        elif hasattr(value, "to_list"):
            value = value.to_list()
        elif hasattr(value, "to_dict"):
            value = value.to_dict()
        values.append((key, repr(value)))
    return values


def _simulation_values(modifier, path: str, animated: set, scene) -> list:
    values = []
    for name in _SIMULATION_STRUCTS:
        nested = getattr(modifier, name, None)
        if nested is not None:
            values += _struct_values(nested, f"{path}.{name}", animated)
    cache = getattr(modifier, "point_cache", None)
    if cache is not None:
        values += [cache.frame_start, cache.frame_end, cache.frame_step]
    values += [_floats(scene.gravity), scene.use_gravity, scene.render.fps, scene.render.fps_base]
    return values


def _bone_values(obj, animated_pose: set) -> list:
    """Rest pose of the armature's bones, pose-position mode, and the pose transforms that no
    animation writes (a posed but unkeyed bone)."""
    armature = obj.data
    values = [armature.pose_position]
    for bone in armature.bones:
        values += [bone.name, bone.parent.name if bone.parent else None, _floats(bone.matrix_local),
                   bone.use_deform, bone.envelope_distance, bone.envelope_weight, bone.head_radius,
                   bone.tail_radius, bone.bbone_segments, bone.use_inherit_rotation, bone.inherit_scale,
                   bone.use_local_location, bone.use_connect, bone.length]
    for bone in obj.pose.bones:
        path = bone.path_from_id()
        for name in ("location", "rotation_quaternion", "rotation_euler", "rotation_axis_angle", "scale",
                     "rotation_mode"):
            if f"{path}.{name}" not in animated_pose:
                value = getattr(bone, name)
                values.append(value if isinstance(value, str) else _floats(value))
    return values


def _shape_key_values(keys, animated: set) -> list:
    values = [keys.use_relative, keys.reference_key.name if keys.reference_key else None]
    if not keys.use_relative and "eval_time" not in animated:
        values.append(keys.eval_time)
    for block in keys.key_blocks:
        path = block.path_from_id()
        coordinates = np.empty(len(block.data) * 3, np.float32)
        block.data.foreach_get("co", coordinates)
        values += [block.name, block.mute, block.slider_min, block.slider_max, block.vertex_group,
                   block.relative_key.name, block.interpolation, coordinates.tobytes()]
        if f"{path}.value" not in animated:
            values.append(block.value)
    return values
