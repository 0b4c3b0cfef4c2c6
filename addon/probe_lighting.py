"""Live lighting from a baked probe grid (issue 12): an enabled object whose Probe Lighting
names a volume (or Empty) with baked probes (probes.py) takes its environment lighting from
them, at its position, every time it is shaded, instead of the World. Its transfer shades it
as usual, so it keeps its own soft shadows under the light of the place it stands in.

The probes hold the World and the lamps as they were baked, so the scene's lamps are not
added again for such an object. Evaluation drops probes the point cannot see (the static
geometry of the bake, kept here per volume), so light does not leak through walls. A cached
object (cache.py) is shaded the same way from its cached transfer, and a new bake of the
probes re-shades the objects it lights at once (`reshade_users`)."""

import numpy as np

from . import probes

#: volume session_uid -> (digest of its stored probes, probes dict, world triangles (M, 3, 3))
_baked: dict[int, tuple] = {}


def volume_of(obj):
    """The object's probe volume, or None (lit by the World)."""
    return getattr(obj.hemishadow, "probe_volume", None)


def point_of(obj, vertices):
    """Where the object samples the grid: the centre of its bounds (world `vertices`), or
    its origin, as its Probe Point says."""
    if obj.hemishadow.probe_point == "ORIGIN" or vertices is None or not len(vertices):
        return np.array(obj.matrix_world.translation, np.float64)
    v = np.asarray(vertices, np.float64)
    return 0.5 * (v.min(axis=0) + v.max(axis=0))


def lighting(obj, scene, vertices, bands):
    """Radiance SH (bands^2, 3) float32 at the object's point, from its volume's probes:
    their 9 coefficients, higher bands zero. Raises ValueError naming the volume when it
    holds no baked probes."""
    volume = volume_of(obj)
    data, blockers = _probes_of(volume, scene)
    import hemishadow.probes as hp

    sh9 = hp.evaluate(data, point_of(obj, vertices)[None], blockers=blockers)["sh9"][0]
    out = np.zeros((bands * bands, 3), np.float32)
    count = min(9, bands * bands)
    out[:count] = sh9[:count]
    return out


def _probes_of(volume, scene):
    data = probes.stored(volume)
    if data is None:
        raise ValueError(f"'{volume.name}' holds no baked probes: bake them first (Bake Probes)")
    digest = hash((data["positions"].tobytes(), data["sh9"].tobytes()))
    known = _baked.get(volume.session_uid)
    if known is None or known[0] != digest:
        _, _, world = probes.scene_geometry(scene)  # the static geometry the probes saw
        known = _baked[volume.session_uid] = (digest, data, world)
    return known[1], known[2]


def users(scene, volume):
    """The enabled objects of the scene that take their light from `volume`."""
    from . import engine_bridge

    return [o for o in engine_bridge.enabled_objects(scene) if volume_of(o) == volume]


def reshade_users(scene, volume):
    """After the volume's probes changed (a bake): its objects shaded with their new light
    now, not on the next frame: from their cache when one serves this frame (re-shading its
    transfer), else from their last live transfer. Only while Live is on, as on a frame
    change; errors go to the objects' status."""
    from . import cache, engine_bridge

    if not scene.hemishadow.live or cache.is_baking():
        return
    live = []
    for obj in users(scene, volume):
        try:
            if not cache.handled(obj, scene):
                live.append(obj)
        except (ValueError, RuntimeError, OSError) as error:
            engine_bridge.set_status(obj, f"bake cache not used: {error}")
            live.append(obj)
    engine_bridge.reshade_scene(scene, live)


def forget():
    _baked.clear()
