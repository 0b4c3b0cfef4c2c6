"""Build the Blender extension zip: dist/<id>-<version>-<platform>.zip.

Run with the project's environment: `.venv/bin/python scripts/build_extension.py`.

Passes:
  1. build the engine wheel (maturin, release, abi3 for CPython 3.11+) into build/wheels/;
  2. download the OpenEXR wheel pinned in requirements.txt for cp311 manylinux x86_64
     (kept in build/downloads/, so later builds work offline);
  3. stage build/extension/: blender_manifest.toml (its `wheels` list rewritten from the actual
     file names), the contents of addon/, and wheels/;
  4. build the zip with Blender's own extension tool (bpy's bl_pkg/cli/blender_ext.py, the
     code behind `blender --command extension build`), with Blender's list of valid tags;
  5. validate the zip with the same tool, then move it into dist/.

Every output is written beside its destination and renamed into place, so an interrupted or
failed build leaves the previous result intact. Running it again rebuilds (cargo and the
download cache make that quick); `--if-stale` skips the build when the zip is newer than every
input.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
import zipfile

ROOT = pathlib.Path(__file__).resolve().parent.parent
MANIFEST = ROOT / "blender_manifest.toml"
ADDON = ROOT / "addon"
NATIVE = ROOT / "native"
REQUIREMENTS = ROOT / "requirements.txt"
BUILD = ROOT / "build"
DIST = ROOT / "dist"

# The Python and platform the bundled wheels are for: what the bpy module here runs
# (CPython 3.11 on linux x86_64). The OpenEXR 3.4.4 wheel is tagged
# cp311-cp311-manylinux2014_x86_64.manylinux_2_17_x86_64.
PYTHON_VERSION = "3.11"
PIP_PLATFORM = "manylinux2014_x86_64"

# Files of addon/ that never go into the extension.
IGNORED = shutil.ignore_patterns("__pycache__", "*.pyc", ".*", "*.blend[1-9]")


def say(message: str) -> None:
    print(f"build_extension: {message}", flush=True)


class BuildError(Exception):
    pass


def run(command: list, cwd=None, env=None) -> str:
    """Run a command; its output is returned, and shown only when it fails."""
    result = subprocess.run([str(c) for c in command], cwd=cwd, env=env, capture_output=True, text=True)
    if result.returncode != 0:
        raise BuildError(
            f"command failed ({result.returncode}): {' '.join(map(str, command))}\n{result.stdout}{result.stderr}")
    return result.stdout + result.stderr


def read_manifest() -> dict:
    with open(MANIFEST, "rb") as fh:
        manifest = tomllib.load(fh)
    for key in ("id", "version", "platforms"):
        if key not in manifest:
            raise BuildError(f"{MANIFEST.name}: no `{key}`")
    return manifest


def blender_ext_paths() -> tuple[pathlib.Path, pathlib.Path]:
    """Blender's extension tool and its list of valid tags, from the installed bpy module."""
    import importlib.util

    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise BuildError("the `bpy` module is not installed: run `make setup` first")
    for root in spec.submodule_search_locations:
        for version_dir in sorted(pathlib.Path(root).glob("[0-9]*.[0-9]*")):
            scripts = version_dir / "scripts"
            tool = scripts / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
            tags = scripts / "modules" / "_bpy_internal" / "extensions" / "tags.py"
            if tool.is_file() and tags.is_file():
                return tool, tags
    raise BuildError("bpy has no bl_pkg/cli/blender_ext.py (Blender's extension tool)")


def pinned_version(package: str) -> str:
    for line in REQUIREMENTS.read_text().splitlines():
        match = re.match(rf"\s*{re.escape(package)}\s*==\s*([^\s#;]+)", line, re.IGNORECASE)
        if match:
            return match.group(1)
    raise BuildError(f"{REQUIREMENTS.name}: no `{package}==VERSION` pin")


