"""Build the Blender extension zips: dist/<id>-<version>-<platform>.zip, one per platform.

Run with the project's environment: `.venv/bin/python scripts/build_extension.py`
(linux-x64 only, what this machine runs) or `... --platforms all` (also windows-x64,
macos-arm64 and macos-x64: needs the cross toolchains of scripts/setup_platforms.sh).

Passes:
  1. build the engine wheel per platform (maturin, release, abi3 for CPython 3.11+) into
     build/wheels/<platform>/; Windows with mingw-w64, macOS with zig as the linker;
  2. download the OpenEXR wheel pinned in requirements.txt for each platform and each Python
     that Blender runs (3.11: Blender 4.2 to 5.0; 3.13: 5.1 and later), kept in
     build/downloads/, so later builds work offline;
  3. stage build/extension/: blender_manifest.toml (`platforms` and `wheels` rewritten from
     what was built), the contents of addon/, and wheels/;
  4. build the zips with Blender's own extension tool (bpy's bl_pkg/cli/blender_ext.py, the
     code behind `blender --command extension build --split-platforms`), with Blender's list
     of valid tags: each zip gets only its platform's wheels, and Blender picks the wheels
     for its own Python when it installs;
  5. validate each zip with the same tool, then move it into dist/.

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

# The Pythons of the supported Blenders: 3.11 (4.2 LTS to 5.0) and 3.13 (5.1 and later).
# The engine wheel is abi3 (one for all); OpenEXR needs one wheel per Python.
PYTHON_VERSIONS = ("3.11", "3.13")

# Blender platform -> how its engine wheel is built and which OpenEXR wheels fit it
# (pip's --platform tags, the first one that has a wheel wins).
PLATFORMS = {
    "linux-x64": {"target": None, "maturin": [], "pip": ["manylinux2014_x86_64"]},
    "windows-x64": {"target": "x86_64-pc-windows-gnu",
                    # python3.dll's import library, made by pyo3 (no Windows Python needed);
                    # one interpreter named, or maturin also builds PyPy and 3.13t wheels.
                    "maturin": ["--features", "pyo3/generate-import-lib", "--interpreter", "python3.11"],
                    # meshoptimizer's C++ with mingw's libstdc++ linked in, so that the DLL
                    # needs no libstdc++-6.dll (Windows has none; tests/platforms checks).
                    "env": {"CXXSTDLIB_STATIC_x86_64_pc_windows_gnu": "1"},
                    "pip": ["win_amd64"]},
    # macOS 11 as the oldest: what Blender 4.2 needs (11.2). MACOSX_DEPLOYMENT_TARGET tags the
    # wheel, but maturin's zig wrapper links for `-target <arch>-macos-none` (zig's default,
    # macOS 13): a later versioned -target, passed as link arguments, wins.
    "macos-arm64": {"target": "aarch64-apple-darwin", "maturin": ["--zig"],
                    "env": {"MACOSX_DEPLOYMENT_TARGET": "11.0", "CARGO_TARGET_AARCH64_APPLE_DARWIN_RUSTFLAGS":
                            "-C link-arg=-target -C link-arg=aarch64-macos.11.0-none"},
                    "pip": ["macosx_11_0_arm64", "macosx_10_15_universal2"]},
    "macos-x64": {"target": "x86_64-apple-darwin", "maturin": ["--zig"],
                  "env": {"MACOSX_DEPLOYMENT_TARGET": "11.0", "CARGO_TARGET_X86_64_APPLE_DARWIN_RUSTFLAGS":
                          "-C link-arg=-target -C link-arg=x86_64-macos.11.0-none"},
                  "pip": ["macosx_10_15_x86_64", "macosx_10_9_x86_64", "macosx_10_15_universal2"]},
}
HOST_PLATFORM = "linux-x64"

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


def build_engine_wheel(platform: str) -> pathlib.Path:
    """maturin build --release from native/; abi3 comes from pyo3's abi3-py311 feature."""
    spec = PLATFORMS[platform]
    out = BUILD / "wheels" / platform
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=out, prefix=".tmp-") as tmp:
        venv = pathlib.Path(sys.prefix)
        # The same environment as scripts/setup.sh's `maturin develop`, so cargo reuses its
        # artifacts instead of rebuilding pyo3 for another interpreter configuration.
        env = dict(os.environ, VIRTUAL_ENV=str(venv), PATH=f"{venv / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}",
                   **spec.get("env", {}))
        maturin = shutil.which("maturin", path=env["PATH"]) or "maturin"
        command = [maturin, "build", "--release", "--out", tmp, *spec["maturin"]]
        if spec["target"]:
            command += ["--target", spec["target"]]
        run(command, cwd=NATIVE, env=env)
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


def download_openexr(platform: str, python: str) -> pathlib.Path:
    """The pinned OpenEXR wheel for one platform and one CPython version, downloaded once."""
    version = pinned_version("OpenEXR")
    cp = "cp" + python.replace(".", "")
    cache = BUILD / "downloads" / platform
    cache.mkdir(parents=True, exist_ok=True)
    pattern = f"openexr-{version}-{cp}-{cp}-*.whl"
    found = sorted(cache.glob(pattern))
    if found:
        return found[0]
    platform_args = [arg for tag in PLATFORMS[platform]["pip"] for arg in ("--platform", tag)]
    with tempfile.TemporaryDirectory(dir=cache, prefix=".tmp-") as tmp:
        run([sys.executable, "-m", "pip", "download", "--disable-pip-version-check", "--quiet",
             "--only-binary=:all:", "--no-deps", "--python-version", python,
             "--implementation", "cp", "--abi", cp, *platform_args, f"OpenEXR=={version}", "--dest", tmp])
        wheels = sorted(pathlib.Path(tmp).glob(pattern))
        if len(wheels) != 1:
            raise BuildError(f"pip downloaded {[w.name for w in pathlib.Path(tmp).iterdir()]}, expected {pattern}")
        target = cache / wheels[0].name
        os.replace(wheels[0], target)
    return target


