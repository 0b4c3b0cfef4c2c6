"""The merge: the units' results assembled into exactly what a single-machine bake writes
(the cache files, the EXR maps, the probe files), all written at once: every file goes to a
temporary name beside its place first, and only when all are written are they renamed into
place. A failed or cancelled farm job never gets here, so it leaves nothing that looks
complete; a failure while writing removes the temporary files.

Runs on the client. The caches' bytes come from the add-on's own `cache.BakeCache` (bpy
imported here, from the .venv's bpy module); lightmaps and probes need the engine package only.
"""

from __future__ import annotations

import contextlib
import os
import re
import uuid

import numpy as np


class MergeError(RuntimeError):
    pass


def resolve(path, blend):
    """A `//`-relative path of the .blend made absolute against the client's view of the file."""
    if path.startswith("//"):
        return os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(blend)), path[2:]))
    return os.path.abspath(path)


def check_writable(paths):
    """Raise MergeError naming the folder when a file could not be written there (before any
    unit runs, as the single-machine bake checks before its first frame). Creates nothing."""
    for path in paths:
        existing = os.path.dirname(path)
        while not os.path.isdir(existing):
            if os.path.lexists(existing):
                raise MergeError(f"cannot write {path}: {existing} is a file, not a folder")
            existing = os.path.dirname(existing)
        if not os.access(existing, os.W_OK):
            raise MergeError(f"cannot write {path}: {existing} is not writable")


def write_all(files):
    """files: [(final path, write(temporary path))]. Every file or none."""
    pending = []
    try:
        for final, write in files:
            folder, name = os.path.split(final)
            os.makedirs(folder, exist_ok=True)
            stem, ext = os.path.splitext(name)
            temporary = os.path.join(folder, f".{stem}.hemishadow-farm-{uuid.uuid4().hex[:8]}{ext}")
            pending.append((temporary, final))
            write(temporary)
    except BaseException:
        for temporary, _ in pending:
            with contextlib.suppress(OSError):
                os.unlink(temporary)
        raise
    for temporary, final in pending:
        os.replace(temporary, final)
    return [final for final, _ in files]


# ---------------------------------------------------------------------------------------
# Animation caches

# Meta entries every unit of an object must agree on (the first frame's lighting, albedo and
# lamps are the whole bake's, as in BakeJob._assemble).
_SAME = ("version", "object", "signature", "rest", "settings", "inputs", "casters")


def bake_caches(plan, results, cache_module):
    """{object: BakeCache over the whole range} from the units (any order)."""
    start = plan["frames"][0]
    out = {}
    for name in plan["objects"]:
        parts = sorted((r for r in results if r["object"] == name), key=lambda r: r["frames"][0])
        frames = [f for r in parts for f in range(r["frames"][0], r["frames"][1] + 1)]
        if frames != list(range(start, plan["frames"][1] + 1)):
            raise MergeError(f"{name}: the units do not cover frames {start}..{plan['frames'][1]} once each")
        first = parts[0]["meta"]
        for part in parts[1:]:
            differ = [k for k in _SAME if part["meta"].get(k) != first.get(k)]
            if differ:
                raise MergeError(f"{name}: the units of frames {part['frames']} read other {', '.join(differ)} "
                                 "than the first (the .blend changed during the bake?)")
        arrays = {}
        for k in ("radiance", "ao", "transfer", "fingerprint", "casters"):
            got = [p["arrays"][k] for p in parts]
            arrays[k] = None if got[0] is None else np.concatenate(got)
        meta = dict(first, frame_start=start)
        out[name] = cache_module.BakeCache(start, arrays["radiance"], arrays["ao"], arrays["transfer"], meta,
                                           arrays["fingerprint"], arrays["casters"])
    return out


def write_caches(plan, caches, blend):
    """The cache files (location FILE): {object: path written}."""
    files = []
    for name, cache in caches.items():
        cache.meta["token"] = uuid.uuid4().hex   # as cache.save does
        data = cache.to_bytes()
        files.append((resolve(plan["outputs"][name], blend), lambda path, data=data: _write_bytes(path, data)))
    return dict(zip(caches, write_all(files)))


