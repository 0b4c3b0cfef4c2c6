"""The lighting as a whole: shading with environment and lamps, its fingerprint, its messages.

- `shade`: radiance = albedo / pi (T . L_env + sum over lamps of T_v . L_lamp,v): the
  environment and suns are one SH vector (world.py), point, spot and area lamps one per vertex
  (lamps.py).
- `fingerprint`: a cheap digest of every lighting input as it is now (World nodes and their
  animated values, lamp objects' transforms, visibility and settings, the scene's lighting
  settings). The handlers compare it each frame and on each depsgraph update and re-shade
  (no transfer recomputed) when it changed, which catches keyframed, driven or moved lighting
  that no depsgraph update names.
- `report`: what the user must know about the lighting goes to the console and the status
  bar once, and operators put it in their report.
"""

from __future__ import annotations

import hashlib

import bpy
import numpy as np

from . import evaluated, lamps, world, world_render

__all__ = ["shade", "fingerprint", "report", "messages", "check_before_render"]

_reported: dict[str, tuple] = {}


def shade(scene, transfer, lighting, albedo, vertices, found=None):
    """Radiance (V, 3): environment SH `lighting` (K, 3) plus the lamps at `vertices`.
    found: the lamps (`lamps.scene_lamps(scene)`, read from Blender: main thread only); pass
    them read beforehand to call this from a worker thread (the rest is numpy and the engine)."""
    import hemishadow

    radiance = hemishadow.shade(transfer, lighting, albedo)
    if found is None:
        found = lamps.scene_lamps(scene)
    if found and vertices is not None:
        radiance += np.asarray(albedo, np.float32) / np.pi * lamps.lamp_irradiance(transfer, vertices, found)
    return radiance


def _lamp_key(obj):
    light = obj.data
    values = [obj.name, tuple(round(v, 6) for row in obj.matrix_world for v in row), light.type,
              tuple(light.color), float(light.energy)]
    for name in ("shadow_soft_size", "spot_size", "spot_blend", "size", "size_y", "shape", "angle", "exposure",
                 "use_temperature", "temperature", "diffuse_factor", "spread", "use_shadow", "normalize"):
        if hasattr(light, name):
            values.append(getattr(light, name))
    return tuple(values)


def fingerprint(scene) -> str:
    """Digest of every lighting input as it is now (see the module notes)."""
    settings = getattr(scene, "hemishadow", None)
    parts = [world_render.value_key(getattr(settings, name, None)) for name in world.DEFAULTS] if settings else []
    w = evaluated.of(scene.world)
    if w is not None:
        parts.append(world_render.fingerprint(w))
        # Animated values themselves (the digest above leaves them out): what this frame shows.
        parts.append(world_render.animated_values(w))
    parts.extend(_lamp_key(o) for o in lamps.visible_lamps(scene, ("POINT", "SPOT", "AREA", "SUN")))
    return hashlib.blake2b(repr(parts).encode(), digest_size=16).hexdigest()


def messages(scene) -> list[str]:
    return world.notes(scene)


def report(scene):
    """Print the scene's lighting messages and show them in the status bar, once per change."""
    found = tuple(messages(scene))
    before = _reported.get(scene.name, ())
    if before == found:
        return found
    _reported[scene.name] = found
    for message in found:
        print(f"hemishadow: lighting: {message}")
    text = ("Hemishadow: " + "; ".join(found)) if found else None
    for window in getattr(bpy.context.window_manager, "windows", []):
        try:
            window.workspace.status_text_set(text)
        except (AttributeError, RuntimeError):
            pass
    return found


def check_before_render(scene) -> list[int]:
    """Before a render: the frames whose World projection is missing (rendering cannot make
    them now), reported; an empty list when all is there or the World needs no render."""
    settings = getattr(scene, "hemishadow", None)
    if settings is None or settings.lighting_source != "WORLD" or scene.world is None:
        return []
    if world.lighting_source(scene, settings).kind != "WORLD_RENDER":
        return []
    missing = world_render.missing_frames(scene)
    if missing:
        message = (f"World {scene.world.name!r} has no lighting projection for {len(missing)} frames "
                   f"({missing[0]}..{missing[-1]}); run Precompute World Lighting before rendering")
        print(f"hemishadow: lighting: {message}")
        for window in getattr(bpy.context.window_manager, "windows", []):
            try:
                window.workspace.status_text_set("Hemishadow: " + message)
            except (AttributeError, RuntimeError):
                pass
    return missing
