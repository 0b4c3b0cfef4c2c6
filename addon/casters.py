"""Shadow casters: the objects of a collection, kept as one `hemishadow.Scene` that shadows the
objects using it (on top of their self-shadowing, which their own solver computes).

An object's casters are its own "Shadow casters" collection, else the scene's default one
(properties.py); none means self-shadowing only. Per collection this module keeps a
`CasterScene`, found from the depsgraph and brought up to date before each solve:
- every evaluated mesh drawn by the collection (its objects, and what their collection and
  geometry-nodes instances draw: depsgraph.object_instances) is one scene mesh, shared by its
  users: linked duplicates without modifiers, and every instance of an object, are instances
  of ONE mesh, never copies;
- an object that only deforms and subdivides (mesh_io.smooths_only) casts with the surface it
  receives on: its original faces through the first evaluated vertices, on the limit surface.
  Four times fewer triangles per level, and the same shadow in the viewport and in renders;
  when it only subdivides, its evaluated mesh is not even touched (steady.py: reading it
  would subdivide it again at every frame);
- per frame, a mesh whose evaluated positions hash differently gets `set_vertices`, an
  instance whose matrix changed `set_matrix`; static casters are left alone. A change of
  topology, or of the collection's members, rebuilds the scene (the engine cannot drop a mesh);
- objects that cannot cast (curves, text, meshes without faces, zero scale) are skipped and
  named in `CasterScene.notes`, which the receivers' status lines show. Nothing here raises
  into a handler: engine errors on a caster become notes too.

Solves may run in worker threads (jobs.py, the bake) while the main thread moves on to the
next frame: a scene is never changed while a `Use` of it is alive (read, queued or solving).
Another scene of the pool is brought up to date instead, so each solve sees the casters of
the frame its own positions were read at.
"""

import contextlib
import itertools
import threading
from dataclasses import dataclass, field

import numpy as np

from . import mesh_io, steady

#: Versions of all CasterScenes: a receiver's result names the state of its casters by one.
_versions = itertools.count(1)

#: Object types that draw nothing a shadow could come from; left out without a note.
_NO_SURFACE = {"EMPTY", "LIGHT", "LIGHT_PROBE", "CAMERA", "ARMATURE", "LATTICE", "SPEAKER"}
_NO_FACES = "its mesh has no faces"


def collection_of(obj, scene):
    """The casters collection the object uses (its own, else the scene's), or None."""
    own = getattr(obj.hemishadow, "casters", None)
    return own if own is not None else scene.hemishadow.casters


# -- what the collection draws --------------------------------------------------------------------

@dataclass
class _Item:
    """One drawn mesh: where (`matrix`), which shared mesh (`mesh_key`), and for sorting and
    stable records the names of what draws it."""

    key: tuple          # the instance, stable between frames
    mesh_key: tuple     # what it shares its geometry with
    mesh: object        # the evaluated bpy Mesh (None when `steady`: never read)
    matrix: np.ndarray  # (4, 4) float64 world matrix
    owner: int | None   # session_uid of the object drawn directly (not through an instancer)
    original: int | None  # vertex count of the source's own mesh (None: geometry made by nodes)
    name: tuple         # names: (instancer, object, persistent id), for the cache's records
    cage: object = None  # the source's own mesh when it casts instead (see `_cage`)
    steady: tuple | None = None  # (source, depsgraph) when steady.py knows its positions


def _mesh_key(source):
    """Linked duplicates without modifiers evaluate to their shared mesh; anything with
    modifiers has geometry of its own."""
    if len(source.modifiers) == 0 and source.data is not None:
        return ("mesh", source.data.session_uid)
    return ("object", source.session_uid)


