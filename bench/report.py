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
sys.path.insert(0, str(HERE))
import curves  # noqa: E402

FITTED_SIDES = (8, 16, 32, 64, 128)  # Embree's curve is drawn to 128^2 = 16384 rays, fitted beyond what ran
TARGET_ERROR = 0.02
TITLES = {
    "cloth": "cloth (Blender cloth sim over a sphere)",
    "suzanne_2k": "Suzanne, subdivision 1",
    "suzanne_8k": "Suzanne, subdivision 2",
    "suzanne_32k": "Suzanne, subdivision 3",
    "cesium_man": "cesium_man.glb (walk)",
    "fox": "fox.glb (Survey)",
    "rigged_figure": "rigged_figure.glb",
}
MARKERS = {"default": "o", "downsample 1": "<", "downsample 2": "^", "downsample 4": ">", "table 64": "s",
           "table 96": "D", "table 128": "p", "ring 1": "v", "ring 2": "h", "two levels (far_lod 0)": "d", "far_lod 0.7": "P", "PVS": "*", "PVS, half the poses": "X"}
# issue 9's targets: (mesh, speed-up at equal error, frames per second)
TARGETS = {"suzanne_8k": (10.0, 40.0), "cloth": (20.0, 300.0)}
TARGET_RATIO = 4.5
CONFIG = {}  # the run's configuration, set by main


def measured(m):
    return [r for r in m["hemishadow"] if not r.get("same_as_default") and not r.get("failed")]


def embree_error(r, cfg):
    """Embree's median error with the reference's share of the noise taken off."""
    return r["error"]["median"] * curves.reference_noise_factor(r["rays"], cfg["reference_side"] ** 2)


def embree_fit(m):
    """(curve, exponent of its law): measured points and the fitted ones beyond."""
    pts = [(r["rays"], r["ms"], embree_error(r, CONFIG)) for r in m["embree"]]
    if len(pts) < 2:
        return [(r, t, e, "measured") for r, t, e in pts], curves.SHALLOWEST
    return curves.extend(pts, [s * s for s in FITTED_SIDES])


def embree_curve(m):
    return embree_fit(m)[0]


def speedups(m):
    """Per measured hemishadow row: (Embree ms at its median error, how, speed-up)."""
    curve, exponent = embree_fit(m)
    out = {}
    for r in measured(m):
        if len(curve) < 2:
            out[r["method"]] = (float("nan"), "no curve", float("nan"))
            continue
        ms, how = curves.time_at_error(r["error"]["median"], curve, exponent)
        out[r["method"]] = (ms, how, ms / r["ms"])
    return out


def pct(x):
    return "–" if x is None or not np.isfinite(x) else f"{100 * x:.2f} %"


def fmt_ms(x):
    return "–" if x is None or not np.isfinite(x) else (f"{x:.1f}" if x >= 10 else f"{x:.2f}")


def met(ok):
    return "**met**" if ok else "**not met**"