def _write_bytes(path, data):
    with open(path, "wb") as handle:
        handle.write(data)


# ---------------------------------------------------------------------------------------
# Lightmaps

def _safe(name):
    return re.sub(r"[^\w.-]+", "_", name)   # as lightmaps._safe names the files


def write_lightmaps(plan, results, blend):
    import hemishadow.lightmap as lm

    maps = {r["object"]: r["maps"] for r in results}
    folder = resolve(plan["folder"], blend)
    files = [(os.path.join(folder, f"{_safe(name)}.exr"), lambda path, m=maps[name]: lm.write_exr(path, m))
             for name in plan["outputs"]]
    return dict(zip(plan["outputs"], write_all(files)))


# ---------------------------------------------------------------------------------------
# Probes

def probe_result(plan, results):
    """The single-machine bake's result dict from the blocks: concatenated, then the fill of
    invalid probes (nearest valid probe of the whole grid, hemishadow.probes.bake)."""
    from hemishadow.probes.bake import _fill_invalid

    parts = sorted(results, key=lambda r: r["block"][0])
    if [p["block"][0] for p in parts] != [0] + [p["block"][1] for p in parts[:-1]] or parts[-1]["block"][1] != plan["count"]:
        raise MergeError(f"the probe blocks do not cover probes 0..{plan['count'] - 1} once each")
    got = {k: np.concatenate([p["result"][k] for p in parts]) for k in ("positions", "cube", "sh9", "valid", "moved",
                                                                           "exact")}
    cube, sh9 = _fill_invalid(got["exact"], got["cube"], got["sh9"], got["valid"])
    result = dict(positions=got["positions"], cube=cube, sh9=sh9, valid=got["valid"], moved=got["moved"])
    first = parts[0]["result"]
    for k in ("grid_matrix", "grid_resolution"):
        if k in first:
            result[k] = first[k]
    result["notes"] = _notes(parts[0]["volume"], result, first["world_lo"], first["world_hi"])
    return result


def _notes(volume, result, world_lo, world_hi):
    """As addon/probes.py `_notes`, from the triangles' bounds the units sent."""
    notes = []
    bad = int((~result["valid"]).sum())
    if bad:
        notes.append(f"{bad} probe(s) inside geometry, left out of interpolation")
    pos = np.asarray(result["positions"], np.float64)
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    if volume is not None and not ((world_hi >= lo) & (world_lo <= hi)).all(axis=1).any():
        notes.append(f"{volume}: no geometry inside the volume: its probes see the World and distant meshes only")
    return notes


def write_probes(plan, result, blend):
    import hemishadow.probes as hp

    path = resolve(plan["output"], blend)
    json_path = os.path.splitext(path)[0] + ".json"
    write_all([(path, lambda p: hp.write_npz(p, result)), (json_path, lambda p: hp.write_json(p, result))])
    return path


# ---------------------------------------------------------------------------------------
# Panoramas

def write_panoramas(plan, results, blend):
    """Each panorama's FILE.exr and its compact form FILE/... (the unit's files, named relative
    to its private `panorama.exr`), every file of every panorama or none."""
    where = {name: resolve(path, blend) for name, path in plan["outputs"]}
    files, written = [], {}
    for result in results:
        final = where[result["camera"]]
        stem = os.path.splitext(final)[0]
        for rel, data in sorted(result["files"].items()):
            if rel == "panorama.exr":
                target = final
            elif rel.split(os.sep)[0] == "panorama":
                target = os.path.join(stem, *rel.split(os.sep)[1:])
            else:
                raise MergeError(f"panorama {result['camera']}: unexpected file {rel} from the unit")
            files.append((target, lambda path, data=data: _write_bytes(path, data)))
        written[result["camera"]] = final
    write_all(files)
    return written