def _items(collection, depsgraph, notes):
    """The meshes the collection draws, in depsgraph order; what cannot cast goes to `notes`."""
    members = {o.session_uid for o in collection.all_objects}
    items, geometry, subdividing = [], {}, {}
    for instance in depsgraph.object_instances:
        evaluated = instance.object
        drawer = (instance.parent if instance.is_instance else evaluated).original
        if drawer.session_uid not in members:
            continue
        source = evaluated.original
        name = evaluated.name if not instance.is_instance else f"{evaluated.name} (instanced by {drawer.name})"
        if evaluated.type != "MESH":
            if evaluated.type not in _NO_SURFACE:
                kind = mesh_io.NOT_A_MESH.get(evaluated.type, evaluated.type.lower())
                notes.append(f"'{name}' skipped: a {kind} object casts no shadow (convert it to a mesh)")
            continue
        persistent = tuple(instance.persistent_id) if instance.is_instance else ()
        item = _Item(key=(drawer.session_uid, source.session_uid, persistent), mesh_key=None, mesh=None,
                     matrix=np.array(instance.matrix_world, np.float64),
                     owner=None if instance.is_instance else source.session_uid, original=None,
                     name=(drawer.name, source.name, persistent))
        if _subdivides_only(source, depsgraph, subdividing):
            skipped = _steady_item(item, source, depsgraph)
        else:
            skipped = _drawn_item(item, instance, source, drawer, depsgraph, geometry)
        if skipped is None:
            items.append(item)
        elif skipped:
            notes.append(f"'{name}' skipped: {skipped}")
    return items


def _steady_item(item, source, depsgraph):
    """Fills in an item whose evaluated mesh is never touched: reading it would subdivide it
    (steady.py). None, or why it cannot cast."""
    if len(source.data.polygons) == 0:
        return _NO_FACES
    item.mesh_key, item.original, item.cage = _mesh_key(source), len(source.data.vertices), source.data
    item.steady = (source, depsgraph)
    return None


def _drawn_item(item, instance, source, drawer, depsgraph, geometry):
    """Fills in an item from its evaluated mesh (`geometry`: the instancers' meshes made by
    nodes, numbered). None, or why it cannot cast ("" for nothing worth a note)."""
    mesh = instance.object.data
    if len(mesh.polygons) == 0:
        # Geometry nodes that output instances only leave the instancer an empty mesh.
        return _NO_FACES if len(mesh.vertices) or not any(m.type == "NODES" for m in source.modifiers) else ""
    if instance.is_instance and source == drawer and mesh.original == mesh:
        # Geometry made by the instancer's nodes: no datablock to share by; the n-th such
        # mesh of an instancer is the same one from frame to frame.
        ordinal = geometry.setdefault((drawer.session_uid, mesh.as_pointer()), len(geometry))
        item.mesh_key = ("geometry", drawer.session_uid, ordinal)
    else:
        item.mesh_key = _mesh_key(source)
    item.mesh = mesh
    item.original = len(source.data.vertices) if item.mesh_key[0] != "geometry" and source.type == "MESH" else None
    item.cage = _cage(source, mesh, item.original, depsgraph)
    return None


def _subdivides_only(source, depsgraph, known):
    """True when steady.py knows the source's positions without its evaluated mesh (`known`:
    the answers so far, per source)."""
    uid = source.session_uid
    if uid not in known:
        known[uid] = steady.applies(source, depsgraph)
    return known[uid]


def _cage(source, evaluated_mesh, original, depsgraph):
    """The source's own mesh when its evaluated mesh only refines it (mesh_io.smooths_only):
    it casts with the surface it receives on, its original faces through the first evaluated
    vertices (on the limit surface). A fraction of the triangles (4^-levels), and the same
    shadow in the viewport and in renders, which subdivide further."""
    if original is None or len(evaluated_mesh.vertices) <= original:
        return None
    return source.data if mesh_io.smooths_only(source, depsgraph.mode == "RENDER") else None


def _positions(item):
    if item.steady is not None:
        source, depsgraph = item.steady
        return steady.first_positions(source, depsgraph,
                                      lambda: mesh_io.positions_of(source.evaluated_get(depsgraph).data, item.original))
    return mesh_io.positions_of(item.mesh, None if item.cage is None else item.original)


