"""Probe grids of a Blender scene (issue 12): ambient cubes and SH9 baked at the samples of a
Light Probe Volume (or in an Empty's bounds, or at given points) through `hemishadow.probes`.

Blockers and bounce surfaces are the visible, renderable meshes (`lightmaps.blockers`),
except objects with hemishadow enabled: they are live-shaded (characters, props that move)
and take their light from the grid instead of being baked into it. Light: the World's SH,
sun, point, spot and area lamps as the lightmap bake reads them (`lightmaps.lighting_of`,
`suns_of`, `lamps_of`); albedo and emission from the Principled BSDF's input values; the
bounce light of surfaces with baked lightmaps from those (probe_lightmaps.py). Results go
to an .npz file (plus .json beside it) and onto the volume object (custom properties
`hemishadow_probe_*`); the objects the volume lights are re-shaded at once.
"""

from __future__ import annotations

import os

import bpy
import numpy as np

from . import lightmaps, probe_lightmaps

PROP = "hemishadow_probe_"
EMPTY_RESOLUTION = (4, 4, 4)
PREVIEW_PREFIX = "hemishadow_probes_"


def grid_of(obj, resolution=None):
    """(grid index -> world (4, 4), resolution (3,)) of a Light Probe Volume (its own
    resolution; Blender's sample placement) or of an Empty (a cube of its display size,
    `resolution` or EMPTY_RESOLUTION)."""
    import hemishadow.probes as hp

    matrix = np.array(obj.matrix_world, np.float64)
    if obj.type == "LIGHT_PROBE" and obj.data.type == "VOLUME":
        res = (obj.data.resolution_x, obj.data.resolution_y, obj.data.resolution_z)
        return hp.volume_matrix(matrix, res), np.array(res)
    if obj.type == "EMPTY":
        size = np.eye(4)
        size[:3, :3] *= obj.empty_display_size
        res = tuple(resolution or EMPTY_RESOLUTION)
        return hp.volume_matrix(matrix @ size, res), np.array(res)
    raise ValueError(f"{obj.name}: not a Light Probe Volume or an Empty (it is a {obj.type.lower()})")


def active_volume(context):
    """The active object when it is a Light Probe Volume or an Empty, else None."""
    obj = context.active_object
    if obj is not None and (obj.type == "EMPTY" or (obj.type == "LIGHT_PROBE" and obj.data.type == "VOLUME")):
        return obj
    return None


def scene_geometry(scene, depsgraph=None, *, live=False, purpose="bake probes against"):
    """(hemishadow.Scene, Surfaces, world triangles (M, 3, 3)) of the bake's meshes; objects
    with hemishadow enabled only when `live` (the panorama sees them; the probes light them)."""
    import hemishadow
    import hemishadow.lightmap as lm

    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    engine_scene, surfaces, world = hemishadow.Scene(), [], []
    for obj in lightmaps.blockers(scene):
        if not live and getattr(getattr(obj, "hemishadow", None), "enabled", False):
            continue  # live-shaded: lit by the grid, not part of it
        data = lightmaps.read_mesh(obj, depsgraph, albedo=True)
        if not len(data.triangles):
            continue
        mesh_id = engine_scene.add_mesh(data.vertices, data.triangles.astype(np.uint32))
        matrix = np.array(obj.evaluated_get(depsgraph).matrix_world, np.float64)
        engine_scene.add_instance(mesh_id, matrix)
        surfaces.append(lm.Surface(mesh_id, data.vertices, data.triangles, matrix, data.albedo, lightmaps.emission_of(obj),
                                   obj.name))
        placed = data.vertices.astype(np.float64) @ matrix[:3, :3].T + matrix[:3, 3]
        world.append(placed[data.triangles])
    if not surfaces:
        raise ValueError(f"scene {scene.name!r} has no visible, renderable mesh to {purpose}")
    return engine_scene, surfaces, np.concatenate(world)


def output_path(volume, out=None):
    if out:
        return bpy.path.abspath(out)
    if bpy.data.filepath:
        return bpy.path.abspath(f"//probes/{lightmaps._safe(volume.name if volume else 'points')}.npz")
    return None


def bake_probes(scene, volume=None, points=None, *, bounces=2, resolution=None, out=None, progress=None,
                store=True):
    """Bakes the probes of `volume` (Light Probe Volume or Empty) or at `points` (P, 3);
    returns (result dict, path written or None). Raises ValueError naming the object for
    unusable input, `hemishadow.Cancelled` when `progress` returns False (nothing written)."""
    import hemishadow.probes as hp

    if (volume is None) == (points is None):
        raise ValueError("give a volume object or points, not both or neither")
    engine_scene, surfaces, world = scene_geometry(scene)
    baked = probe_lightmaps.vertex_light(scene, surfaces) if bounces else {}
    kwargs = dict(lighting=lightmaps.lighting_of(scene), suns=lightmaps.suns_of(scene), lamps=lightmaps.lamps_of(scene),
                  surfaces=surfaces, bounces=bounces, lightmaps=baked, progress=progress)
    if volume is not None:
        matrix, res = grid_of(volume, resolution)
        result = hp.bake_grid(engine_scene, matrix, res, **kwargs)
    else:
        result = hp.bake(engine_scene, points, **kwargs)
    result["notes"] = _notes(volume, result, world)
    path = output_path(volume, out)
    if path is not None:
        hp.write_npz(path, result)
        hp.write_json(os.path.splitext(path)[0] + ".json", result)
    if store and volume is not None:
        store_on(volume, result)
        from . import probe_lighting  # (it reads the probes through this module)

        probe_lighting.reshade_users(scene, volume)
    return result, path


