"""Every test of `make test`, group by group, with the time each group took.

    .venv/bin/python scripts/run_tests.py            # all groups
    .venv/bin/python scripts/run_tests.py --only 4.2 # the groups whose name contains "4.2"

Groups, in order:
  rust            cargo test --release of the engine, and its profiling example built with
                  the census feature;
  5.3 engine      pytest tests/*.py in .venv (the primary version: bpy 5.3 on Python 3.13);
  5.3 add-on      pytest tests/addon in .venv (the add-on from source, the zip's install tests);
  X.Y zip         for each requirements-X.Y.txt (the second tier, .venv-X.Y from
                  `scripts/setup.sh --all`): the linux-x64 extension zip installed into that
                  Blender, then its install, live compute, World, bake and CLI tests
                  (tests/tier2/installed_extension.py);
  platforms       the cross toolchains (scripts/setup_platforms.sh), the Windows and macOS zips
                  built and validated (build_extension.py --platforms all), and their tests
                  (tests/platforms: the Windows engine under Wine, the macOS binaries statically).

Every group runs even when an earlier one fails. The times go to out/test-times.txt and are
printed as a table; the last line sums the counts ("tests: N passed, N failed, N skipped"),
and the exit code is 1 if any group failed.
"""

from __future__ import annotations

import argparse
import pathlib
import re
import subprocess
import sys
import time
import xml.etree.ElementTree as ET

ROOT = pathlib.Path(__file__).resolve().parent.parent
OUT = ROOT / "out"
PRIMARY = "5.3"
# The second tier: the tests that go through the installed zip.
TIER2_TESTS = ["tests/addon/test_package.py", "tests/addon/test_live.py", "tests/addon/test_world.py",
               "tests/addon/test_bake.py", "tests/addon/test_cli.py", "tests/addon/test_casters.py",
               "tests/addon/test_steady.py",
               "tests/addon/test_lightmaps.py", "tests/addon/test_lightmap_ui.py",
               "tests/addon/test_lightmaps_atlas.py", "tests/addon/test_lightmap_cancel.py",
               "tests/addon/test_bake_probes.py", "tests/addon/test_probe_lighting.py", "tests/addon/test_probe_sources.py",
               "tests/addon/test_probe_playback.py", "tests/addon/test_panorama_hits.py", "tests/addon/test_panorama_bake.py",
               "tests/addon/test_panorama_cycles.py"]


def tier2_versions() -> list[str]:
    return sorted((p.stem.removeprefix("requirements-") for p in ROOT.glob("requirements-[0-9]*.txt")),
                  key=lambda v: tuple(int(x) for x in v.split(".")))


def pytest_counts(xml: pathlib.Path) -> dict:
    counts = {"passed": 0, "failed": 0, "skipped": 0}
    if not xml.is_file():
        return counts
    root = ET.parse(xml).getroot()
    for suite in root.iter("testsuite"):
        tests, failures, errors, skipped = (int(suite.get(k, 0)) for k in ("tests", "failures", "errors", "skipped"))
        counts["failed"] += failures + errors
        counts["skipped"] += skipped
        counts["passed"] += tests - failures - errors - skipped
    return counts


def cargo_counts(output: str) -> dict:
    counts = {"passed": 0, "failed": 0, "skipped": 0}
    for passed, failed, ignored in re.findall(r"test result: \w+\. (\d+) passed; (\d+) failed; (\d+) ignored", output):
        counts["passed"] += int(passed)
        counts["failed"] += int(failed)
        counts["skipped"] += int(ignored)
    return counts


def run_group(name: str, command: list, env=None, xml: pathlib.Path | None = None) -> dict:
    print(f"\n==== {name}: {' '.join(map(str, command))}", flush=True)
    start = time.perf_counter()
    if xml is None:  # cargo: its output is parsed (and shown as it comes)
        process = subprocess.Popen([str(c) for c in command], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                                   stderr=subprocess.STDOUT, text=True)
        lines = []
        for line in process.stdout:
            print(line, end="", flush=True)
            lines.append(line)
        code = process.wait()
        counts = cargo_counts("".join(lines))
    else:
        xml.unlink(missing_ok=True)
        code = subprocess.run([str(c) for c in command], cwd=ROOT, env=env).returncode
        counts = pytest_counts(xml)
        if code == 5:  # pytest collected no test
            code = 0
    seconds = time.perf_counter() - start
    ok = code == 0 and counts["failed"] == 0
    return {"name": name, "seconds": seconds, "ok": ok, "code": code, **counts}


