"""What runs on a farm worker: open the .blend, register the add-on, run one work unit.

A unit is a plain dict (JSON-able: it also goes to a `blender -b` subprocess as a file):
  kind    "plan", "bake", "lightmaps", "probes" or "panorama"
  blend   path of the .blend as the workers see it (or its name, when the bytes are sent)
  args    the subcommand's own options, parsed here by the add-on's own parser (addon/cli.py),
          so the farm takes exactly the options of `blender -b FILE --command hemishadow ...`
  addon   folder holding the add-on package `addon/` (a source checkout), or None: the add-on
          must then be installed and enabled in the worker's Blender (the extension)
  plus    bake: object, frames [a, b], start (the whole bake's); lightmaps: object; probes: block
          [a, b] (probe indices); panorama: camera (None: the command's own viewpoint)

Results are dicts of numpy arrays and numbers (`seconds`: open = opening the .blend and
registering, setup = reading the scene into the engine, work = the unit's own computation).

This module imports only the standard library at the top, so that Blender's own Python (no
dask) can run it as a script: `blender -b FILE --python worker.py -- UNIT.json RESULT.pickle`.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import os
import pickle
import socket
import subprocess
import sys
import tempfile
import time


class FarmError(RuntimeError):
    """A unit that cannot run here: the message names the worker and what to do."""


def _where() -> str:
    return f"worker {socket.gethostname()} (pid {os.getpid()})"


# ---------------------------------------------------------------------------------------
# The add-on and the .blend

_package = None


def addon_package(addon_dir):
    """The add-on's package, registered once per process: from `addon_dir` (a folder with
    `addon/`) or, with None, the one an enabled extension registered."""
    global _package
    if addon_dir and not os.path.isfile(os.path.join(addon_dir, "addon", "__init__.py")):
        raise FarmError(f"{_where()}: the hemishadow add-on is not in {addon_dir} (no addon/__init__.py): "
                        "give --addon a checkout the workers can read, or install the extension on them")
    if _package is not None:
        return _package
    bpy = _import_bpy()

    if addon_dir:
        if addon_dir not in sys.path:
            sys.path.insert(0, addon_dir)
        package = importlib.import_module("addon")
        if not hasattr(bpy.types.Object, "hemishadow"):
            package.register()
    else:
        package = next((m for name, m in sys.modules.items()
                        if name.endswith(".hemishadow") and name.startswith("bl_ext.")), None)
        if package is None or not hasattr(bpy.types.Object, "hemishadow"):
            raise FarmError(f"{_where()}: the hemishadow add-on is not enabled in this Blender: install the "
                            "extension on the workers or give --addon a checkout they can read")
    _package = package
    return package


def _import_bpy():
    """bpy, also in a process spawned by one that had imported it: the spawned process inherits
    its sys.path, where Blender's own `scripts/modules` (holding the inner `bpy` package) shadows
    the bpy module until the module itself is imported."""
    if "bpy" not in sys.modules:
        sys.path[:] = [p for p in sys.path if not (os.path.basename(p) == "modules"
                                                   and os.path.basename(os.path.dirname(p)) == "scripts"
                                                   and os.path.isdir(os.path.join(p, "bpy")))]
    import bpy

    return bpy


def module(name):
    return importlib.import_module(f"{_package.__name__}.{name}")


def local_blend(unit, blend_bytes):
    """The path to open: the shared path, or the sent bytes written once per process."""
    if blend_bytes is None:
        return unit["blend"]
    digest = hashlib.sha256(blend_bytes).hexdigest()[:16]
    folder = os.path.join(tempfile.gettempdir(), f"hemishadow-farm-{os.getpid()}", digest)
    path = os.path.join(folder, os.path.basename(unit["blend"]))
    if not os.path.isfile(path):
        os.makedirs(folder, exist_ok=True)
        with open(path + ".part", "wb") as handle:
            handle.write(blend_bytes)
        os.replace(path + ".part", path)
    return path


def open_blend(path):
    import bpy

    if not os.path.isfile(path):
        raise FarmError(f"{_where()} cannot open {path}: no such file here (not on a path the workers share? "
                        "use --send-blend)")
    try:
        bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
    except RuntimeError as error:
        raise FarmError(f"{_where()} cannot open {path}: {str(error).strip()}") from None


# ---------------------------------------------------------------------------------------
# Units

def run(unit, blend_bytes=None):
    """A dask task (workers that import bpy): open, register, run the unit."""
    addon_package(unit.get("addon"))   # once per worker process (importing bpy: seconds)
    t0 = time.perf_counter()
    open_blend(local_blend(unit, blend_bytes))
    return _run_open(unit, time.perf_counter() - t0)


def _run_open(unit, open_seconds):
    result = _KINDS[unit["kind"]](unit)
    result["seconds"]["open"] = open_seconds
    result["worker"] = _where()
    return result


def _parse(kind, args):
    cli = module("cli")
    try:
        return cli.build_parser().parse_args([kind, *args])
    except cli.UsageError as error:
        raise FarmError(str(error).replace(cli.PROG, "hemishadow farm")) from None


def _plan(unit):
    """What the units are: objects, frames, probe counts and where the outputs go."""
    import bpy

    t0 = time.perf_counter()
    kind, args = unit["args"][0], _parse(unit["args"][0], unit["args"][1:])
    cli = module("cli")
    scene = cli._scene(args.scene)
    plan = dict(kind=kind, blend=bpy.data.filepath)
    if kind == "bake":
        objects = cli._objects(scene, args.objects)
        start = scene.frame_start if args.start is None else args.start
        end = scene.frame_end if args.end is None else args.end
        if end < start:
            raise FarmError(f"hemishadow farm: error: --end {end} is before --start {start}")
        cache = module("cache")
        depsgraph = bpy.context.evaluated_depsgraph_get()
        plan.update(objects=[o.name for o in objects], frames=[start, end], simulated=_simulated(scene),
                    vertices={o.name: len(o.evaluated_get(depsgraph).data.vertices) for o in objects},
                    outputs={o.name: cache.cache_path(o, args.cache_dir) for o in objects},
                    pack=args.pack, save=args.save, cache_dir=args.cache_dir)
    elif kind == "lightmaps":
        found = module("lightmaps_cli").objects(scene, args, lambda m: FarmError(f"hemishadow farm: error: {m}"))
        names = [o.name for o in found]
        atlas = _atlas(args, found)   # one unit for an atlas: its layout and padding span every object
        plan.update(objects=names, outputs=[atlas] if atlas else names, folder=args.out or "//lightmaps")
    elif kind == "probes":
        import numpy as np

        probes, probes_cli = module("probes"), module("probes_cli")
        volume, points = probes_cli.target(scene, args, lambda m: FarmError(f"hemishadow farm: error: {m}"))
        count = len(points) if volume is None else int(np.prod(probes.grid_of(volume, args.resolution)[1]))
        name = volume.name if volume else "points"
        plan.update(count=count, output=args.out or f"//probes/{module('lightmaps')._safe(name)}.npz")
    elif kind == "panorama":
        plan.update(_panorama_plan(scene, args, unit.get("cameras")))
    return dict(plan=plan, seconds=dict(setup=time.perf_counter() - t0, work=0.0))


def _panorama_modules():
    try:
        return module("panorama_bake"), module("panorama_cli")
    except ImportError:
        raise FarmError(f"{_where()}: this hemishadow add-on has no panorama baker (addon/panorama_cli.py)") from None


def _panorama_plan(scene, args, cameras):
    """One panorama per camera (`--cameras`, else the command's own --camera / --at / the scene
    camera); where each goes, `//`-relative to the .blend as the headless command names it."""
    import bpy

    bake, _ = _panorama_modules()
    cameras = list(cameras or [args.camera])
    if len(cameras) > 1 and (args.out or args.at):
        raise FarmError("hemishadow farm: error: --cameras bakes one panorama per camera to "
                        "//panoramas/<camera>.exr: leave out --out and --at")
    for name in cameras:
        if name is not None and scene.objects.get(name) is None:
            raise FarmError(f"hemishadow farm: error: no camera or Empty named {name!r} in scene {scene.name!r}")
    outputs = [[name, args.out or bpy.path.relpath(bake.output_path(name, None))] for name in cameras]
    return dict(cameras=cameras, outputs=outputs)


def _simulated(scene):
    """Objects whose shape depends on the frames before (cloth, soft body, dynamic paint, fluid,
    particles, geometry-node simulation): their frames cannot be computed out of order."""
    kinds = {"CLOTH", "SOFT_BODY", "DYNAMIC_PAINT", "FLUID", "PARTICLE_SYSTEM", "OCEAN"}
    out = []
    for obj in scene.objects:
        for mod in getattr(obj, "modifiers", ()):
            if mod.type in kinds or (mod.type == "NODES" and mod.node_group is not None
                                     and any(n.bl_idname == "GeometryNodeSimulationInput"
                                             for n in mod.node_group.nodes)):
                out.append(obj.name)
                break
    return out


def _bake(unit):
    """Frames a..b of one object, through the add-on's own bake job (into a private folder)."""
    cli, cache, mesh_io = module("cli"), module("cache"), module("mesh_io")
    bake = module("operators.bake")
    t0 = time.perf_counter()
    args = _parse("bake", unit["args"])
    scene = cli._scene(args.scene)
    objects = cli._objects(scene, args.objects)   # the same flags as a single-machine bake
    obj = next((o for o in objects if o.name == unit["object"]), None)
    if obj is None:
        raise FarmError(f"{_where()}: {unit['object']}: not among the objects to bake in {unit['blend']}")
    a, b = unit["frames"]
    setup = time.perf_counter() - t0
    with tempfile.TemporaryDirectory(prefix="hemishadow-unit-") as folder:
        t1 = time.perf_counter()
        job = bake.BakeJob(scene, [obj], a, b, location="FILE", directory=folder,
                           store_transfer=not args.no_transfer)
        try:
            if a != unit["start"]:
                _seed_solver(job, obj, unit["start"], scene, mesh_io, bake)
            while not job.step(budget_seconds=0.5):
                pass
        except BaseException:
            job.abort()
            raise
        with open(os.path.join(folder, os.path.basename(cache.cache_path(obj, folder))), "rb") as handle:
            baked = cache.BakeCache.from_bytes(handle.read())
    arrays = {k: getattr(baked, k) for k in ("radiance", "ao", "transfer", "fingerprint", "casters")}
    return dict(object=obj.name, frames=[a, b], arrays=arrays, meta=baked.meta,
                seconds=dict(setup=setup, work=time.perf_counter() - t1))