def build_engine_wheel() -> pathlib.Path:
    """maturin build --release from native/; abi3 comes from pyo3's abi3-py311 feature."""
    out = BUILD / "wheels"
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=out, prefix=".tmp-") as tmp:
        venv = pathlib.Path(sys.prefix)
        # The same environment as scripts/setup.sh's `maturin develop`, so cargo reuses its
        # artifacts instead of rebuilding pyo3 for another interpreter configuration.
        env = dict(os.environ, VIRTUAL_ENV=str(venv), PATH=f"{venv / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}")
        maturin = shutil.which("maturin", path=env["PATH"]) or "maturin"
        run([maturin, "build", "--release", "--out", tmp], cwd=NATIVE, env=env)
        wheels = sorted(pathlib.Path(tmp).glob("*.whl"))
        if len(wheels) != 1:
            raise BuildError(f"maturin built {len(wheels)} wheels, expected one: {[w.name for w in wheels]}")
        wheel = wheels[0]
        if "-abi3-" not in wheel.name:
            raise BuildError(f"the engine wheel is not abi3: {wheel.name}")
        for stale in out.glob("hemishadow-*.whl"):
            stale.unlink()
        target = out / wheel.name
        os.replace(wheel, target)
    return target


def download_openexr() -> pathlib.Path:
    """The pinned OpenEXR wheel for cp311 manylinux x86_64, downloaded once."""
    version = pinned_version("OpenEXR")
    cache = BUILD / "downloads"
    cache.mkdir(parents=True, exist_ok=True)
    pattern = f"openexr-{version}-cp311-cp311-*x86_64*.whl"
    found = sorted(cache.glob(pattern))
    if found:
        return found[0]
    with tempfile.TemporaryDirectory(dir=cache, prefix=".tmp-") as tmp:
        run([sys.executable, "-m", "pip", "download", "--disable-pip-version-check", "--quiet",
             "--only-binary=:all:", "--no-deps", "--python-version", PYTHON_VERSION,
             "--implementation", "cp", "--abi", "cp311", "--platform", PIP_PLATFORM,
             f"OpenEXR=={version}", "--dest", tmp])
        wheels = sorted(pathlib.Path(tmp).glob(pattern))
        if len(wheels) != 1:
            raise BuildError(f"pip downloaded {[w.name for w in pathlib.Path(tmp).iterdir()]}, expected {pattern}")
        target = cache / wheels[0].name
        os.replace(wheels[0], target)
    return target


def manifest_with_wheels(text: str, wheel_paths: list[str]) -> str:
    """The manifest text with its `wheels = [...]` array replaced (or added) by wheel_paths."""
    array = "wheels = [\n" + "".join(f'  "{p}",\n' for p in wheel_paths) + "]"
    pattern = re.compile(r"^wheels\s*=\s*\[.*?\]", re.MULTILINE | re.DOTALL)
    if pattern.search(text):
        new = pattern.sub(lambda _: array, text, count=1)
    else:
        # Top-level keys must come before the first [table].
        table = re.search(r"^\[", text, re.MULTILINE)
        at = table.start() if table else len(text)
        new = text[:at] + array + "\n\n" + text[at:]
    if tomllib.loads(new).get("wheels") != wheel_paths:
        raise BuildError("could not rewrite the manifest's `wheels` list")
    return new


def stage_extension(wheels: list[pathlib.Path]) -> pathlib.Path:
    """build/extension/ = manifest + addon/ contents + wheels/, replaced in one rename."""
    if not (ADDON / "__init__.py").is_file():
        raise BuildError("addon/__init__.py is missing: the add-on package root is addon/")
    BUILD.mkdir(parents=True, exist_ok=True)
    target = BUILD / "extension"
    staging = pathlib.Path(tempfile.mkdtemp(dir=BUILD, prefix=".extension-"))
    try:
        shutil.copytree(ADDON, staging, ignore=IGNORED, dirs_exist_ok=True)
        (staging / "wheels").mkdir()
        for wheel in wheels:
            shutil.copy2(wheel, staging / "wheels" / wheel.name)
        wheel_paths = [f"./wheels/{w.name}" for w in wheels]
        source = MANIFEST.read_text()
        declared = tomllib.loads(source).get("wheels")
        if declared != wheel_paths:
            say(f"note: {MANIFEST.name} lists {declared}; the extension gets {wheel_paths}")
        (staging / MANIFEST.name).write_text(manifest_with_wheels(source, wheel_paths))
        old = None
        if target.exists():
            old = pathlib.Path(tempfile.mkdtemp(dir=BUILD, prefix=".extension-old-"))
            os.replace(target, old / "extension")
        os.replace(staging, target)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return target


