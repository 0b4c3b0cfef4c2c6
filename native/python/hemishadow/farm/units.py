"""Work units: deterministic, idempotent pieces of a farm job (same unit, same bytes), so that
a retry after a lost worker is safe. A unit is a plain dict (see worker.py).

Sizes: per-unit overhead (opening the .blend, registering the add-on, reading the scene into
the engine, building the object's solver) must stay under 10 % of the unit's work. bench/farm.py
measures both by regression over unit sizes: a bake unit costs UNIT_SECONDS plus about
FRAME_SECONDS_PER_VERTEX x vertices per frame (one engine thread), so an object of V vertices
gets units of at least UNIT_SECONDS / (0.1 x FRAME_SECONDS_PER_VERTEX x V) frames (a 2k-vertex
mesh: tens of frames; a 50k-vertex character: a few), and at most enough units for balance.
Probe units repeat the scene's bounce pass (every unit needs the whole scene's bounce light),
so blocks are large, and whole multiples of the probe baker's chunk of PROBE_CHUNK probes: its
float32 matrix products then see the same shapes as on one machine and give the same bits
(smaller blocks, with `--probes-per-unit`, differ in the last bits). Lightmaps are one unit per
object: its padding and seam pass need all of its own texels and no other object's. A panorama
is one unit (`--cameras` makes one per camera).
`--frames-per-unit` / `--probes-per-unit` override the sizes.
"""

from __future__ import annotations

import hashlib
import json
import math

UNIT_SECONDS = 0.2                # bench/farm.py: fixed cost of a bake unit (open, setup, solver)
FRAME_SECONDS_PER_VERTEX = 3.4e-5 # bench/farm.py: one object-frame per vertex, one engine thread
OVERHEAD = 0.1                    # the most per-unit overhead allowed, as a fraction of the work
from hemishadow.probes.bake import _CHUNK as PROBE_CHUNK   # blocks of whole chunks give the same bits
UNITS_PER_WORKER = 3   # enough units for balance when units take unequal times


def base(kind, blend, args, addon):
    return dict(kind=kind, blend=blend, args=list(args), addon=addon)


def plan_unit(kind, blend, args, addon, cameras=None):
    """The first task: reads the .blend on a worker and says what the units are."""
    return dict(base("plan", blend, [kind, *args], addon), cameras=cameras)


def min_frames(vertices):
    """Frames a bake unit of an object of `vertices` vertices needs for overhead < OVERHEAD."""
    return max(1, math.ceil(UNIT_SECONDS / (OVERHEAD * FRAME_SECONDS_PER_VERTEX * max(vertices, 1))))


def _size(count, workers, minimum, given):
    """Items per unit: `given`, else equal units of at least `minimum` items, at most
    UNITS_PER_WORKER per worker (balance when units take unequal times)."""
    if given:
        return max(1, int(given))
    n = min(max(1, count // max(1, minimum)), max(1, UNITS_PER_WORKER * workers))
    return math.ceil(count / n)


def make(plan, unit_base, workers, frames_per_unit=None, probes_per_unit=None):
    """The units of a job, in output order."""
    kind = plan["kind"]
    if kind == "bake":
        a, b = plan["frames"]
        count = b - a + 1
        out = []
        for name in plan["objects"]:
            size = count if plan["simulated"] else _size(count, workers, min_frames(plan["vertices"][name]),
                                                         frames_per_unit)
            out += [dict(unit_base, object=name, frames=[s, min(b, s + size - 1)], start=a)
                    for s in range(a, b + 1, size)]
        return out
    if kind == "lightmaps":
        return [dict(unit_base, object=name) for name in plan["outputs"]]   # objects, or one atlas
    if kind == "probes":
        count = plan["count"]
        chunks = math.ceil(count / PROBE_CHUNK)
        size = probes_per_unit or PROBE_CHUNK * _size(chunks, workers, 1, None)
        return [dict(unit_base, block=[s, min(count, s + size)]) for s in range(0, count, size)]
    if kind == "panorama":   # one panorama per unit: its pixels share one scene and one bounce pass
        return [dict(unit_base, camera=name) for name in plan["cameras"]]
    raise ValueError(f"unknown kind of job {kind!r}")


def key(unit) -> str:
    """A dask key naming the unit: the same unit, the same key (its result can be reused)."""
    digest = hashlib.blake2b(json.dumps(unit, sort_keys=True).encode(), digest_size=8).hexdigest()
    what = unit.get("object") or unit["kind"]
    where = unit.get("frames") or unit.get("block") or []
    return f"hemishadow-{unit['kind']}-{what}-{'-'.join(map(str, where))}-{digest}"


def describe(unit) -> str:
    if unit["kind"] == "bake":
        return f"{unit['object']} frames {unit['frames'][0]}..{unit['frames'][1]}"
    if unit["kind"] == "probes":
        return f"probes {unit['block'][0]}..{unit['block'][1] - 1}"
    if unit["kind"] == "panorama":
        return f"panorama {unit['camera'] or '(the command line viewpoint)'}"
    return unit.get("object", unit["kind"])