def _faces_of(item):
    """The mesh whose faces the item casts with."""
    return item.mesh if item.cage is None else item.cage


def _digest(array):
    return hash(array.tobytes())


def _faces_digest(mesh):
    """Of the polygons' corners: the topology. Not of the loop triangles, whose diagonals a
    bending quad may flip from one frame to the next (the cloth does): that is no new
    topology, and the scene keeps the triangles it was built with."""
    corners = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", corners)
    sizes = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_total", sizes)
    return hash((corners.tobytes(), sizes.tobytes()))


# -- one scene of a collection ----------------------------------------------------------------------

@dataclass
class _Mesh:
    id: int
    counts: tuple            # (vertices, triangles)
    digest: int              # of the positions
    faces_digest: int        # of the polygons (see _faces_digest)


@dataclass(eq=False)
class CasterScene:
    """A hemishadow.Scene of one collection and what it was built from. `version` is new (in
    all scenes) after every change, so a receiver's result is known current by it."""

    scene: object = None
    meshes: dict = field(default_factory=dict)       # mesh_key -> _Mesh
    instances: dict = field(default_factory=dict)    # item key -> (instance id, matrix bytes, owner)
    found_notes: list = field(default_factory=list)   # of this frame's items (curves, no faces)
    build_notes: list = field(default_factory=list)   # what the engine refused at the last build
    version: int = 0
    users: int = 0
    lock: threading.RLock = field(default_factory=threading.RLock)  # a Use may be collected anywhere

    @property
    def busy(self):
        with self.lock:
            return self.users > 0

    def sync(self, items, notes):
        """Bring the scene to `items` (this frame's): set_vertices / set_matrix for what moved,
        a rebuild when the members or a topology changed."""
        self.found_notes = notes
        if set(self.instances) != {i.key for i in items} or self.scene is None:
            return self._build(items)
        changed = False
        for mesh_key, item in _first_per_mesh(items).items():
            known = self.meshes.get(mesh_key)
            if known is None:  # skipped at the build (its note stays)
                continue
            positions = _positions(item)
            counts = (len(positions), len(_faces_of(item).loop_triangles))
            if counts != known.counts:
                return self._build(items)
            digest = _digest(positions)
            if digest == known.digest:
                continue
            # Moved: only then are the faces read, to tell a deformation from a new topology.
            if _faces_digest(_faces_of(item)) != known.faces_digest:
                return self._build(items)
            self.scene.set_vertices(known.id, positions)
            known.digest, changed = digest, True
        for item in items:
            instance_id, matrix, owner = self.instances[item.key]
            if instance_id is not None and item.matrix.tobytes() != matrix:
                self.scene.set_matrix(instance_id, item.matrix)
                self.instances[item.key] = (instance_id, item.matrix.tobytes(), owner)
                changed = True
        if changed:
            self.version = next(_versions)
        return changed

    def _build(self, items):
        import hemishadow

        self.scene, self.meshes, self.instances, self.build_notes = hemishadow.Scene(), {}, {}, []
        self.version = next(_versions)
        for mesh_key, item in _first_per_mesh(items).items():
            positions, triangles = _positions(item), mesh_io.triangles_of(_faces_of(item))
            try:
                mesh_id = self.scene.add_mesh(positions, triangles)
            except ValueError as error:
                self.build_notes.append(f"'{item.name[1]}' skipped: {error}")
                continue
            self.meshes[mesh_key] = _Mesh(mesh_id, (len(positions), len(triangles)), _digest(positions),
                                          _faces_digest(_faces_of(item)))
        for item in items:
            known = self.meshes.get(item.mesh_key)
            if known is None:
                continue
            try:
                instance_id = self.scene.add_instance(known.id, item.matrix)
            except ValueError as error:  # a zero scale
                self.build_notes.append(f"'{item.name[1]}' skipped: {error}")
                continue
            self.instances[item.key] = (instance_id, item.matrix.tobytes(), item.owner)
        # Keys of skipped items count as present, so they are not rebuilt every frame.
        for item in items:
            self.instances.setdefault(item.key, (None, item.matrix.tobytes(), item.owner))
        return True

    @property
    def notes(self):
        return self.found_notes + self.build_notes

    def own_instances(self, obj):
        """Instance ids of the object itself (drawn directly): its solver shadows it."""
        return tuple(i for i, _, owner in self.instances.values() if owner == obj.session_uid and i is not None)