def build_zip(source: pathlib.Path, manifest: dict) -> pathlib.Path:
    """Zip with `blender_ext.py build --split-platforms`, validate, then move into dist/."""
    tool, tags = blender_ext_paths()
    DIST.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=DIST, prefix=".tmp-") as tmp:
        output = run([sys.executable, tool, "build", "--source-dir", source, "--output-dir", tmp,
                      "--split-platforms", "--valid-tags", tags])
        zips = sorted(pathlib.Path(tmp).glob("*.zip"))
        expected = {f"{manifest['id']}-{manifest['version']}-{p.replace('-', '_')}.zip" for p in manifest["platforms"]}
        if {z.name for z in zips} != expected:
            raise BuildError(f"blender_ext build made {[z.name for z in zips]}, expected {sorted(expected)}\n{output}")
        results = []
        for built in zips:
            target = DIST / built.name
            report = run([sys.executable, tool, "validate", "--valid-tags", tags, built]).strip()
            say(f"validated: {report.replace(str(built), str(target.relative_to(ROOT))) or 'ok'}")
            os.replace(built, target)
            results.append(target)
    if len(results) != 1:
        raise BuildError(f"one platform expected, built {[r.name for r in results]}")
    return results[0]


def inputs() -> list[pathlib.Path]:
    """Every file the zip is built from."""
    files = [MANIFEST, REQUIREMENTS, pathlib.Path(__file__).resolve()]
    files += [p for p in ADDON.rglob("*") if p.is_file() and "__pycache__" not in p.parts]
    for pattern in ("**/*.rs", "**/Cargo.toml", "Cargo.lock", "pyproject.toml", "python/**/*.py"):
        files += [p for p in NATIVE.glob(pattern) if "target" not in p.relative_to(NATIVE).parts]
    return files


def zip_path(manifest: dict) -> pathlib.Path:
    (platform,) = manifest["platforms"]
    return DIST / f"{manifest['id']}-{manifest['version']}-{platform.replace('-', '_')}.zip"


def is_fresh(manifest: dict) -> bool:
    target = zip_path(manifest)
    if not target.is_file():
        return False
    newest = max(p.stat().st_mtime for p in inputs())
    return target.stat().st_mtime > newest


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--if-stale", action="store_true",
                        help="do nothing when the zip is newer than every input")
    args = parser.parse_args(argv)
    try:
        manifest = read_manifest()
        if args.if_stale and is_fresh(manifest):
            say(f"up to date: {zip_path(manifest).relative_to(ROOT)}")
            return 0
        start = time.perf_counter()
        engine = build_engine_wheel()
        say(f"engine wheel: {engine.relative_to(ROOT)} ({engine.stat().st_size / 1e6:.1f} MB, "
            f"{time.perf_counter() - start:.1f} s)")
        openexr = download_openexr()
        say(f"OpenEXR wheel: {openexr.relative_to(ROOT)} ({openexr.stat().st_size / 1e6:.1f} MB)")
        staged = stage_extension([engine, openexr])
        say(f"staged: {staged.relative_to(ROOT)}")
        result = build_zip(staged, manifest)
        with zipfile.ZipFile(result) as archive:
            names = archive.namelist()
        say(f"wrote: {result.relative_to(ROOT)} ({result.stat().st_size / 1e6:.1f} MB, {len(names)} files, "
            f"{time.perf_counter() - start:.1f} s)")
    except BuildError as error:
        print(f"build_extension: error: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