def manifest_with_platforms(text: str, platforms: list[str]) -> str:
    """The manifest text with its `platforms = [...]` array replaced by platforms."""
    array = "platforms = [" + ", ".join(f'"{p}"' for p in platforms) + "]"
    pattern = re.compile(r"^platforms\s*=\s*\[.*?\]", re.MULTILINE | re.DOTALL)
    new = pattern.sub(lambda _: array, text, count=1)
    if tomllib.loads(new).get("platforms") != platforms:
        raise BuildError("could not rewrite the manifest's `platforms` list")
    return new


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


def stage_extension(wheels: list[pathlib.Path], platforms: list[str]) -> pathlib.Path:
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
        missing = set(wheel_paths) - set(declared or [])
        if missing:
            say(f"note: {MANIFEST.name} does not list {sorted(missing)}")
        text = manifest_with_platforms(manifest_with_wheels(source, wheel_paths), platforms)
        (staging / MANIFEST.name).write_text(text)
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


def build_zips(source: pathlib.Path, manifest: dict, platforms: list[str]) -> list[pathlib.Path]:
    """Zip with `blender_ext.py build --split-platforms`, validate each, then move into dist/."""
    tool, tags = blender_ext_paths()
    DIST.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=DIST, prefix=".tmp-") as tmp:
        output = run([sys.executable, tool, "build", "--source-dir", source, "--output-dir", tmp,
                      "--split-platforms", "--valid-tags", tags])
        zips = sorted(pathlib.Path(tmp).glob("*.zip"))
        expected = {zip_path(manifest, p).name for p in platforms}
        if {z.name for z in zips} != expected:
            raise BuildError(f"blender_ext build made {[z.name for z in zips]}, expected {sorted(expected)}\n{output}")
        results = []
        for built in zips:
            target = DIST / built.name
            report = run([sys.executable, tool, "validate", "--valid-tags", tags, built]).strip()
            say(f"validated: {report.replace(str(built), str(target.relative_to(ROOT))) or 'ok'}")
            os.replace(built, target)
            results.append(target)
    return results


def inputs() -> list[pathlib.Path]:
    """Every file the zip is built from."""
    files = [MANIFEST, REQUIREMENTS, pathlib.Path(__file__).resolve()]
    files += [p for p in ADDON.rglob("*") if p.is_file() and "__pycache__" not in p.parts]
    # python/**/web/*: the panorama web viewer's page and scripts, which the wheel carries too.
    for pattern in ("**/*.rs", "**/Cargo.toml", "Cargo.lock", "pyproject.toml", "python/**/*.py", "python/**/web/*"):
        files += [p for p in NATIVE.glob(pattern) if "target" not in p.relative_to(NATIVE).parts]
    return files


def zip_path(manifest: dict, platform: str = HOST_PLATFORM) -> pathlib.Path:
    return DIST / f"{manifest['id']}-{manifest['version']}-{platform.replace('-', '_')}.zip"


def is_fresh(manifest: dict, platforms: list[str]) -> bool:
    targets = [zip_path(manifest, p) for p in platforms]
    if not all(t.is_file() for t in targets):
        return False
    newest = max(p.stat().st_mtime for p in inputs())
    return min(t.stat().st_mtime for t in targets) > newest


def parse_platforms(value: str, manifest: dict) -> list[str]:
    declared = list(manifest["platforms"])
    if value == "all":
        return declared
    platforms = [p.strip() for p in value.split(",") if p.strip()]
    unknown = [p for p in platforms if p not in declared or p not in PLATFORMS]
    if unknown or not platforms:
        raise BuildError(f"--platforms: {unknown or value!r} not among {declared}")
    return platforms


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--if-stale", action="store_true",
                        help="do nothing when the zips are newer than every input")
    parser.add_argument("--platforms", default=HOST_PLATFORM,
                        help=f"comma-separated Blender platforms, or `all` (default: {HOST_PLATFORM})")
    args = parser.parse_args(argv)
    try:
        manifest = read_manifest()
        platforms = parse_platforms(args.platforms, manifest)
        if args.if_stale and is_fresh(manifest, platforms):
            for platform in platforms:
                say(f"up to date: {zip_path(manifest, platform).relative_to(ROOT)}")
            return 0
        start = time.perf_counter()
        wheels = []
        for platform in platforms:
            engine = build_engine_wheel(platform)
            say(f"engine wheel: {engine.relative_to(ROOT)} ({engine.stat().st_size / 1e6:.1f} MB, "
                f"{time.perf_counter() - start:.1f} s)")
            wheels.append(engine)
            for python in PYTHON_VERSIONS:
                openexr = download_openexr(platform, python)
                say(f"OpenEXR wheel: {openexr.relative_to(ROOT)} ({openexr.stat().st_size / 1e6:.1f} MB)")
                wheels.append(openexr)
        staged = stage_extension(wheels, platforms)
        say(f"staged: {staged.relative_to(ROOT)}")
        for result in build_zips(staged, manifest, platforms):
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
