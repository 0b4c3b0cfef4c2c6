"""Work units: deterministic, idempotent pieces of a farm job (same unit, same bytes), so that
a retry after a lost worker is safe. A unit is a plain dict (see worker.py).

Sizes: per-unit overhead (opening the .blend, registering the add-on, reading the scene into
the engine) must stay under 10 % of the unit's work. bench/farm.py measures both (docs/farm.md
has the numbers): a bake unit takes at least MIN_FRAMES frames. Probe units repeat the scene's
bounce pass (every unit needs the whole scene's bounce light), so blocks are large, and whole
multiples of the probe baker's chunk of PROBE_CHUNK probes: its float32 matrix products then
see the same shapes as on one machine and give the same bits (smaller blocks, with
`--probes-per-unit`, differ in the last bits of sh9). Lightmaps are one unit per object: its
padding and seam pass need all of its own texels and no other object's.
`--frames-per-unit` / `--probes-per-unit` override the sizes.
"""

from __future__ import annotations

import hashlib
import json
import math

MIN_FRAMES = 10        # bake: frames per unit at least (bench/farm.py: overhead < 10 % of the work)
from hemishadow.probes.bake import _CHUNK as PROBE_CHUNK   # blocks of whole chunks give the same bits
UNITS_PER_WORKER = 3   # enough units for balance when units take unequal times


def base(kind, blend, args, addon):
    return dict(kind=kind, blend=blend, args=list(args), addon=addon)


def plan_unit(kind, blend, args, addon):
    """The first task: reads the .blend on a worker and says what the units are."""
    unit = base("plan", blend, [kind, *args], addon)
    return unit


def _size(count, workers, minimum, given):
    if given:
        return max(1, int(given))
    return max(minimum, math.ceil(count / max(1, UNITS_PER_WORKER * workers)))


def make(plan, unit_base, workers, frames_per_unit=None, probes_per_unit=None):
    """The units of a job, in output order."""
    kind = plan["kind"]
    if kind == "bake":
        a, b = plan["frames"]
        count = b - a + 1
        size = count if plan["simulated"] else _size(count, workers, MIN_FRAMES, frames_per_unit)
        return [dict(unit_base, object=name, frames=[s, min(b, s + size - 1)], start=a)
                for name in plan["objects"] for s in range(a, b + 1, size)]
    if kind == "lightmaps":
        return [dict(unit_base, object=name) for name in plan["objects"]]
    if kind == "probes":
        count = plan["count"]
        size = probes_per_unit or PROBE_CHUNK * math.ceil(_size(count, workers, PROBE_CHUNK, None) / PROBE_CHUNK)
        return [dict(unit_base, block=[s, min(count, s + size)]) for s in range(0, count, size)]
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
    return unit.get("object", unit["kind"])