def _seed_solver(job, obj, start, scene, mesh_io, bake):
    """The solver a single-machine bake builds on its first frame: its hierarchy is built from
    the rest pose placed by that frame's matrix (a moving object's translation enters it), so
    building it on this unit's first frame would round differently in the last bits."""
    import bpy

    scene.frame_set(start)
    vertices, triangles, _, frame = mesh_io.read_in_frame(obj, bpy.context.evaluated_depsgraph_get())
    key = (len(vertices), hash(triangles.tobytes()))   # BakeJob._frame_input's key
    job._solvers[obj.name] = (key, bake._make_solver(obj, vertices, triangles, frame.matrix))


def _atlas(args, found):
    """The atlas's name when the headless command would bake one (several objects, no --uv,
    no --per-object: lightmaps_cli.run), else None."""
    if args.per_object or args.uv is not None or len(found) < 2:
        return None
    return module("lightmap_atlas").atlas_name(args.atlas)


def _lightmaps(unit):
    """One object's lightmap: the scene read as for the whole bake (same engine scene, same
    bounce receivers in the same order), the engine's bake run on this target only."""
    import warnings

    import hemishadow.lightmap as lm

    cli, lightmaps = module("cli"), module("lightmaps")
    t0 = time.perf_counter()
    args = _parse("lightmaps", unit["args"])
    scene = cli._scene(args.scene)
    found = module("lightmaps_cli").objects(scene, args, lambda m: FarmError(f"hemishadow farm: error: {m}"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        prepared = lightmaps.prepare(scene, found, uv_name=args.uv or args.islands,
                                     layout="ATLAS" if _atlas(args, found) else "OBJECT", atlas_name=args.atlas,
                                     resolution=args.resolution, texel_density=args.texel_density, basis=args.basis,
                                     bounces=args.bounces, samples=args.samples, adaptive=not args.uniform,
                                     margin=args.margin)
    if prepared.atlas:
        t1 = time.perf_counter()
        maps = lightmaps.compute(prepared)[0]
        return dict(object=unit["object"], maps=maps, warnings=[str(w.message) for w in caught],
                    seconds=dict(setup=t1 - t0, work=time.perf_counter() - t1))
    k = lightmaps.baked_names(prepared.targets).index(unit["object"])
    # Every target's surface among the surfaces, in the whole bake's order: the engine keeps the
    # first of each mesh, so the bounce receivers are the single-machine bake's.
    surfaces = list(prepared.surfaces) + [t.surface for t in prepared.targets]
    setup = time.perf_counter() - t0
    t1 = time.perf_counter()
    maps = lm.bake(prepared.engine_scene, [prepared.targets[k]], resolution=[prepared.resolutions[k]],
                   lighting=prepared.lighting, suns=prepared.suns, surfaces=surfaces, bounce_scene=prepared.bounce_scene,
                   **prepared.options)[0]
    return dict(object=unit["object"], maps=maps, warnings=[str(w.message) for w in caught],
                seconds=dict(setup=setup, work=time.perf_counter() - t1))


def _probes(unit):
    """Probes a..b of the grid (or point list), without the fill of invalid probes, which needs
    every probe (merge.py does it)."""
    import numpy as np

    import hemishadow.probes as hp

    cli, probes, lightmaps = module("cli"), module("probes"), module("lightmaps")
    t0 = time.perf_counter()
    args = _parse("probes", unit["args"])
    scene = cli._scene(args.scene)
    volume, points = module("probes_cli").target(scene, args, lambda m: FarmError(f"hemishadow farm: error: {m}"))
    engine_scene, surfaces, world = probes.scene_geometry(scene)
    cell, extra = None, {}
    if volume is not None:
        matrix, res = probes.grid_of(volume, args.resolution)
        m = hp.grid.matrix4(matrix)
        res = hp.grid.resolution3(res)
        points, cell = hp.grid.grid_points(m, res), m[:3, :3]
        extra = dict(grid_matrix=m.astype(np.float64), grid_resolution=res)
    a, b = unit["block"]
    block = np.asarray(points, np.float64)[a:b]
    setup = time.perf_counter() - t0
    t1 = time.perf_counter()
    result = hp.bake(engine_scene, block, lighting=lightmaps.lighting_of(scene), suns=lightmaps.suns_of(scene),
                     surfaces=surfaces, bounces=args.bounces, cell=cell)
    # The fill measures distances in float64 from the (moved) points: keep them exact.
    exact = np.where(result["moved"][:, None], result["positions"].astype(np.float64), block)
    result.update(extra, exact=exact, world_lo=world.min(axis=1), world_hi=world.max(axis=1))
    return dict(block=[a, b], result=result, volume=volume.name if volume else None,
                seconds=dict(setup=setup, work=time.perf_counter() - t1))


def _panorama(unit):
    """One panorama through the headless command's own run (its checks, its files), written to
    a private folder; the files come back as bytes, named relative to FILE.exr's stem."""
    _, command = _panorama_modules()
    cli = module("cli")
    t0 = time.perf_counter()
    args = _parse("panorama", unit["args"])
    if unit.get("camera") is not None:
        args.camera = unit["camera"]
    scene = cli._scene(args.scene)
    setup = time.perf_counter() - t0
    with tempfile.TemporaryDirectory(prefix="hemishadow-unit-") as folder:
        t1 = time.perf_counter()
        args.out = os.path.join(folder, "panorama.exr")
        command.run(scene, args, lambda m: FarmError(f"hemishadow farm: error: {m}"), None)
        files = {}
        for root, _, names in os.walk(folder):
            for name in names:
                path = os.path.join(root, name)
                with open(path, "rb") as handle:
                    files[os.path.relpath(path, folder)] = handle.read()
    return dict(camera=unit.get("camera"), files=files, seconds=dict(setup=setup, work=time.perf_counter() - t1))


_KINDS = {"plan": _plan, "bake": _bake, "lightmaps": _lightmaps, "probes": _probes, "panorama": _panorama}


# ---------------------------------------------------------------------------------------
# The subprocess mode: `blender -b FILE --python worker.py -- UNIT.json RESULT.pickle`

def run_subprocess(unit, blend_bytes=None, blender="blender"):
    """A dask task (workers without bpy): the unit in a `blender -b` process of its own."""
    with tempfile.TemporaryDirectory(prefix="hemishadow-unit-") as folder:
        unit_file, result_file = os.path.join(folder, "unit.json"), os.path.join(folder, "result.pickle")
        with open(unit_file, "w") as handle:
            json.dump(unit, handle)
        blend = local_blend(unit, blend_bytes)
        command = [blender, "-b", blend, "--python", os.path.abspath(__file__), "--", unit_file, result_file]
        try:
            done = subprocess.run(command, capture_output=True, text=True)
        except FileNotFoundError:
            raise FarmError(f"{_where()}: no Blender executable {blender!r} here: give --blender PATH or use "
                            "--worker-mode bpy") from None
        if not os.path.isfile(result_file):
            tail = "\n".join((done.stderr or done.stdout).strip().splitlines()[-5:])
            raise FarmError(f"{_where()}: {blender} -b exited with {done.returncode} and no result: {tail}")
        with open(result_file, "rb") as handle:
            outcome = pickle.load(handle)
    if "error" in outcome:
        raise FarmError(outcome["error"])
    return outcome["result"]


def _main_in_blender(argv):
    """Inside `blender -b FILE --python worker.py -- UNIT RESULT`: the file is open already."""
    unit_file, result_file = argv[argv.index("--") + 1:][:2]
    with open(unit_file) as handle:
        unit = json.load(handle)
    try:
        addon_package(unit.get("addon"))
        outcome = dict(result=_run_open(unit, 0.0))   # Blender opened the file before this script
    except FarmError as error:
        outcome = dict(error=str(error))
    except Exception as error:  # any other failure: named, for the client
        outcome = dict(error=f"{_where()}: {unit['kind']} unit failed: {type(error).__name__}: {error}")
    with open(result_file + ".part", "wb") as handle:
        pickle.dump(outcome, handle)
    os.replace(result_file + ".part", result_file)


if __name__ == "__main__" and "--" in sys.argv:
    _main_in_blender(sys.argv)
