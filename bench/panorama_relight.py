"""Relight speed of a baked panorama (issue 13): relights per second and the memory
bandwidth reached, 8-bit and float16 maps, AVX2 and the portable code; plus the bake time,
file sizes and the 8-bit quantization error of the same panorama. Writes
docs/benchmarks_panorama.md.

    PYTHONPATH=native/python .venv/bin/python bench/panorama_relight.py [--size 1024x512] [--coefficients 16]

Relights go into one preallocated float32 (H, W, 3) array (file output excluded). Each case
runs for --seconds; the page gives the best and the median wall time per relight (the best
is what the code does on an idle machine; on a loaded one the median shows the load), the
process CPU time per relight (both cores' work summed), and the best time of the AVX2 cases
on one thread (a second process with RAYON_NUM_THREADS=1): on a shared machine, what one
core does when it gets its turn.
"""

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

import numpy as np
import trimesh

import hemishadow
from hemishadow import panorama as pano
from hemishadow.environment import default_hdri

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def scene():
    """A small room-sized scene: a floor, a back wall, a box, a sphere, a column (about 4k
    triangles), seen from (0, 0, 0.2)."""
    parts = [trimesh.creation.box((8, 8, 0.2)).apply_translation((0, 0, -1.1)),
             trimesh.creation.box((0.2, 8, 3)).apply_translation((3.5, 0, 0.4)),
             trimesh.creation.box((0.8, 0.8, 1.4)).apply_translation((1.6, 0.9, -0.3)),
             trimesh.creation.icosphere(4, 0.6).apply_translation((-1.4, -1.2, -0.4)),
             trimesh.creation.cylinder(0.25, 3.0, sections=48).apply_translation((-1.0, 1.8, 0.4))]
    s = hemishadow.Scene()
    for m in parts:
        s.add_instance(s.add_mesh(m.vertices.astype(np.float32), m.faces.astype(np.uint32)))
    return s, sum(len(m.faces) for m in parts)


def timed(fn, seconds):
    fn()
    walls, cpu0, n = [], time.process_time(), 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds or n < 5:
        t = time.perf_counter()
        fn()
        walls.append(time.perf_counter() - t)
        n += 1
    cpu = (time.process_time() - cpu0) / n
    return min(walls), float(np.median(walls)), cpu


def cpu_name():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def commit():
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    except OSError:
        return "?"


def cases_for(bands):
    env_sh = hemishadow.project_environment(os.fspath(default_hdri()), bands=bands)
    return {
        "sun": [pano.Sun((0.4, 0.3, 1.0), 3.0)],
        "environment": [pano.Environment(env_sh)],
        "point": [pano.Point((0.5, -0.8, 0.6), 150.0)],
        "sun + point + environment": [pano.Sun((0.4, 0.3, 1.0), 3.0), pano.Point((0.5, -0.8, 0.6), 150.0),
                                      pano.Environment(env_sh)],
    }


def single_thread(files, seconds):
    """{maps: {case: best seconds}} of the AVX2 cases in a process with one rayon thread."""
    env = dict(os.environ, RAYON_NUM_THREADS="1")
    done = subprocess.run([sys.executable, os.path.abspath(__file__), "--single", *files, "--seconds", str(seconds)],
                          env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout)


def run_single(files, seconds):
    result = {}
    for maps, path in zip(("8bit", "float16"), files):
        source = pano.Panorama.load(path)
        out = np.empty((source.height, source.width, 3), np.float32)
        result[maps] = {name: timed(lambda: pano.relight(source, lights, maps=maps, out=out), seconds)[0]
                        for name, lights in cases_for(source.bands).items()}
    print(json.dumps(result))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--single", nargs=2, metavar=("JSON", "EXR"), help=argparse.SUPPRESS)
    parser.add_argument("--size", default="1024x512")
    parser.add_argument("--coefficients", type=int, choices=(9, 16, 25), default=16)
    parser.add_argument("--seconds", type=float, default=3.0, help="time per relight case")
    parser.add_argument("--out", default=os.path.join(ROOT, "docs", "benchmarks_panorama.md"))
    args = parser.parse_args(argv)
    if args.single:
        return run_single(args.single, args.seconds)
    width, height = (int(v) for v in args.size.split("x"))
    bands = int(round(args.coefficients ** 0.5))
    load_before = os.getloadavg()[0]

    s, triangles = scene()
    origin = (0.0, 0.0, 0.2)
    t = time.perf_counter()
    hits = pano.primary_hits(s, origin, size=(width, height))
    hits_time = time.perf_counter() - t
    t = time.perf_counter()
    baked = pano.bake(s, origin, size=(width, height), bands=bands, hits=hits)
    bake_time = time.perf_counter() - t
    print(f"bake: hits {hits_time:.2f} s, transfer {bake_time:.1f} s", file=sys.stderr)

    with tempfile.TemporaryDirectory() as tmp:
        files = [os.path.join(tmp, "c", "panorama.json"), os.path.join(tmp, "p.exr")]
        exr = baked.save(files[1])
        small = baked.save(files[0])
        loaded = pano.Panorama.load(files[0])
        position_bytes = os.path.getsize(os.path.join(tmp, "c", "position.f32"))
        one_thread = single_thread(files, args.seconds)

    cases = cases_for(bands)
    # Quantization: the 8-bit maps against the float16 ones, relit.
    quant = {}
    for name in ("sun", "environment", "point"):
        a = pano.relight(loaded, cases[name], maps="8bit")
        b = pano.relight(baked, cases[name], maps="float16")
        peak = np.abs(b[baked.mask]).max()
        d = np.abs(a - b)[baked.mask] / peak
        quant[name] = (float(d.max()), float(np.percentile(d, 99)), float(d.mean()),
                       float(np.mean(np.abs(np.rint(np.clip(a, 0, 1) ** (1 / 2.2) * 255)
                                             - np.rint(np.clip(b, 0, 1) ** (1 / 2.2) * 255)) <= 1)))
    out = np.empty((height, width, 3), np.float32)
    rows = []
    for maps, source in (("8bit", loaded), ("float16", baked)):
        relighter = source.relighter(maps)
        for simd in (True, False):
            for name, lights in cases.items():
                if not simd and name != "sun" and name != "point":
                    continue
                seconds = args.seconds if simd else min(args.seconds, 1.0)
                best, median, cpu = timed(lambda: pano.relight(source, lights, maps=maps, out=out, simd=simd), seconds)
                points = any(isinstance(light, pano.Point) for light in lights)
                read = relighter.bytes_read(points) + out.nbytes
                single = one_thread[maps].get(name) if simd else None
                rows.append((maps, "AVX2" if simd else "portable", name, best, median, cpu, read / best / 1e9, single))
                print(f"{maps} {rows[-1][1]} {name}: {1 / best:.0f}/s best, {1 / median:.0f}/s median", file=sys.stderr)
    load_after = os.getloadavg()[0]
    write_page(args, width, height, triangles, hits_time, bake_time, exr, small, position_bytes, quant, rows,
               load_before, load_after)