def _notes(volume, result, world):
    """What the user should know about a bake that went through: probes left out, a volume
    with no geometry inside (its probes see the sky only)."""
    notes = []
    if result.get("lightmapped"):
        notes.append(f"bounce light from the baked lightmaps of {len(result['lightmapped'])} object(s)")
    bad = int((~result["valid"]).sum())
    if bad:
        notes.append(f"{bad} probe(s) inside geometry, left out of interpolation")
    pos = np.asarray(result["positions"], np.float64)
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    if volume is not None and not ((world.max(axis=1) >= lo) & (world.min(axis=1) <= hi)).all(axis=1).any():
        notes.append(f"{volume.name}: no geometry inside the volume: its probes see the World and distant meshes only")
    return notes


def store_on(obj, result):
    """Keeps the baked arrays with the .blend, as flat custom properties of the volume."""
    import hemishadow.probes as hp

    for key in hp.files.KEYS:
        value = np.asarray(result[key])
        obj[PROP + key] = value.astype(np.int32 if value.dtype.kind in "bi" else np.float64).ravel().tolist()


def stored(obj):
    """The arrays `store_on` kept on `obj`, or None."""
    if PROP + "positions" not in obj:
        return None
    p = len(obj[PROP + "positions"]) // 3
    shapes = {"positions": (p, 3), "cube": (p, 6, 3), "sh9": (p, 9, 3), "valid": (p,), "grid_matrix": (4, 4),
              "grid_resolution": (3,)}
    out = {k: np.array(obj[PROP + k], np.float64).reshape(s) for k, s in shapes.items()}
    out["valid"] = out["valid"].astype(bool)
    out["grid_resolution"] = out["grid_resolution"].astype(np.int64)
    return out


def preview(context_scene, volume, radius=None, subdivisions=2):
    """A mesh object of small spheres at the probes, corner colours = the n-squared value for
    the sphere's normal (colour attribute `hemishadow_probe`), replaced on every call."""
    import hemishadow.probes as hp

    data = stored(volume)
    if data is None:
        raise ValueError(f"{volume.name}: no baked probes on it: bake first")
    sphere_v, sphere_f = _icosphere(subdivisions)
    spacing = np.linalg.norm(data["grid_matrix"][:3, :3], axis=0).min()
    r = radius or 0.15 * spacing
    p = len(data["positions"])
    verts = (data["positions"][:, None] + r * sphere_v[None]).reshape(-1, 3)
    faces = (sphere_f[None] + (np.arange(p) * len(sphere_v))[:, None, None]).reshape(-1, 3)
    name = PREVIEW_PREFIX + volume.name
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts.tolist(), [], faces.tolist())
    corner_normals = np.broadcast_to(sphere_v[sphere_f], (p,) + sphere_f.shape + (3,)).reshape(-1, 3)
    cube = np.repeat(data["cube"], sphere_f.size, axis=0)
    rgb = hp.sample(cube, corner_normals)
    attr = mesh.color_attributes.new("hemishadow_probe", "FLOAT_COLOR", "CORNER")
    rgba = np.concatenate([rgb, np.ones((len(rgb), 1))], axis=1).astype(np.float32)
    attr.data.foreach_set("color", rgba.ravel())
    old = bpy.data.objects.get(name)
    if old is not None:
        old_mesh = old.data
        bpy.data.objects.remove(old)
        if old_mesh is not None and old_mesh.users == 0:
            bpy.data.meshes.remove(old_mesh)
    obj = bpy.data.objects.new(name, mesh)
    obj.hide_render = True  # a viewport aid: never rendered, never baked
    context_scene.collection.objects.link(obj)
    return obj


def remove_preview(volume):
    obj = bpy.data.objects.get(PREVIEW_PREFIX + volume.name)
    if obj is None:
        return False
    mesh = obj.data
    bpy.data.objects.remove(obj)
    if mesh is not None and mesh.users == 0:
        bpy.data.meshes.remove(mesh)
    return True


def _icosphere(subdivisions):
    """Unit icosphere: vertices (V, 3), triangles (F, 3)."""
    import bmesh

    bm = bmesh.new()
    try:
        bmesh.ops.create_icosphere(bm, subdivisions=subdivisions, radius=1.0)
        verts = np.array([v.co[:] for v in bm.verts], np.float64)
        faces = np.array([[v.index for v in f.verts] for f in bm.faces], np.int64)
    finally:
        bm.free()
    return verts / np.linalg.norm(verts, axis=1, keepdims=True), faces


def lighting_at(volume, point, blockers=None):
    """Radiance SH9 (9, 3) at a world point from the probes stored on `volume`
    (`hemishadow.probes.evaluate`, without leaks when `blockers`, world triangles (M, 3, 3) as
    `scene_geometry` gives them, are passed): the lighting an object in live mode can take
    from the grid instead of the World."""
    import hemishadow.probes as hp

    data = stored(volume)
    if data is None:
        raise ValueError(f"{volume.name}: no baked probes on it: bake first")
    return hp.evaluate(data, np.asarray(point, np.float64).reshape(1, 3), blockers=blockers)["sh9"][0]
