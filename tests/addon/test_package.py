"""The built extension zip installs into the bpy module the way a user installs it.

`scripts/build_extension.py --if-stale` builds dist/hemishadow-<version>-linux_x64.zip (or
reuses it when it is newer than every input). The same tests run on every supported Blender:
on the primary version (.venv) and, through scripts/run_tests.py, on each second-tier version
(.venv-X.Y), so the zip is checked with Python 3.11 and 3.13. Each test runs in its own Python process with
BLENDER_USER_RESOURCES pointing at a temporary folder: the bpy module reads it when it is
imported, so a process per test is the only way to start from an empty user configuration,
and a real user's configuration is never touched.
"""

import json
import os
import pathlib
import subprocess
import sys
import textwrap
import tomllib
import zipfile

import pytest

pytest.importorskip("bpy")  # the subprocesses import it; skip where it is not installed

ROOT = pathlib.Path(__file__).resolve().parents[2]
MODULE = "bl_ext.user_default.hemishadow"
PYTHON = f"python{sys.version_info.major}.{sys.version_info.minor}"


@pytest.fixture(scope="module")
def package():
    """Path of the built zip and the manifest it was built from."""
    with open(ROOT / "blender_manifest.toml", "rb") as fh:
        manifest = tomllib.load(fh)
    given = os.environ.get("HEMISHADOW_TEST_ZIP")
    if given:  # the second tier (tests/tier2) tests a zip built by the primary environment
        return pathlib.Path(given), manifest
    result = subprocess.run([sys.executable, str(ROOT / "scripts" / "build_extension.py"), "--if-stale"],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr
    # The zip for this machine; the other platforms' zips are tested by tests/platforms.
    assert "linux-x64" in manifest["platforms"]
    path = ROOT / "dist" / f"{manifest['id']}-{manifest['version']}-linux_x64.zip"
    assert path.is_file(), result.stdout
    return path, manifest


# Runs in a fresh process; prints one JSON line prefixed with RESULT.
PRELUDE = """
import json, os, sys
import bpy, addon_utils

MODULE = {module!r}

def fail(error):
    raise error

def install():
    result = bpy.ops.extensions.package_install_files(
        filepath={zip!r}, repo="user_default", enable_on_install=True)
    return sorted(result)

def enabled():
    return list(addon_utils.check(MODULE)) + [MODULE in bpy.context.preferences.addons]

def operators():
    return sorted(dir(bpy.ops.hemishadow))

def report(**facts):
    print("RESULT " + json.dumps(facts), flush=True)
    if bpy.app.version < (5, 0):
        # The bpy module of 4.2 and 4.5 crashes at interpreter exit once any Python property
        # callback (update=, items=) or CLI command was registered, even after unregistering
        # (Blender's own exit path differs): leave without that teardown.
        sys.stderr.flush()
        os._exit(0)
"""


def run_blender(zip_path, body, user_resources):
    """Run PRELUDE + body with the bpy module in a fresh process; the facts it reports."""
    user_resources = pathlib.Path(user_resources)
    # Blender puts the extensions' wheel folder ahead of the other site-packages only when it
    # exists at start-up (as it does once any extension with wheels has been installed);
    # created later, it goes to the end of sys.path, behind this environment's editable
    # install of the engine. Creating it first tests what a user's Blender imports.
    site = user_resources / "extensions" / ".local" / "lib" / PYTHON / "site-packages"
    site.mkdir(parents=True, exist_ok=True)
    script = PRELUDE.format(module=MODULE, zip=str(zip_path)) + textwrap.dedent(body)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user_resources))
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env,
                            cwd=user_resources, timeout=300)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    lines = [line for line in result.stdout.splitlines() if line.startswith("RESULT ")]
    assert len(lines) == 1, output
    return json.loads(lines[0][len("RESULT "):]), output


def test_zip_holds_manifest_addon_and_wheels(package):
    path, manifest = package
    with zipfile.ZipFile(path) as archive:
        names = set(archive.namelist())
        inside = tomllib.loads(archive.read("blender_manifest.toml").decode())
    # --split-platforms writes this zip's own platform and wheels into [build.generated],
    # which Blender reads instead of the top-level lists (those name every platform's).
    generated = inside.get("build", {}).get("generated", {})
    assert "__init__.py" in names
    assert not any("__pycache__" in n or n.endswith(".pyc") for n in names)
    assert inside["id"] == "hemishadow" and inside["version"] == manifest["version"]
    assert inside["license"] == ["SPDX:GPL-3.0-or-later"]
    assert generated.get("platforms", inside["platforms"]) == ["linux-x64"]
    wheels = generated.get("wheels", inside["wheels"])
    assert {w.removeprefix("./") for w in wheels} == {n for n in names if n.endswith(".whl")}
    assert any(pathlib.Path(w).name.startswith("hemishadow-") and "-abi3-" in w for w in wheels)
    # OpenEXR once per Python that Blender runs: 3.11 (4.2 LTS to 5.0) and 3.13 (5.1 and later).
    openexr = sorted(pathlib.Path(w).name.split("-")[2] for w in wheels if pathlib.Path(w).name.startswith("openexr-"))
    assert openexr == ["cp311", "cp313"], wheels
    assert len(wheels) == 3, wheels
    addon_files = {p.relative_to(ROOT / "addon").as_posix() for p in (ROOT / "addon").rglob("*.py")
                   if "__pycache__" not in p.parts}
    assert addon_files <= names