def _first_per_mesh(items):
    first = {}
    for item in items:
        first.setdefault(item.mesh_key, item)
    return first


# -- using one for a solve ----------------------------------------------------------------------

class Use:
    """A receiver's hold on a CasterScene from the read of its positions to the end of its
    solve (any thread): the scene is not changed meanwhile. Released by `release()` or when
    it is garbage-collected (a dropped job)."""

    def __init__(self, caster_scene, collection_name, exclude):
        self.caster_scene, self.collection = caster_scene, collection_name
        self.exclude = exclude
        self.version = caster_scene.version
        with caster_scene.lock:
            caster_scene.users += 1
        self._held = True

    def release(self):
        with self.caster_scene.lock:
            if self._held:
                self._held = False
                self.caster_scene.users -= 1

    def __del__(self):
        self.release()

    @property
    def scene(self):
        return self.caster_scene.scene

    @property
    def notes(self):
        return self.caster_scene.notes

    def key(self, frame):
        """What the receiver's result depends on besides its own positions: this state of the
        casters and where the receiver's frame is among them."""
        return self.version, self.exclude, to_world(frame).tobytes()

    def note(self):
        skipped = "; ".join(self.notes)
        return f"; shadowed by '{self.collection}'" + (f" ({skipped})" if skipped else "")

    def solve_arguments(self, frame):
        """Keyword arguments of TransferSolver.solve for positions in the receiver's frame."""
        return dict(casters=self.scene, to_world=to_world(frame), exclude=self.exclude)


def to_world(frame):
    """The 4x4 rigid matrix of a mesh_io.Frame: positions in the frame -> world space."""
    matrix = np.eye(4)
    if frame.rotation is not None:
        matrix[:3, :3], matrix[:3, 3] = frame.rotation, frame.offset
    return matrix


#: collection session_uid -> its CasterScenes (more than one only while solves hold them)
_pools: dict[int, list] = {}
#: collection session_uid -> the CasterScene synced in the current pass (see `one_pass`)
_pass: dict[int, CasterScene] | None = None


@contextlib.contextmanager
def one_pass():
    """Within it, each collection is brought up to date once, for all its receivers."""
    global _pass
    if _pass is not None:
        yield
        return
    _pass = {}
    try:
        yield
    finally:
        _pass = None


def _synced(collection, depsgraph):
    if _pass is not None and collection.session_uid in _pass:
        return _pass[collection.session_uid]
    pool = _pools.setdefault(collection.session_uid, [])
    caster_scene = next((c for c in pool if not c.busy), None)
    if caster_scene is None:
        caster_scene = CasterScene()
        pool.append(caster_scene)
    notes = []
    items = _items(collection, depsgraph, notes)
    try:
        caster_scene.sync(items, notes)
    except ValueError:  # the engine refused new positions (NaN...): the build names the object
        caster_scene._build(items)
    if _pass is not None:
        _pass[collection.session_uid] = caster_scene
    return caster_scene


def for_object(obj, scene, depsgraph):
    """The object's casters brought to this frame, held for its solve (a Use), or None when it
    has none (no collection, an empty one, or nothing in it can cast)."""
    collection = collection_of(obj, scene)
    if collection is None or len(collection.all_objects) == 0:
        return None
    caster_scene = _synced(collection, depsgraph)
    if not caster_scene.instances:
        return None
    return Use(caster_scene, collection.name, caster_scene.own_instances(obj))


