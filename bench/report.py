"""docs/benchmarks.md and docs/images/bench_*.png from bench/results.json.

    .venv/bin/python bench/report.py [bench/results.json]

A quick run's JSON is reported to bench/quick/ instead of docs/.
"""

import json
import math
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent
DEFAULT = "hierarchy + cull (default)"
TARGET_MEDIAN = 0.04
TITLES = {
    "cloth": "cloth (Blender cloth sim over a sphere)",
    "suzanne_2k": "Suzanne, subdivision 1",
    "suzanne_8k": "Suzanne, subdivision 2",
    "suzanne_32k": "Suzanne, subdivision 3",
    "cesium_man": "cesium_man.glb (walk)",
    "fox": "fox.glb (Survey)",
    "rigged_figure": "rigged_figure.glb",
}
MARKERS = {"exact": "s", "exact + cull": "D", "hierarchy": "^", DEFAULT: "o", "hierarchy + cull, ring 1": "v",
           "hierarchy + cull, coarse x4": "P"}


def interp_time(target, points):
    """Time to reach error `target` on a measured curve [(error, ms)] ordered by cost (rays or
    samples): log-log interpolation between the last point above the target and the first
    at or below it; beyond the dearest point, extrapolated with time ~ error^-2 (Monte Carlo)
    unless the curve has flattened into a floor ('not reached'); when the cheapest point is
    already as accurate, its time ('at most'). -> (ms, how)."""
    pts = sorted((t, e) for e, t in points if e > 0 and t > 0)
    if len(pts) < 2:
        return float("nan"), "n/a"
    lt, le = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    x = math.log(target)
    below = [k for k in range(len(pts)) if le[k] <= x]
    if below and below[0] > 0:
        i, how = below[0] - 1, "interpolated"
    elif below:  # the cheapest measured point is already as good: its time is an upper bound
        return float(math.exp(lt[0])), "at most"
    else:  # more accurate than the dearest point: extend it by the Monte-Carlo law, time ~ error^-2,
        # unless the curve has flattened there (a systematic floor, not noise)
        slope = (lt[-1] - lt[-2]) / (le[-1] - le[-2]) if le[-1] < le[-2] else -np.inf
        if slope < -4.0:
            return float("nan"), "not reached"
        return float(math.exp(lt[-1] - 2.0 * (x - le[-1]))), "extrapolated"
    slope = (lt[i + 1] - lt[i]) / (le[i + 1] - le[i]) if le[i + 1] != le[i] else 0.0
    return float(math.exp(lt[i] + slope * (x - le[i]))), how


def xfmt(x):
    return f"{x:.1f}x" if np.isfinite(x) else "–"


def pct(x):
    return "–" if x is None or not np.isfinite(x) else f"{100 * x:.2f} %"


def fmt_ms(x):
    return f"{x:.1f}" if x >= 10 else f"{x:.2f}"