def test_install_enables_the_extension(package, tmp_path):
    facts, output = run_blender(package[0], """
        before = enabled()
        result = install()
        report(before=before, result=result, after=enabled())
    """, tmp_path)
    assert facts["before"] == [False, False, False]
    assert facts["after"] == [True, True, True], output
    assert (tmp_path / "extensions" / "user_default" / "hemishadow" / "blender_manifest.toml").is_file()


def test_engine_is_imported_from_the_extension_wheels(package, tmp_path):
    facts, output = run_blender(package[0], """
        install()
        import hemishadow, hemishadow._native, OpenEXR
        import numpy as np
        light = hemishadow.sh_basis([[0, 0, 1]], 3)
        report(engine=hemishadow.__file__, native=hemishadow._native.__file__, openexr=OpenEXR.__file__,
               value=float(light[0, 2]))
    """, tmp_path)
    site = tmp_path / "extensions" / ".local" / "lib" / PYTHON / "site-packages"
    for key in ("engine", "native", "openexr"):
        assert pathlib.Path(facts[key]).is_relative_to(site), (key, facts[key], output)
    assert facts["value"] == pytest.approx(0.488603, abs=1e-6)


def test_blender_installs_the_openexr_wheel_of_its_python(package, tmp_path):
    # The zip carries OpenEXR for CPython 3.11 and 3.13; Blender must pick its own Python's.
    facts, output = run_blender(package[0], """
        import sys
        install()
        import OpenEXR
        report(python=list(sys.version_info[:2]), blender=list(bpy.app.version), openexr=OpenEXR.__file__)
    """, tmp_path)
    site = tmp_path / "extensions" / ".local" / "lib" / PYTHON / "site-packages"
    tags = sorted(line.split(":", 1)[1].strip() for info in site.glob("openexr-*.dist-info")
                  for line in (info / "WHEEL").read_text().splitlines() if line.startswith("Tag:"))
    cp = "cp{}{}".format(*facts["python"])
    assert tags and all(tag.startswith(f"{cp}-{cp}-") for tag in tags), (tags, output)
    assert f"cpython-{cp[2:]}" in pathlib.Path(facts["openexr"]).name or pathlib.Path(facts["openexr"]).name == \
        "__init__.py", facts["openexr"]


def test_operators_are_registered(package, tmp_path):
    facts, output = run_blender(package[0], """
        before = operators()
        install()
        report(before=before, after=operators())
    """, tmp_path)
    assert facts["before"] == []
    assert facts["after"], output


def test_disable_enable_disable_twice(package, tmp_path):
    # handle_error=fail: addon_utils otherwise prints a failing register/unregister and goes on.
    facts, output = run_blender(package[0], """
        install()
        states = [(enabled(), operators())]
        for _ in range(2):
            addon_utils.disable(MODULE, default_set=True, handle_error=fail)
            states.append((enabled(), operators()))
            addon_utils.enable(MODULE, default_set=True, handle_error=fail)
            states.append((enabled(), operators()))
            addon_utils.disable(MODULE, default_set=True, handle_error=fail)
            states.append((enabled(), operators()))
            addon_utils.enable(MODULE, default_set=True, handle_error=fail)
            states.append((enabled(), operators()))
        report(states=states)
    """, tmp_path)
    states = facts["states"]
    registered = states[0][1]
    assert states[0][0] == [True, True, True] and registered, output
    for i, (state, ops) in enumerate(states[1:], start=1):
        if i % 2:  # after a disable
            assert state[1] is False and state[2] is False, (i, state, output)
            assert ops == [], (i, ops)
        else:
            assert state == [True, True, True], (i, state, output)
            assert ops == registered, (i, ops)
    assert "Traceback" not in output, output


def test_command_line_install(package, tmp_path):
    # What `blender --command extension install-file -r user_default -e ZIP` runs: the bpy
    # module does not parse --command, so the registered function is called with its argv.
    facts, output = run_blender(package[0], """
        import bl_pkg
        code = bl_pkg.cli_extension(["install-file", "-r", "user_default", "-e", {zip!r}])
        report(code=code, after=enabled(), operators=operators())
    """.replace("{zip!r}", repr(str(package[0]))), tmp_path)
    assert facts["code"] == 0, output
    assert facts["after"] == [True, True, True], output
    assert facts["operators"], output


def test_engine_wheel_holds_the_panorama_web_viewer(package):
    """`python -m hemishadow serve` needs the viewer's page and scripts beside the server in the wheel."""
    import io

    path, _ = package
    with zipfile.ZipFile(path) as archive:
        (wheel,) = [n for n in archive.namelist() if pathlib.PurePosixPath(n).name.startswith("hemishadow-")]
        with zipfile.ZipFile(io.BytesIO(archive.read(wheel))) as inner:
            names = set(inner.namelist())
    web = ROOT / "native" / "python" / "hemishadow" / "panorama" / "web"
    expected = {f"hemishadow/panorama/web/{p.name}" for p in web.iterdir() if p.is_file()}
    assert len(expected) >= 5 and expected <= names, sorted(expected - names)
    assert "hemishadow/panorama/server.py" in names