def forget():
    """Drop every scene (a file was loaded, or the add-on goes)."""
    _pools.clear()


def receivers_touched(scene, depsgraph, objects):
    """The objects (of `objects`) with casters that a depsgraph update moved relative to them:
    a member of their casters collection changed (geometry, transform, membership), or they
    moved themselves."""
    import bpy

    moved = {u.id.original.session_uid for u in depsgraph.updates
             if isinstance(u.id, bpy.types.Object) and (u.is_updated_geometry or u.is_updated_transform)}
    transformed = {u.id.original.session_uid for u in depsgraph.updates
                   if isinstance(u.id, bpy.types.Object) and u.is_updated_transform}
    collections = {u.id.original.session_uid for u in depsgraph.updates if isinstance(u.id, bpy.types.Collection)}
    found = []
    for obj in objects:
        collection = collection_of(obj, scene)
        if collection is None:
            continue
        members = _members(collection)
        if obj.session_uid in transformed or collection.session_uid in collections or members & moved:
            found.append(obj)
    return found


def _members(collection):
    """session_uids of the collection's objects and of the objects their collections instance."""
    found, seen, todo = set(), set(), [collection]
    while todo:
        current = todo.pop()
        if current.session_uid in seen:
            continue
        seen.add(current.session_uid)
        for obj in current.all_objects:
            found.add(obj.session_uid)
            if obj.instance_type == "COLLECTION" and obj.instance_collection is not None:
                todo.append(obj.instance_collection)
    return found


# -- records for bake caches ------------------------------------------------------------------------

def describe(obj, scene):
    """What a bake records of the object's casters: the collection and its objects' names, or
    None (self-shadowing only)."""
    collection = collection_of(obj, scene)
    if collection is None or len(collection.all_objects) == 0:
        return None
    return {"collection": collection.name, "objects": sorted(o.name for o in collection.all_objects)}


def fingerprint(obj, scene, depsgraph):
    """(10, 3) float64 record of where every caster is this frame, or None without casters:
    the count of drawn meshes, the largest coordinate, and eight random-sign sums over the
    drawn meshes (by names) of their world matrices and staleness-style sums of positions:
    any caster moved by more than staleness.TOLERANCE of the largest coordinate changes a sum.
    Of a mesh object only its original vertices count (as for receivers, mesh_io): renders
    subdivide more than the viewport the bake ran in, and keep those first, in place."""
    from . import staleness

    collection = collection_of(obj, scene)
    if collection is None or len(collection.all_objects) == 0:
        return None
    rows, sums = [], {}
    for item in sorted(_items(collection, depsgraph, []), key=lambda i: i.name):
        if item.mesh_key not in sums:
            positions = _positions(item)
            if item.original is not None and item.original <= len(positions):
                positions = positions[:item.original]
            sums[item.mesh_key] = staleness.fingerprint(positions)
        rows += [item.matrix[:3].T, sums[item.mesh_key]]
    rows = np.concatenate(rows) if rows else np.zeros((0, 3))
    head = np.array([[len(rows), 0.0, 0.0], np.abs(rows).max(axis=0, initial=0.0)])
    return np.concatenate([head, mesh_io.matmul(staleness.random_signs(len(rows)), rows)])


def fingerprint_mismatch(stored, current):
    """None when two `fingerprint`s agree, else a short reason."""
    from . import staleness

    if stored is None and current is None:
        return None
    if stored is None or current is None or np.shape(stored) != np.shape(current) or stored[0, 0] != current[0, 0]:
        return "the shadow casters are not the bake's"
    scale = max(float(np.abs(stored[1]).max()), 1e-30)
    if float(np.abs(np.asarray(stored[2:]) - current[2:]).max(initial=0.0)) > staleness.TOLERANCE * scale:
        return "a shadow caster moved or deformed since the bake"
    return None