def plot_curves(results, path):
    names = list(results["meshes"])
    cols = min(4, len(names))
    rows = math.ceil((len(names) + 1) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.3 * cols, 3.7 * rows), squeeze=False)
    for ax, name in zip(axes.ravel(), names):
        m = results["meshes"][name]
        curve = embree_curve(m)
        meas = [p for p in curve if p[3] == "measured"]
        fit = [p for p in curve if p[3] == "fitted"]
        ax.plot([p[1] for p in meas], [p[2] for p in meas], "-", color="0.35", marker="o", mfc="0.35",
                label=f"Embree, N rays, {results['embree_workers']} processes (measured)")
        if fit:
            tail = meas[-1:] + fit
            ax.plot([p[1] for p in tail], [p[2] for p in tail], "--", color="0.35")
            ax.plot([p[1] for p in fit], [p[2] for p in fit], "--", color="0.35", marker="o", mfc="white",
                    label="Embree, fitted: a N^b, time linear in N")
        for p in curve:
            ax.annotate(str(p[0]), (p[1], p[2]), textcoords="offset points", xytext=(4, 2), fontsize=7, color="0.35")
        for r in measured(m):
            big = r["method"] == "default" or r["method"].startswith("PVS")
            ax.plot([r["ms"]], [r["error"]["median"]], linestyle="none", marker=MARKERS.get(r["method"], "o"),
                    markersize=9 if big else 6, label="hemishadow " + r["method"],
                    color="k" if r["method"] == "default" else None)
        ax.axhline(TARGET_ERROR, color="tab:red", lw=0.6, ls=":")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(f"{name}: {m['vertices']} vertices", fontsize=9)
        ax.set_xlabel("ms per frame (solve, all cores)", fontsize=8)
        ax.set_ylabel("median relative L2 error", fontsize=8)
        ax.grid(True, which="both", lw=0.3)
    handles, labels = [], []
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    fig.tight_layout()
    axes.ravel()[len(names)].legend(handles, labels, loc="center", fontsize=7.5, frameon=False)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_vertex_curve(rows, path):
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    tri = [r["triangles"] for r in rows]
    ax.plot(tri, [1e3 * r["ms"] / r["vertices"] for r in rows], "-o", color="k", label="hemishadow default")
    emb = [r for r in rows if r.get("embree_ms")]
    if emb:
        ax.plot([r["triangles"] for r in emb], [1e3 * r["embree_ms"] / r["vertices"] for r in emb], "-s",
                color="0.5", label=f"Embree {emb[0]['embree_rays']} rays, all cores")
    for r in rows:
        ax.annotate(f"{r['vertices'] / 1e3:.0f}k" if r["vertices"] >= 1e3 else str(r["vertices"]),
                    (r["triangles"], 1e3 * r["ms"] / r["vertices"]), textcoords="offset points", xytext=(4, -10),
                    fontsize=7)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("triangles (Suzanne, subdivision levels)")
    ax.set_ylabel("µs per vertex per frame (2 cores)")
    ax.grid(True, which="both", lw=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def slope_note(results):
    """The exponents the fitted points use, per mesh."""
    fits = {n: curves.fit_law([r["rays"] for r in m["embree"]], [embree_error(r, CONFIG) for r in m["embree"]])
            for n, m in results["meshes"].items() if len(m["embree"]) >= 2}
    return (" Exponents b used (measured slope in brackets): "
            + ", ".join(f"{n} {b:.2f} ({slope:.2f})" for n, (_, b, slope) in fits.items()) + ".")


def header(results):
    mach, cfg = results["machine"], results["config"]
    out = ["# Benchmarks\n"]
    out.append(
        f"Measured by `{results['command']}` on **{mach['cpu']}**, {mach['cores']} cores "
        f"(AVX2 {'yes' if mach['avx2'] else 'no'}, AVX-512F {'yes' if mach['avx512f'] else 'no'}), "
        f"{mach['date'].replace('T', ' ')}, load average {mach['load_before'][0]:.2f} before the run "
        f"({mach['load_after'][0]:.2f} after; the run itself loads both cores), Blender {mach['blender']} (`bpy` "
        f"module), bench commit {mach['commit']}, engine {mach['engine']}. The whole run took "
        f"{results['seconds'] / 60:.1f} minutes. Load average (1 min) at the start of each mesh: "
        + ", ".join(f"{n} {m['load_start']:.2f}" for n, m in results["meshes"].items())
        + ". Everything below is generated from that run's `bench/results.json` (`bench/report.py` redraws the "
        "page from it).\n")
    out.append("`TransferSolver` defaults of the engine measured: "
               + ", ".join(f"`{k}={v}`" for k, v in results["solver_defaults"].items()) + ". "
               + identical_note(results))
    out.append("## What is measured\n")
    eval_frames = ", ".join(str(f) for f in cfg["eval_frames"])
    out += [
        "- **Meshes**, each welded by position once; every method sees the same welded mesh, the same area-weighted "
        "vertex normals and the same receiver offset (1e-3 x mean edge length of the rest pose): a 37 x 37 cloth "
        "dropped by Blender's cloth solver over a sphere (frames 24-48, every 4th; the sphere is not part of the mesh), "
        "Suzanne with Subdivision Surface 1, 2, 3 applied, bent and twisted in numpy per frame, and the skinned glTF "
        f"characters of `../shared/data`, {cfg['frames']} frames over their first action. Frame 0 is the rest pose "
        "(flat cloth, undeformed Suzanne, bind pose): solvers are built from it; it is never timed nor evaluated.",
        f"- **Reference**: `tests/reference.py` `transfer_reference`, {cfg['reference_side']}² = "
        f"{cfg['reference_side'] ** 2} stratified cosine rays per receiver with the control variate, on "
        f"{cfg['receivers']} random receivers (all vertices when fewer), on frames {eval_frames}; computed in the "
        "Embree worker processes, outside every timing. It has at least 4x the rays of the densest Embree point "
        "it judges (Embree is run to at most a quarter of its rays). Being the same unbiased estimator with R "
        "rays, its noise adds N / R to the expected squared error of Embree's N-ray point: Embree's median "
        "errors are divided by sqrt(1 + N / R) (at most 11 %; both numbers are in the per-mesh tables), so "
        "Embree is not charged for the reference's noise. **Errors** are `error_summary` on those receivers, averaged over "
        "the evaluated frames: the median over receivers of the per-vertex relative L2 error (the curves), and "
        "the mean over receivers with AO >= 0.1 (tables).",
        "- **hemishadow**: `TransferSolver(rest pose, tris, offset=..., reuse=False, **variant)`, built once, one "
        "warm-up `solve`, then `solve(vertices, normals)` timed per moving frame, in passes over the frames "
        f"while the budget lasts ({cfg['hemishadow_budget']:g} s of solves per variant, at most "
        f"{cfg.get('max_passes', 1)} passes: one pass on the slow meshes, many on the fast ones, whose median of "
        "seven solves caught the host's busy spells); the median over the solves timed (column 'solves timed'). "
        "No Blender I/O. Variants: the default (no keywords), `downsample` 1 / 2 / 4, "
        "`table_resolution` 64 / 96 / 128, `ring` 1 / 2 (a variant whose keywords equal the declared defaults is "
        "the default and is not run twice; 'output = default' marks a variant whose transfer was bit-identical "
        "to the default's), and **PVS**: the default after `solver.build_pvs(all frames of the mesh)` (the timed "
        "frames are among the sampled poses: PVS's best case), and 'PVS, half the poses' after "
        "`build_pvs(frames 0, 2, 4, ...)` (every other timed frame unseen)."
        + ("" if results["pvs_available"] else " **The engine measured has no `build_pvs` yet: no PVS points.**"),
        f"- **Embree** (`embreex`, Embree 2): **on all cores**: embreex holds the GIL, so a pool of "
        f"{results['embree_workers']} processes (started once, before any timing) each builds its own BVH of "
        "the frame and traces a share of the receivers; a frame is timed wall-clock from dispatch to the "
        "concatenated result (BVH builds, ray generation, queries, SH projection, pickling). N = n² stratified "
        "cosine rays per receiver (a jittered n x n grid, concentric map, lifted), from p + offset n; rays that "
        "hit a triangle incident to the receiver are re-cast past it (the engine's and the reference's rule); "
        "the control-variate projection T = T_open(n) - π/N Σ_blocked Y(d) as in the reference. N = "
        + ", ".join(str(s * s) for s in cfg["embree_sides"] if 2 * s <= cfg["reference_side"])
        + f" in turn, the next one run while predicted (4x the last time) to take at most {cfg['embree_cap']:g} s "
        "per frame, and at least two; **beyond what was run, the points are fitted** (hollow markers, dashed): "
        "error = a N^b, time linear in N through the two densest measured points. Plain Monte Carlo has "
        "b = -1/2 (the 'four times the rays for half the error' of the issue); stratified rays converge faster "
        "on visibility edges, up to b = -3/4, and the measured curves do, so b is the measured log-log slope "
        "held within [-3/4, -1/2] and a is fitted to the two densest measured points (with b = -1/2 forced, "
        "Embree's fitted errors would be too high and the speed-ups read off them too flattering). The per-mesh tables say which points are measured and which fitted."
        + slope_note(results),
        "- **Speed-up at equal error**: for a hemishadow point of median error e, Embree's time at e is read off "
        "Embree's curve (measured and fitted points) by log-log interpolation between the neighbouring ray "
        "counts; outside the curve, by the same law (time ∝ N ∝ error^(1/b)) from its nearest end (said in the "
        "tables). Speed-up = Embree's time at e / hemishadow's time.",
        "- **Cycles** (issue 4's AO-bake peer) is no longer run: it only measured AO, and Embree is the faster and "
        "fairer peer; issue 4's numbers are in this page's git history.\n",
    ]
    return out


def targets(results):
    out = ["## Targets (issue 9)\n",
           "Default settings, PVS off, reuse off, `solve()` time, Embree on all cores, from this run:\n",
           "| target | mesh | measured | status |", "|---|---|---|---|"]
    for name, (speed, fps) in TARGETS.items():
        m = results["meshes"].get(name)
        if m is None:
            out.append(f"| speed-up >= {speed:.0f}x, >= {fps:.0f} FPS | {name} | not in this run | – |")
            continue
        d = next(r for r in m["hemishadow"] if r["method"] == "default")
        ms, how, ratio = speedups(m)["default"]
        out.append(f"| speed-up vs Embree at equal error >= {speed:.0f}x | {name} | {ratio:.1f}x ({fmt_ms(d['ms'])} ms "
                   f"against Embree's {fmt_ms(ms)} ms at {pct(d['error']['median'])}, {how}) | {met(ratio >= speed)} |")
        out.append(f"| >= {fps:.0f} frames per second | {name} | {d['fps']:.0f} FPS ({fmt_ms(d['ms'])} ms) "
                   f"| {met(d['fps'] >= fps)} |")
        out.append(f"| median error <= 2 % | {name} | {pct(d['error']['median'])} (mean over AO >= 0.1: "
                   f"{pct(d['error']['mean'])}) | {met(d['error']['median'] <= TARGET_ERROR)} |")
    out.append(scale_target(results))
    out.append("\nWhere the 8k Suzanne's frame goes, and what was tried for 40 frames per second: "
               "[solver_speed.md](solver_speed.md).")
    others = [(n, next(r for r in m["hemishadow"] if r["method"] == "default")) for n, m in results["meshes"].items()]
    out.append("\nDefault median error on every mesh: " + ", ".join(f"{n} {pct(d['error']['median'])}" for n, d in others)
               + f" ({'all' if all(d['error']['median'] <= TARGET_ERROR for _, d in others) else 'not all'} at or below 2 %).\n")
    return out


def scale_target(results):
    """The target row for the 126k / 32k ratio: from the levels timed in alternation
    (`scale_pair`) when the run has them, else from the curve's levels 4 and 3."""
    pair = results.get("scale_pair")
    if pair:
        (a, b), (ms_a, ms_b) = pair["vertices"], pair["ms"]
        quartiles = " / ".join(f"{q:.2f}" for q in pair["round_ratio_quartiles"])
        what = "126k / 32k" if pair["levels"] == [3, 4] else f"level {pair['levels'][1]} / level {pair['levels'][0]}"
        return (f"| {what} solve time <= {TARGET_RATIO}x | Suzanne levels {pair['levels'][1]} / {pair['levels'][0]}, "
                f"timed in alternation | {pair['ratio']:.2f}x ({ms_b / 1e3:.2f} s / {ms_a / 1e3:.2f} s for {b / a:.1f}x the "
                f"vertices; per round, quartiles {quartiles}, {pair['rounds']} rounds) | {met(pair['ratio'] <= TARGET_RATIO)} |")
    by_level = {r["level"]: r for r in results.get("vertex_curve", []) if "ms" in r}
    if 3 not in by_level or 4 not in by_level:
        return "| 126k / 32k solve time | – | levels 3 and 4 not in this run | – |"
    a, b = by_level[3], by_level[4]
    ratio = b["ms"] / a["ms"]
    return (f"| 126k / 32k solve time <= {TARGET_RATIO}x | Suzanne levels 4 / 3 | {ratio:.2f}x ({b['ms'] / 1e3:.2f} s / "
            f"{a['ms'] / 1e3:.2f} s for {b['vertices'] / a['vertices']:.1f}x the vertices) | {met(ratio <= TARGET_RATIO)} |")


def speedup_table(results):
    labels = [lab for lab in MARKERS if any(r["method"] == lab for m in results["meshes"].values() for r in measured(m))]
    out = ["## Speed-up at equal error\n",
           "Each measured hemishadow setting: ms per frame, median error, and Embree's time at that error / "
           "hemishadow's time (✱: Embree's time read off a fitted part of its curve or extended by the law).\n",
           "| mesh | " + " | ".join(labels) + " |", "|---|" + "---|" * len(labels)]
    for name, m in results["meshes"].items():
        rows = {r["method"]: r for r in measured(m)}
        sp = speedups(m)
        measured_to = max((p[1] for p in embree_curve(m) if p[3] == "measured"), default=0.0)
        cells = []
        for lab in labels:
            r = rows.get(lab)
            if r is None:
                cells.append("= default" if any(x["method"] == lab and x.get("same_as_default")
                                                for x in m["hemishadow"]) else "–")
                continue
            ms, how, ratio = sp[lab]
            star = "✱" if how != "interpolated" or ms > measured_to else ""
            cells.append(f"{fmt_ms(r['ms'])} ms, {pct(r['error']['median'])}: **{ratio:.1f}x**{star}")
        out.append(f"| {name} | " + " | ".join(cells) + " |")
    return out + [""]


def pvs_section(results):
    out = ["## PVS\n"]
    if not results["pvs_available"]:
        return out + ["Not measured: the engine of this run has no `TransferSolver.build_pvs`.\n"]
    out += ["The default with `build_pvs(poses)`: 'PVS' samples all frames of the mesh (the timed frames are "
            "among them: its best case); 'half the poses' samples frames 0, 2, 4, ... only, so every other timed "
            "frame (and evaluated frame 5) is a pose the PVS has not seen. Speed-up = default ms / PVS ms; "
            "'transfer' says whether the PVS's output was bit-identical to the default's on the evaluated "
            "frames.\n",
            "| mesh | variant | default ms | PVS ms | speed-up | blockers / vertex | median: default → PVS "
            "| mean (AO ≥ 0.1): default → PVS | transfer | build_pvs ms |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name, m in results["meshes"].items():
        rows = {r["method"]: r for r in m["hemishadow"]}
        d = rows["default"]
        for label in ("PVS", "PVS, half the poses"):
            p = rows.get(label)
            if p is None or p.get("failed"):
                out.append(f"| {name} | {label} | {fmt_ms(d['ms'])} | {p['failed'] if p else '–'} | | | | | | |")
                continue
            out.append(f"| {name} | {label} | {fmt_ms(d['ms'])} | {fmt_ms(p['ms'])} | {d['ms'] / p['ms']:.2f}x "
                       f"| {d['blockers_per_vertex']:.0f} → {p['blockers_per_vertex']:.0f} "
                       f"| {pct(d['error']['median'])} → {pct(p['error']['median'])} "
                       f"| {pct(d['error']['mean'])} → {pct(p['error']['mean'])} "
                       f"| {'identical' if p['identical_to_default'] else 'differs'} | {p['pvs_ms']:.0f} |")
    return out + [""]


def identical_note(results):
    """Which variants gave the default's transfer bit for bit on every mesh (how the
    defaults left open by the signature, e.g. downsample=None, resolve)."""
    labels = [lab for lab in MARKERS if lab != "default" and not lab.startswith("PVS")]
    same = [lab for lab in labels if all(any(r["method"] == lab and r.get("identical_to_default") for r in m["hemishadow"])
                                        for m in results["meshes"].values())]
    return (f"On every mesh the default's transfer was bit-identical to that of: {', '.join(same) or 'none'}.\n")


def vertex_section(results):
    rows = [r for r in results.get("vertex_curve", []) if "ms" in r]
    skipped = [r for r in results.get("vertex_curve", []) if "skipped" in r]
    if not rows:
        return []
    out = ["## Cost per vertex against the vertex count\n",
           "Suzanne with Subdivision Surface levels "
           f"{', '.join(str(r['level']) for r in rows)} applied, bent and twisted as above; the default solver "
           "(reuse off), one warm-up solve then the median over the moving frames, except meshes above "
           f"{results['config']['once_above']} vertices or predicted (from the last two levels) to take more than "
           f"{results['config']['warm_up_cap']:g} s: those are timed once without a warm-up (the plane table is "
           "shared and already built). Embree at its 256-ray point on all cores, where run. The 126k / 32k ratio "
           "of the targets is levels 4 and 3 timed again in alternation after the curve (`scale_pair` in "
           "bench/run.py): timed minutes apart, as here, the ratio of the two levels moved between 3.4x and 4.6x "
           "from run to run of the same engine on this shared machine.\n",
           "![cost per vertex against triangles](images/bench_vertex_curve.png)\n",
           "| level | vertices | triangles | hemishadow ms / frame | µs / vertex | blockers / vertex | frames "
           "| Embree ms / frame | Embree µs / vertex | Embree / hemishadow |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        e = r.get("embree_ms")
        embree = f"{fmt_ms(e)} | {1e3 * e / r['vertices']:.2f} | {e / r['ms']:.1f}x" if e else "– | – | –"
        out.append(f"| {r['level']} | {r['vertices']} | {r['triangles']} | {fmt_ms(r['ms'])} | "
                   f"{1e3 * r['ms'] / r['vertices']:.2f} | {r['blockers_per_vertex']:.0f} | {r['frames_timed']}"
                   f"{'' if r['warm_up'] else ' (no warm-up)'} | {embree} |")
    for r in skipped:
        out.append(f"\nLevel {r['level']} was not run: {r['skipped']} (extrapolated from the last two levels; "
                   f"the run's cap is {results['config']['level_cap']:.0f} s).")
    return out + [""]


def mesh_section(name, m):
    out = [f"### {TITLES.get(name, name)}: {m['vertices']} vertices, {m['triangles']} triangles\n",
           f"Errors on {m['receivers']} receivers x frames {m['eval_frames']}.\n",
           "| method | ms / frame | FPS | blockers / vertex | median | mean (AO ≥ 0.1, raw) | AO mean abs. error "
           "| Embree ms at that median | speed-up | solves timed |", "|---|---|---|---|---|---|---|---|---|---|"]
    sp = speedups(m)
    for r in m["hemishadow"]:
        if r.get("same_as_default") or r.get("failed"):
            what = "= default" if r.get("same_as_default") else f"failed: `{r['failed']}`"
            out.append(f"| hemishadow {r['method']} | {what} | | | | | | | | |")
            continue
        e = r["error"]
        ms, how, ratio = sp[r["method"]]
        note = " (output = default)" if r.get("identical_to_default") and r["method"] != "default" else ""
        if r.get("pvs_ms") is not None:
            note += f" (build_pvs {r['pvs_ms']:.0f} ms)"
        out.append(f"| hemishadow {r['method']}{note} | {fmt_ms(r['ms'])} | {r['fps']:.0f} | {r['blockers_per_vertex']:.0f} "
                   f"| {pct(e['median'])} | {pct(e['mean'])} | {e['ao_mean_abs']:.4f} | {fmt_ms(ms)} ({how}) "
                   f"| {ratio:.1f}x | {r['frames_timed']} |")
    byrays = {r["rays"]: r for r in m["embree"]}
    for rays, ms, err, kind in embree_curve(m):
        r = byrays.get(rays) if kind == "measured" else None
        if r:
            e = r["error"]
            out.append(f"| Embree {rays} rays, measured | {fmt_ms(ms)} | {r['fps']:.1f} | | {pct(err)} "
                       f"({pct(e['median'])} raw) "
                       f"| {pct(e['mean'])} | {e['ao_mean_abs']:.4f} | | | {r['frames_timed']} |")
        else:
            out.append(f"| Embree {rays} rays, *fitted* | {fmt_ms(ms)} | {1e3 / ms:.1f} | | {pct(err)} | | | | | – |")
    if len(m["embree"]) >= 2:
        rays = [r["rays"] for r in m["embree"]]
        errors = [embree_error(r, CONFIG) for r in m["embree"]]
        a, b, slope = curves.fit_law(rays, errors)
        out.append(f"\nEmbree fit: median error = {a:.3f} N^{b:.2f} (measured log-log slope {slope:.2f}, "
                   f"held within [{curves.STEEPEST}, {curves.SHALLOWEST}]; a through the two densest measured "
                   "points).\n")
    return out + [""]


def build_markdown(results):
    out = header(results) + targets(results)
    out += ["## Time against error\n",
            "Median relative L2 error against ms per frame, log-log, per mesh: Embree's curve (filled: measured, "
            "hollow and dashed: fitted) and every hemishadow setting; the dotted red line is 2 %.\n",
            "![time against median error, per mesh](images/bench_curves.png)\n"]
    out += speedup_table(results) + pvs_section(results) + vertex_section(results) + ["## Per mesh\n"]
    for name, m in results["meshes"].items():
        out += mesh_section(name, m)
    return "\n".join(out + scenes_section())


def scenes_section():
    """The scene benchmark's page (`bench/scene.py`, a run of its own), under a heading here."""
    page = ROOT / "docs" / "benchmarks_scene.md"
    lines = page.read_text().splitlines()[1:] if page.is_file() else []
    return ["## Scenes\n",
            "Many objects and instances seen from arbitrary receivers (`hemishadow.Scene`, issue 10), measured by "
            "`bench/scene.py` in a run of its own (also on [benchmarks_scene.md](benchmarks_scene.md)):\n",
            "\n".join(lines), PANORAMA_LINE]


PANORAMA_LINE = ("\nPanorama relighting (issue 13): relights per second, GB/s, file sizes and 8-bit error on "
                 "[benchmarks_panorama.md](benchmarks_panorama.md), measured by `bench/panorama_relight.py`.")


def main(path=None, write_docs=None):
    path = pathlib.Path(path or HERE / "results.json")
    results = json.loads(path.read_text())
    CONFIG.update(results["config"])
    if write_docs is None:
        write_docs = not results.get("quick")
    img_dir = ROOT / "docs" / "images" if write_docs else HERE / "quick"
    img_dir.mkdir(exist_ok=True)
    md_path = ROOT / "docs" / "benchmarks.md" if write_docs else img_dir / "benchmarks.md"
    plot_curves(results, img_dir / "bench_curves.png")
    if any("ms" in r for r in results.get("vertex_curve", [])):
        plot_vertex_curve([r for r in results["vertex_curve"] if "ms" in r], img_dir / "bench_vertex_curve.png")
    text = build_markdown(results)
    if not write_docs:
        text = text.replace("](images/", "](")
    md_path.write_text(text)
    print(f"wrote {md_path.relative_to(ROOT)} and its figures")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