def groups() -> list[tuple[str, list, dict | None, pathlib.Path | None]]:
    import os

    results = OUT / "test-results"
    primary = ROOT / ".venv" / "bin" / "python"
    # The census build keeps the profiling feature compiling (docs/solver_speed.md).
    rust = ("cargo test --release --manifest-path native/Cargo.toml && cargo build --release --manifest-path "
            "native/Cargo.toml --example profile_solver --features hemishadow-engine/census")
    out = [("rust", ["bash", "-c", rust], None, None)]
    engine_tests = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "tests").glob("test_*.py"))
    xml = results / "engine.xml"
    out.append((f"{PRIMARY} engine", [primary, "-m", "pytest", "-q", f"--junitxml={xml}", *engine_tests], None, xml))
    xml = results / "addon.xml"
    out.append((f"{PRIMARY} add-on", [primary, "-m", "pytest", "-q", f"--junitxml={xml}", "tests/addon"], None, xml))
    zip_path = ROOT / "dist" / "hemishadow-0.1.0-linux_x64.zip"
    for version in tier2_versions():
        python = ROOT / f".venv-{version}" / "bin" / "python"
        xml = results / f"tier2-{version}.xml"
        env = dict(os.environ, PYTHONPATH=str(ROOT / "tests" / "tier2"))
        out.append((f"{version} zip", [python, "-m", "pytest", "-q", "-p", "installed_extension",
                                       f"--extension-zip={zip_path}", f"--junitxml={xml}", *TIER2_TESTS], env, xml))
    xml = results / "platforms.xml"
    platforms = (f"bash scripts/setup_platforms.sh && {primary} scripts/build_extension.py --platforms all --if-stale"
                 f" && {primary} -m pytest -q --junitxml={xml} tests/platforms")
    out.append(("platforms", ["bash", "-c", platforms], None, xml))
    return out


def build_zip() -> dict:
    start = time.perf_counter()
    print("\n==== extension zip (linux-x64)", flush=True)
    code = subprocess.run([ROOT / ".venv" / "bin" / "python", ROOT / "scripts" / "build_extension.py", "--if-stale"],
                          cwd=ROOT).returncode
    return {"name": "build zip", "seconds": time.perf_counter() - start, "ok": code == 0, "code": code,
            "passed": 0, "failed": 0 if code == 0 else 1, "skipped": 0}


def table(rows: list[dict]) -> str:
    lines = [f"{'group':<16} {'time':>9} {'passed':>7} {'failed':>7} {'skipped':>8}  result"]
    for r in rows:
        result = "ok" if r["ok"] else f"FAILED (exit {r['code']})"
        lines.append(f"{r['name']:<16} {r['seconds'] / 60:>6.1f} min {r['passed']:>7} {r['failed']:>7} "
                     f"{r['skipped']:>8}  {result}")
    total = sum(r["seconds"] for r in rows)
    lines.append(f"{'total':<16} {total / 60:>6.1f} min")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--only", help="run only the groups whose name contains this")
    args = parser.parse_args(argv)
    (OUT / "test-results").mkdir(parents=True, exist_ok=True)
    selected = [g for g in groups() if not args.only or args.only in g[0]]
    rows = []
    if any(g[0].endswith(" zip") for g in selected):
        rows.append(build_zip())
    for name, command, env, xml in selected:
        rows.append(run_group(name, command, env, xml))
    report = table(rows)
    stamp = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    (OUT / "test-times.txt").write_text(f"scripts/run_tests.py, {stamp}\n{report}\n")
    print(f"\n{report}\n(also in out/test-times.txt)")
    passed, failed, skipped = (sum(r[k] for r in rows) for k in ("passed", "failed", "skipped"))
    failed_groups = [r["name"] for r in rows if not r["ok"]]
    if failed_groups and failed == 0:
        failed = len(failed_groups)  # a group that failed without a test failing (a crash, a build)
    print(f"tests: {passed} passed, {failed} failed, {skipped} skipped", flush=True)
    return 1 if failed_groups else 0


if __name__ == "__main__":
    sys.exit(main())
