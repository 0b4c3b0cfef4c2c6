"""Which objects are computed, and what the others show.

- Linked duplicates share one mesh, hence one set of attributes: only one result can be shown.
  It is computed for the mesh's *owner*, the first enabled user by name (when no user is
  enabled, the first by name of the objects asked for), so the result does not depend on
  which object happened to be computed last. The other users show the owner's result (its
  pose, and its orientation under the lighting); their status says so, and
  `hemishadow.make_single_user` gives them meshes of their own when the user asks.
- Instances (collection instances, geometry-nodes instances) draw the source object's mesh,
  attributes included: they show the source's result, computed in the source's own place and
  pose. Enabled sources that are not in the scene are not computed, and are reported.
- Objects that are not meshes (curves, text, metaballs, surfaces) are refused with a message:
  their evaluated mesh is rebuilt on every evaluation and has nowhere to keep attributes.

Scanning the scene's objects is skipped when no mesh asked for has another user, so the
per-frame path costs nothing for scenes without linked duplicates.
"""

from . import mesh_io

_MAX_NAMES = 3


def _mesh_users(mesh):
    return mesh.users - int(mesh.use_fake_user)


def shared_users(scene, objects) -> dict[int, list]:
    """{mesh session_uid: the scene's mesh objects using it, by name} for the meshes of
    `objects` that more than one scene object uses."""
    wanted = {o.data.session_uid for o in objects if o.type == "MESH" and _mesh_users(o.data) > 1}
    if not wanted:
        return {}
    users = {}
    for obj in scene.objects:
        if obj.type == "MESH" and obj.data.session_uid in wanted:
            users.setdefault(obj.data.session_uid, []).append(obj)
    return {uid: sorted(group, key=lambda o: o.name) for uid, group in users.items() if len(group) > 1}


def owner(obj, shared, asked=()):
    """The object whose result `obj`'s mesh shows (`obj` itself when it has the mesh alone)."""
    users = shared.get(obj.data.session_uid)
    if not users:
        return obj
    enabled = [u for u in users if u.hemishadow.enabled]
    if enabled:
        return enabled[0]
    asked_uids = {a.session_uid for a in asked}
    return next((u for u in users if u.session_uid in asked_uids), obj)


def owners(scene, objects):
    """(objects to compute: one per mesh, in the order asked; {name: note} of the objects
    asked for that show another object's result instead)."""
    meshes = [o for o in objects if o.type == "MESH"]
    shared = shared_users(scene, meshes)
    computed, seen, notes = [], set(), {}
    for obj in meshes:
        chosen = owner(obj, shared, meshes)
        if chosen.session_uid != obj.session_uid:
            notes[obj.name] = follower_status(obj, chosen)
        if chosen.session_uid not in seen:
            seen.add(chosen.session_uid)
            computed.append(chosen)
    return computed, notes


def _names(objects):
    return _quoted([o.name for o in objects])


def _quoted(names):
    more = len(names) - _MAX_NAMES
    names = [f"'{n}'" for n in names[:_MAX_NAMES]]
    return ", ".join(names) + (f" and {more} more" if more > 0 else "")


def follower_status(obj, chosen):
    return (f"{obj.name}: shows the result of '{chosen.name}', which shares its mesh '{obj.data.name}' "
            f"(computed in the pose and orientation of '{chosen.name}'); click Make Single User to compute it on its own")


def owner_note(obj, shared):
    """Status suffix of an owner naming the objects showing its result ('' when none)."""
    others = [u for u in shared.get(obj.data.session_uid, ()) if u.session_uid != obj.session_uid]
    if not others:
        return ""
    return f"; mesh '{obj.data.name}' shared with {_names(others)}: they show this result"


def sharing_warning(obj, shared):
    """One line for an operator report on a computed owner of a shared mesh, or None."""
    users = shared.get(obj.data.session_uid)
    if not users:
        return None
    others = [u for u in users if u.session_uid != obj.session_uid]
    return (f"mesh '{obj.data.name}' is shared by {_names(users)}: computed once, for '{obj.name}'; "
            f"{_names(others)} show its result (Make Single User computes each)")


def refused(scene):
    """{name: message} of enabled objects that are not meshes."""
    return {o.name: mesh_io.not_a_mesh_message(o) for o in scene.objects
            if o.type != "MESH" and o.hemishadow.enabled}


def _hidden_enabled(scene):
    """Enabled mesh objects that are not drawn themselves: outside the scene, or hidden or
    excluded in the view layer. Only these can be visible through instances alone."""
    import bpy

    in_scene = {o.session_uid for o in scene.objects}
    return {o.session_uid: o for o in bpy.data.objects if o.type == "MESH" and o.hemishadow.enabled
            and (o.session_uid not in in_scene or not o.visible_get())}


def instance_notes(scene, depsgraph) -> dict[str, tuple[bool, str]]:
    """{name: (computed, note)} of enabled mesh objects visible only through instances
    (collection instances, geometry nodes, particles): whether they are computed (they are
    when in the scene) and what the instances show. Walks the instances only when such an
    object exists, since there can be millions."""
    hidden = _hidden_enabled(scene)
    if not hidden:
        return {}
    instancers = {}
    for instance in depsgraph.object_instances:
        if instance.is_instance and instance.object is not None:
            uid = instance.object.original.session_uid
            if uid in hidden:
                parent = instance.parent.original.name if instance.parent else "?"
                instancers.setdefault(uid, set()).add(parent)
    in_scene = {o.session_uid for o in scene.objects}
    notes = {}
    for uid, parents in instancers.items():
        source, by = hidden[uid], _quoted(sorted(parents))
        if uid not in in_scene:
            notes[source.name] = (False, f"enabled but not in scene '{scene.name}', only instanced (by {by}): not "
                                         "computed; link it into the scene (an excluded collection will do) to "
                                         "compute it")
        else:
            notes[source.name] = (True, f"visible only through instances (by {by}): they show its result, computed "
                                        "in its own place and pose")
    return notes


def make_single_user(scene, obj):
    """Give every enabled object sharing `obj`'s mesh except its owner (and `obj` itself when
    it is not the owner) a copy of the mesh; returns the objects that got one. The copies'
    hemishadow outputs are removed: they were the owner's."""
    shared = shared_users(scene, [obj])
    users = shared.get(obj.data.session_uid, [])
    if not users:
        return []
    keep = owner(obj, shared, [obj])
    changed = [u for u in users
               if u.session_uid != keep.session_uid and (u.hemishadow.enabled or u.session_uid == obj.session_uid)]
    for user in changed:
        user.data = user.data.copy()
        mesh_io.clear_outputs(user)
    return changed