def mesh_table(name, m):
    rows = ["| method | ms / frame | FPS | blockers / vertex | ns / triangle | median | mean (AO ≥ 0.1) "
            "| occluded mean | AO < 0.1: abs. error | AO mean abs. error | frames |",
            "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in m["hemishadow"]:
        e = r["error"]
        coarse = f" ({r['coarse_triangles']} coarse tris)" if r.get("coarse_triangles") else ""
        rows.append(f"| hemishadow {r['method']}{coarse} | {fmt_ms(r['ms'])} | {r['fps']:.0f} | {r['blockers_per_vertex']:.0f} "
                    f"| {r['ns_per_triangle']:.0f} | {pct(e['median'])} | {pct(e['mean'])} | {pct(e['occluded_mean'])} "
                    f"| {e['dark_abs_error_mean']:.3f} ({e['n_dark']:.0f} vertices) | {e['ao_mean_abs']:.4f} | {r['frames_timed']} |")
    for r in m["embree"]:
        e = r["error"]
        rows.append(f"| {r['method']} (1 core) | {fmt_ms(r['ms'])} | {r['fps']:.1f} | | | {pct(e['median'])} | {pct(e['mean'])} "
                    f"| {pct(e['occluded_mean'])} | {e['dark_abs_error_mean']:.3f} | {e['ao_mean_abs']:.4f} | {r['frames_timed']} |")
    for r in m["cycles"]:
        rows.append(f"| {r['method']} (bake call) | {fmt_ms(r['ms'])} | {1e3 / r['ms']:.1f} | | | | | | | {r['ao_mean_abs']:.4f} | 1 |")
    return "\n".join(rows)


def comparisons(m):
    """Speed-ups of hemishadow's default at its own error, against Embree's and Cycles' curves."""
    d = next((r for r in m["hemishadow"] if r["method"] == DEFAULT), None)
    if d is None:
        return None
    emb = [(r["error"]["median"], r["ms"]) for r in m["embree"]]
    t_emb, how_emb = interp_time(d["error"]["median"], emb)
    emb_ao = [(r["ao_first_frame"], r["ms"]) for r in m["embree"]]
    cyc = [(r["ao_mean_abs"], r["ms"]) for r in m["cycles"]]
    t_cyc, how_cyc = interp_time(d["ao_first_frame"], cyc)
    t_emb_ao, _ = interp_time(d["ao_first_frame"], emb_ao)
    fast = [r for r in m["hemishadow"] if r["error"]["median"] <= TARGET_MEDIAN]
    best = min(fast, key=lambda r: r["ms"]) if fast else None
    best_emb = interp_time(best["error"]["median"], emb) if best else (float("nan"), "n/a")
    return {"default": d, "embree_ms": t_emb, "embree_how": how_emb, "speedup_embree": t_emb / d["ms"],
            "cycles_ms": t_cyc, "cycles_how": how_cyc, "speedup_cycles": t_cyc / d["ms"],
            "embree_ao_ms": t_emb_ao, "best": best, "best_embree_ms": best_emb[0],
            "best_speedup": best_emb[0] / best["ms"] if best else float("nan")}


def plot_error(results, key, label, path, target=None):
    names = list(results["meshes"])
    cols = min(4, len(names))
    rows = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.6 * rows), squeeze=False)
    for ax, name in zip(axes.ravel(), names):
        m = results["meshes"][name]
        if m["embree"]:
            xs = [r["ms"] for r in m["embree"]]
            ys = [key(r) for r in m["embree"]]
            ax.plot(xs, ys, "-", color="tab:gray", marker=".", label="Embree, N rays (1 core)")
            ax.plot([x / 2 for x in xs], ys, ":", color="tab:gray", label="Embree ideal on 2 cores (time / 2)")
            for r, x, y in zip(m["embree"], xs, ys):
                ax.annotate(str(r["rays"]), (x, y), textcoords="offset points", xytext=(3, 3), fontsize=7, color="tab:gray")
        if "cycles" in label.lower() or label.startswith("AO"):
            if m["cycles"]:
                ax.plot([r["ms"] for r in m["cycles"]], [r["ao_mean_abs"] for r in m["cycles"]], "-", marker="x",
                        color="tab:red", label="Cycles AO bake, samples")
                for r in m["cycles"]:
                    ax.annotate(str(r["samples"]), (r["ms"], r["ao_mean_abs"]), textcoords="offset points",
                                xytext=(3, 3), fontsize=7, color="tab:red")
        for r in m["hemishadow"]:
            ax.plot([r["ms"]], [key(r)], linestyle="none", marker=MARKERS.get(r["method"], "o"),
                    label="hemishadow " + r["method"], markersize=7 if r["method"] == DEFAULT else 5)
        if target:
            ax.axhline(target, color="k", lw=0.6, ls="--")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(f"{name} ({m['vertices']} vertices)", fontsize=9)
        ax.set_xlabel("ms per frame")
        ax.set_ylabel(label, fontsize=8)
        ax.grid(True, which="both", lw=0.3)
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    handles, labels = [], []
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    if len(names) % cols:
        fig.tight_layout()
        free = axes.ravel()[len(names)]
        free.legend(handles, labels, loc="center", fontsize=8, frameon=False)
    else:
        fig.tight_layout(rect=(0, 0.12, 1, 1))
        fig.legend(handles, labels, loc="lower center", fontsize=7, ncol=3, frameon=False)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_linear(results, path):
    sizes = [n for n in ("suzanne_2k", "suzanne_8k", "suzanne_32k") if n in results["meshes"]]
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    fits = {}
    methods = [lab for lab in MARKERS]
    for method in methods:
        xs, ys = [], []
        for n in sizes:
            r = next((r for r in results["meshes"][n]["hemishadow"] if r["method"] == method), None)
            if r:
                xs.append(results["meshes"][n]["vertices"] * r["blockers_per_vertex"])
                ys.append(r["ms"])
        if not xs:
            continue
        ax.plot(xs, ys, linestyle="-" if method == DEFAULT else "none", marker=MARKERS[method], label=method)
        xs, ys = np.array(xs), np.array(ys)
        fits[method] = float((xs * ys).sum() / (xs * xs).sum())  # ms per (vertex x blocker)
    if DEFAULT in fits:
        grid = np.geomspace(5e4, 2e9, 50)
        ax.plot(grid, fits[DEFAULT] * grid, "k--", lw=0.7,
                label=f"linear fit to the default: {fits[DEFAULT] * 1e6:.1f} ns x V x blockers / frame")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("vertices x blockers per vertex (triangles rasterized per frame)")
    ax.set_ylabel("ms per frame (2 cores)")
    ax.set_title("Suzanne, subdivision 1 / 2 / 3: cost against work", fontsize=10)
    ax.grid(True, which="both", lw=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return fits


def build_markdown(results, images, fits):
    mach = results["machine"]
    cfg = results["config"]
    out = []
    w = out.append
    w("# Benchmarks\n")
    w(f"Measured by `{results['command']}` on **{mach['cpu']}**, {mach['cores']} cores "
      f"(AVX2 {'yes' if mach['avx2'] else 'no'}, AVX-512F {'yes' if mach['avx512f'] else 'no'}), "
      f"{mach['date'][:10]}, load average {mach['load_before'][0]:.2f} before the run "
      f"({mach['load_after'][0]:.2f} after; the run itself loads both cores), Blender {mach['blender']} (`bpy` module), "
      f"commit {mach['commit']}. The whole run took {results['seconds'] / 60:.1f} minutes. "
      f"Load average (1 min) at the start of each mesh: "
      + ", ".join(f"{n} {m.get('load_start', float('nan')):.2f}" for n, m in results["meshes"].items())
      + f". The numbers below are regenerated by that one command (`bench/report.py` redraws this page from `bench/results.json`).\n")
    w("## What is measured\n")
    w(f"- **Meshes**, each welded by position once, all methods on the same welded mesh, the same area-weighted "
      f"vertex normals and the same receiver offset (1e-3 x mean edge length of the first frame): "
      f"a 37 x 37 cloth dropped by Blender's cloth solver over a sphere (frames 24-48, every 4th; the sphere is "
      f"not part of the mesh; the rest pose is the flat sheet of frame 1); Suzanne with Subdivision Surface 1, 2, 3 applied, bent and twisted in numpy per "
      f"frame; the skinned glTF characters of `../shared/data`, {cfg['frames']} frames spread over their first action. "
      "Frame 0 of every mesh is its rest pose (flat cloth, undeformed Suzanne, bind pose): the solvers are built "
      "from it, as a live session would be; it is never timed nor evaluated.")
    w(f"- **Reference**: `tests/reference.py` `transfer_reference`, {cfg['n_side'] ** 2} stratified cosine rays per "
      f"receiver (Embree, control variate), on {cfg['receivers']} random receivers (all vertices when fewer), on "
      f"frames {', '.join(str(f) for f in cfg['eval_frames'])} of each mesh. Errors are `error_summary`: median of "
      "the per-vertex relative L2 error over all receivers, mean over those with AO >= 0.1, 'occluded mean' over "
      "those at least 10 % occluded; receivers with AO < 0.1 are reported apart as the absolute error relative "
      "to an unoccluded vector. AO error = mean |AO - AO_ref| with AO = T_0 / 0.886227.")
    w("- **hemishadow**: `TransferSolver(rest=first frame, offset=..., reuse=False, ...)`, built once, one warm-up "
      "`solve`, then `solve(vertices, normals)` timed per frame (moving frames, reuse off, so every receiver is "
      "computed); median over the frames timed (column 'frames'; fewer frames for the slow exact paths). "
      "'blockers / vertex' is `stats['blockers_per_vertex']` (triangles above the horizon actually rasterized per "
      f"receiver). **ns / triangle = ms per frame x {mach['cores']} cores / (vertices x blockers per vertex)**, i.e. "
      "core-nanoseconds per rasterized triangle, everything else (integration, SH rotation, culling, Python call) "
      "included. Variants: `exact` = `hierarchy=False, cull=False` (what `transfer` does), `exact + cull` = "
      "`hierarchy=False`, `hierarchy` = `cull=False`, default = hierarchy + cull, ring 2; `ring 1`; "
      "`coarse x4` = `coarse_triangles` 4 x the default's.")
    w(f"- **Embree** (`embreex`, Embree 2 through its Python binding): per frame a BVH build, N cosine-distributed "
      "rays per vertex (a Hammersley set randomly shifted per vertex, concentric map, lifted), first-hit queries, "
      "rays that hit a triangle incident to the receiver re-cast past it (the reference's and the engine's rule), "
      "and the control-variate projection T = T_open(n) - pi/N sum_blocked Y(d) on the 25 SH functions, for "
      f"N = {', '.join(str(n) for n in cfg['rays'])}; a different seed from the reference. **embreex holds the GIL: "
      "Embree runs on one core.** The comparison below therefore also gives Embree's time halved (ideal use of "
      "both cores), which is the fair figure for the 2-core target.")
    w("- **Cycles**: a mesh object of the same welded triangles, smooth with the same normals as custom normals, "
      "a plain material, `bpy.ops.object.bake(type='AO')` to a point color attribute (CPU, no denoising, no adaptive sampling, AO "
      "distance 10 x the bounding-box diagonal), timed around the bake call (scene sync and BVH included; a 1-sample "
      "warm-up bake first). Cycles bakes at the face corners and averages them per vertex. "
      f"Samples {', '.join(str(s) for s in cfg['cycles_samples'])} (a bake predicted to take more than "
      f"{cfg['cycles_limit']:.0f} s is skipped); on the first evaluated frame only, and compared on AO with "
      "everybody's AO on that frame.\n")

    w("## Targets (issue 4)\n")
    comps = {n: comparisons(m) for n, m in results["meshes"].items()}
    lines = []
    for n, c in comps.items():
        if c is None:
            continue
        d = c["default"]
        lines.append(f"| {n} | {results['meshes'][n]['vertices']} | {fmt_ms(d['ms'])} | {d['fps']:.0f} | {pct(d['error']['median'])} "
                     f"| {fmt_ms(c['embree_ms']) if np.isfinite(c['embree_ms']) else '–'} ({c['embree_how']}) | {c['speedup_embree']:.1f}x / {c['speedup_embree'] / 2:.1f}x "
                     f"| {pct(d['error']['mean'])} | {d['ao_first_frame']:.4f} | {fmt_ms(c['cycles_ms']) if np.isfinite(c['cycles_ms']) else '–'} ({c['cycles_how']}) "
                     f"| {xfmt(c['speedup_cycles'])} | {d['bytes_per_vertex']:.0f} |")
    w("hemishadow's default (hierarchy + cull, ring 2) against the peers **at the same error**: Embree's and "
      "Cycles' time at hemishadow's error is read off their measured error-versus-time curves (log-log "
      "interpolation between the two neighbouring ray / sample counts; 'extrapolated' with time ~ error^-2 when "
      "hemishadow's error lies below the measured range, 'not reached' when the peer's curve has flattened into a "
      "floor there, 'at most' when the peer's cheapest setting is already as accurate).\n")
    w("| mesh | vertices | ms / frame | FPS | median error | Embree ms at that median | speed-up vs Embree 1 core / 2 cores "
      "| mean error (AO ≥ 0.1) | AO abs. error | Cycles ms at that AO error | speed-up vs Cycles | solver bytes / vertex |")
    w("|---|---|---|---|---|---|---|---|---|---|---|---|")
    out.extend(lines)
    w("")
    w("Every hemishadow variant at its own error (speed-up = peer's time at that error / hemishadow's time; "
      "Embree on 1 core as measured, Cycles as measured; '≤' when even the cheapest peer setting is more accurate):\n")
    variants = [r["method"] for r in next(iter(results["meshes"].values()))["hemishadow"]]
    variants = list(dict.fromkeys(r["method"] for m in results["meshes"].values() for r in m["hemishadow"]))
    w("| mesh | " + " | ".join(variants) + " |")
    w("|---|" + "---|" * len(variants))
    for n, m in results["meshes"].items():
        cells = []
        for v in variants:
            r = next((r for r in m["hemishadow"] if r["method"] == v), None)
            if r is None:
                cells.append("–")
                continue
            te, he = interp_time(r["error"]["median"], [(e["error"]["median"], e["ms"]) for e in m["embree"]])
            tc, hc = interp_time(r["ao_first_frame"], [(c["ao_mean_abs"], c["ms"]) for c in m["cycles"]])
            mark = lambda how: "≤ " if how == "at most" else ("~" if how == "extrapolated" else "")  # noqa: E731
            ratio = lambda t, how: f"{mark(how)}{t / r['ms']:.1f}x" if np.isfinite(t) else "not reached"  # noqa: E731
            cells.append(f"{fmt_ms(r['ms'])} ms, {pct(r['error']['median'])}: Embree {ratio(te, he)}, "
                         f"Cycles AO {ratio(tc, hc)}")
        w(f"| {n} | " + " | ".join(cells) + " |")
    w("")
    verdicts = target_verdicts(results, comps, fits)
    for v in verdicts:
        w(f"- {v}")
    w("")
    w("## Observations\n")
    for line in observations(results):
        w(f"- {line}")
    w("")
    w("## Error against time\n")
    w("Median per-vertex relative L2 error against ms per frame (log-log; the dashed line is the 4 % target):\n")
    w(f"![median error against time](images/{images['median'].name})\n")
    w("Mean error over receivers with AO >= 0.1 (this is where the hierarchy's bias shows):\n")
    w(f"![mean error against time](images/{images['mean'].name})\n")
    w("Ambient occlusion, mean absolute error against time, with Cycles' bake:\n")
    w(f"![AO error against time](images/{images['ao'].name})\n")
    w("## Cost is linear in vertices x blockers\n")
    w(f"![time against vertices x blockers](images/{images['linear'].name})\n")
    rows = []
    for n in ("suzanne_2k", "suzanne_8k", "suzanne_32k"):
        m = results["meshes"].get(n)
        if not m:
            continue
        for r in m["hemishadow"]:
            rows.append(f"| {n} | {r['method']} | {m['vertices']} | {r['blockers_per_vertex']:.0f} "
                        f"| {m['vertices'] * r['blockers_per_vertex'] / 1e6:.2f} M | {fmt_ms(r['ms'])} | {r['ns_per_triangle']:.0f} |")
    w("| mesh | variant | vertices | blockers / vertex | V x blockers | ms / frame | ns / triangle (2 cores) |")
    w("|---|---|---|---|---|---|---|")
    out.extend(rows)
    w("")
    w("## Per mesh\n")
    for n, m in results["meshes"].items():
        w(f"### {TITLES.get(n, n)}: {m['vertices']} vertices, {m['triangles']} triangles\n")
        w(f"Errors on {m['receivers']} receivers x frames {m['eval_frames']}; Cycles on frame {m['eval_frames'][0]}.\n")
        w(mesh_table(n, m))
        w("")
    return "\n".join(out) + "\n"


def observations(results):
    out = []
    rows = []
    for n, m in results["meshes"].items():
        d = next((r for r in m["hemishadow"] if r["method"] == DEFAULT), None)
        x = next((r for r in m["hemishadow"] if r["method"].startswith("exact")), None)
        if d and x:
            rows.append(f"{n} {pct(x['error']['mean'])} -> {pct(d['error']['mean'])} (AO bias "
                        f"{x['error']['ao_bias']:+.3f} -> {d['error']['ao_bias']:+.3f})")
    out.append("**The hierarchy costs accuracy where it matters.** The median error moves little from the exact path "
               "to the default, but the mean over receivers with AO >= 0.1 and the AO error grow several-fold on the larger meshes, and "
               "the AO bias (hemishadow - reference, mean over receivers) grows: negative (the coarse mesh "
               "over-occludes) on Suzanne and cesium_man, positive on the cloth, whose coarse mesh is simplified "
               "from the flat rest sheet and misses the folds. Mean error and AO bias, exact -> default: " + "; ".join(rows) + ". Ring 1 is worse "
               "than ring 2, and a 4x finer coarse mesh recovers part of it at about twice the time: the overlap of "
               "the coarse surface with the receiver's neighbourhood is not handled well enough yet.")
    out.append("**Culling** changes neither the error nor the blocker count (the stat counts triangles above the "
               "horizon, which the per-triangle horizon test rejects anyway); it saves time on the exact path only.")
    out.append("**Embree runs on one core** (embreex holds the GIL); the 2-core comparisons halve its time, "
               "which flatters Embree slightly (perfect scaling, BVH build included).")
    floors = []
    for n, m in results["meshes"].items():
        if m["cycles"]:
            c = max(m["cycles"], key=lambda c: c["samples"])
            floors.append(f"{n} {c['ao_mean_abs']:.4f} at {c['samples']} samples")
    out.append("**Cycles' AO does not converge to the reference on every mesh**: " + ", ".join(floors) + ". On the "
               "cloth a few vertices at sharp folds bake nearly black (AO ~0.05 where the reference, Embree and "
               "hemishadow's exact path say ~0.9), whatever the sample count. Cycles evaluates AO per face corner; "
               "probably a corner whose face turns away from the vertex normal sees the sheet itself (not "
               "investigated further). So the cloth's "
               "Cycles curve flattens at that floor; elsewhere it follows 1/sqrt(samples).")
    return out


def target_verdicts(results, comps, fits):
    out = []
    ok = []
    for n, c in comps.items():
        if c is None:
            continue
        d = c["default"]
        med_ok = d["error"]["median"] <= TARGET_MEDIAN
        ok.append((n, med_ok, c["speedup_embree"] / 2))
    met = [n for n, m, s in ok if m and s >= 10]
    notmet = [f"{n} ({'median ' + pct(next(c for k, c in comps.items() if k == n)['default']['error']['median']) if not m else f'{s:.1f}x'})"
              for n, m, s in ok if not (m and s >= 10)]
    out.append("**>= 10x faster than Embree at the same error, median <= 4 %** (against Embree's time halved, i.e. "
               f"as if it used both cores): met on {', '.join(met) or 'no mesh'}; not met on "
               f"{', '.join(notmet) or 'no mesh'}.")
    s8 = comps.get("suzanne_8k")
    if s8:
        out.append(f"On the 8000-vertex Suzanne the default takes {fmt_ms(s8['default']['ms'])} ms per frame "
                   f"(the issue's goal: about 20 ms, 50 FPS); Embree needs {fmt_ms(s8['embree_ms'])} ms on one core "
                   f"for the same median error.")
    cl = comps.get("cloth")
    if cl:
        fps = cl["default"]["fps"]
        out.append(f"**Cloth >= 300 FPS**: {'met' if fps >= 300 else 'not met'}, {fps:.0f} FPS "
                   f"({fmt_ms(cl['default']['ms'])} ms per frame) with the default.")
    sc = [(n, c["speedup_cycles"]) for n, c in comps.items() if c]
    out.append("**AO >= 50x faster than Cycles at the same AO error**: "
               + ", ".join(f"{n} {s:.0f}x {'(met)' if s >= 50 else '(not met)'}" if np.isfinite(s) else
                           f"{n}: Cycles never reaches hemishadow's AO error (its curve flattens, see Observations)"
                           for n, s in sc) + ".")
    if DEFAULT in fits:
        ns = []
        for n in ("suzanne_2k", "suzanne_8k", "suzanne_32k"):
            r = next((r for r in results["meshes"].get(n, {}).get("hemishadow", []) if r["method"] == DEFAULT), None)
            if r:
                ns.append(f"{r['ns_per_triangle']:.0f}")
        out.append(f"**Linear cost**: the default costs {' / '.join(ns)} ns per rasterized triangle (x 2 cores) on the "
                   "three Suzanne sizes; see the figure.")
    mem = [r["bytes_per_vertex"] for m in results["meshes"].values() for r in m["hemishadow"]]
    if mem:
        out.append(f"**Per-vertex solver state <= 1 KB**: {'met' if max(mem) <= 1024 else 'not met'}, at most "
                   f"{max(mem):.0f} bytes per vertex (`memory_bytes`, the shared plane table excepted).")
    return out


def main(path=None, write_docs=None):
    path = pathlib.Path(path or HERE / "results.json")
    results = json.loads(path.read_text())
    if write_docs is None:
        write_docs = not results.get("quick")
    if write_docs:
        img_dir, md_path = ROOT / "docs" / "images", ROOT / "docs" / "benchmarks.md"
    else:
        img_dir = md_path = HERE / "quick"
        img_dir.mkdir(exist_ok=True)
        md_path = img_dir / "benchmarks.md"
    images = {k: img_dir / f"bench_{k}.png" for k in ("median", "mean", "ao", "linear")}
    images = {"median": img_dir / "bench_error_vs_time.png", "mean": img_dir / "bench_mean_error_vs_time.png",
              "ao": img_dir / "bench_ao_vs_time.png", "linear": img_dir / "bench_linear.png"}
    plot_error(results, lambda r: r["error"]["median"], "median relative L2 error", images["median"], TARGET_MEDIAN)
    plot_error(results, lambda r: r["error"]["mean"], "mean rel. L2 error (AO >= 0.1)", images["mean"])
    plot_error(results, lambda r: r["ao_first_frame"], "AO mean abs. error (Cycles: AO bake)", images["ao"])
    fits = plot_linear(results, images["linear"])
    text = build_markdown(results, images, fits)
    if not write_docs:
        text = text.replace("](images/", "](")
    md_path.write_text(text)
    print(f"wrote {md_path.relative_to(ROOT)} and {len(images)} figures")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