def write_page(args, width, height, triangles, hits_time, bake_time, exr, small, position_bytes, quant, rows,
               load_before, load_after):
    k = args.coefficients
    lines = [
        "# Panorama relighting: speed, sizes, 8-bit error (issue 13)",
        "",
        f"Measured by `PYTHONPATH=native/python .venv/bin/python bench/panorama_relight.py --size {args.size} "
        f"--coefficients {k}` on **{cpu_name()}**, {os.cpu_count()} cores (AVX2 kernel: "
        f"{'yes' if hemishadow._native.Relighter.simd_available() else 'no'}), "
        f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, commit {commit()}, load average "
        f"{load_before:.2f} before the run and {load_after:.2f} after (other work shared the 2 cores: the best "
        "times are the code's, the medians show the load).",
        "",
        f"Scene: a floor, a wall, a box, a sphere and a column ({triangles} triangles) seen from (0, 0, 0.2); "
        f"{width} x {height} pixels, {k} SH coefficients per pixel and channel, albedo 0.8.",
        "",
        "## Relight speed",
        "",
        "Into a preallocated float32 (H, W, 3) array, file output excluded; `relight()` as called from Python "
        "(light set-up included). GB/s = bytes the kernel reads (maps, positions for point lights) plus the "
        "output it writes, per best time.",
        "",
        "| maps | code | lights | relights/s (best) | relights/s (median) | CPU ms per relight | GB/s (best) "
        "| 1 thread: relights/s (best) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for maps, code, name, best, median, cpu, gbs, single in rows:
        one = f"{1 / single:.0f}" if single else "-"
        lines.append(f"| {maps} | {code} | {name} | {1 / best:.0f} | {1 / median:.0f} | {cpu * 1e3:.1f} | {gbs:.1f} "
                     f"| {one} |")
    target = {r[2]: r for r in rows if r[0] == "8bit" and r[1] == "AVX2"}
    lines += [
        "",
        f"Targets ({width} x {height} x {k}, 2 cores, from the 8-bit maps): directional >= 200/s: "
        f"{1 / target['sun'][3]:.0f}/s best ({'met' if 1 / target['sun'][3] >= 200 else 'not met'}); point light "
        f">= 60/s: {1 / target['point'][3]:.0f}/s best ({'met' if 1 / target['point'][3] >= 60 else 'not met'}). "
        "Wong et al.: 114 and about 20 per second on a GeForce3 at 1024 x 256.",
        "",
        "## Bake and files",
        "",
        f"- Bake of {width} x {height} x {k}: primary visibility (BVH ray cast) {hits_time:.2f} s, transfer "
        f"{bake_time:.1f} s.",
        f"- Float EXR (HALF maps, FLOAT position, normal, depth): {exr['bytes'] / 1e6:.2f} MB.",
        f"- Compact form: {small['bytes'] / 1e6:.2f} MB in all, of which the {k} 8-bit PNG maps "
        f"{small['map_bytes'] / 1e6:.2f} MB and position.f32 {position_bytes / 1e6:.2f} MB "
        f"(Wong et al.: 2.8 and 3.6 MB for 16 maps of 1024 x 256).",
        f"- 8-bit quantization: largest coefficient error {small['max_quantization_error']:.3g} (each map's "
        "error is at most its range / 510).",
        "",
        "Relit from the 8-bit maps against the float16 maps (relative to the brightest pixel):",
        "",
        "| lights | max | 99th percentile | mean | pixels within 1/255 after a 2.2 gamma |",
        "|---|---|---|---|---|",
    ]
    for name, (mx, p99, mean, within) in quant.items():
        lines.append(f"| {name} | {mx * 100:.2f} % | {p99 * 100:.2f} % | {mean * 100:.3f} % | {within * 100:.1f} % |")
    with open(args.out, "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"wrote {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
