"""The Windows x64 zip: its engine imports and computes under Wine, in the official
embeddable Windows CPython 3.11 and 3.13 (scripts/setup_platforms.sh unpacks them into
build/platforms/) with numpy's win_amd64 wheel (2.1.3: see WINE_NUMPY), and gives the linux
engine's numbers; the zip's OpenEXR wheel for that Python reads an EXR written here. Wine 8
lacks bcryptprimitives.dll (Windows 10 and later have it), so a tiny mingw-built stand-in
(bcryptprimitives_stub.c) is put beside python.exe for this test only. Also checked
statically: the engine links python3.dll (the stable ABI), not python3XY.dll."""

import json
import os
import pathlib
import shutil
import subprocess
import sys
import zipfile

import numpy as np
import pytest

from zips import ROOT, engine_wheel, extract_member, platform_zip, wheels_in

hemishadow = pytest.importorskip("hemishadow")

PLATFORM_DIR = ROOT / "build" / "platforms"
# The Pythons of Blender 4.2 to 5.0 (3.11) and of 5.1 and later (3.13).
PYTHONS = {"3.11": "3.11.0", "3.13": "3.13.0"}
MINGW = "x86_64-w64-mingw32-"
# numpy 2.2 and later call ucrtbase's crealf, which Wine 8 does not implement (the import
# aborts); 2.1.3 is the newest that imports under Wine 8 (Blender 5.3 ships numpy 2.x too).
WINE_NUMPY = "2.1.3"

# One mesh for both engines: an open box (floor and three walls) lit from everywhere.
VERTICES = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1],
            [0.5, 0.5, 0.0], [0.25, 0.75, 0.0]]
TRIANGLES = [[0, 1, 8], [1, 2, 8], [2, 3, 9], [3, 0, 9], [8, 2, 9], [0, 9, 8],
             [0, 4, 5], [0, 5, 1], [1, 5, 6], [1, 6, 2], [3, 7, 4], [3, 4, 0]]

SCRIPT = """
import json, sys
import numpy as np
import hemishadow, hemishadow._native, OpenEXR
from hemishadow.environment import read_exr
t = hemishadow.transfer(np.array({vertices}, np.float32), np.array({triangles}, np.int32), bands=3)
print("RESULT " + json.dumps({{"transfer": t.tolist(), "native": hemishadow._native.__file__,
                              "exr": read_exr(sys.argv[1]).tolist(), "python": sys.version}}))
"""


def tool(name):
    path = shutil.which(name)
    if path is None:
        pytest.skip(f"{name} is missing: scripts/setup_platforms.sh installs it")
    return path


def numpy_wheel(python):
    """numpy's win_amd64 wheel for CPython `python`, downloaded once."""
    cache = PLATFORM_DIR / "downloads"
    cache.mkdir(parents=True, exist_ok=True)
    cp = "cp" + python.replace(".", "")
    pattern = f"numpy-{WINE_NUMPY}-{cp}-{cp}-win_amd64.whl"
    if not list(cache.glob(pattern)):
        subprocess.run([sys.executable, "-m", "pip", "download", "-q", "--disable-pip-version-check", "--no-deps",
                        "--only-binary=:all:", "--python-version", python, "--platform", "win_amd64",
                        f"numpy=={WINE_NUMPY}", "-d", cache], check=True)
    (wheel,) = cache.glob(pattern)
    return wheel


def stub_dll(dest):
    gcc = tool(MINGW + "gcc")
    source = pathlib.Path(__file__).with_name("bcryptprimitives_stub.c")
    subprocess.run([gcc, "-O2", "-shared", "-o", dest / "bcryptprimitives.dll", source, "-ladvapi32"], check=True)


def test_windows_zip_holds_its_wheels():
    wheels = wheels_in(platform_zip("windows-x64"))
    assert [w for w in wheels if w.startswith("hemishadow-")] == ["hemishadow-0.1.0-cp311-abi3-win_amd64.whl"]
    assert sorted(w for w in wheels if w.startswith("openexr-")) == [
        "openexr-3.4.4-cp311-cp311-win_amd64.whl", "openexr-3.4.4-cp313-cp313-win_amd64.whl"]


def test_engine_links_the_stable_abi_dll(tmp_path):
    objdump = tool(MINGW + "objdump")
    with zipfile.ZipFile(engine_wheel(platform_zip("windows-x64"), tmp_path)) as archive:
        archive.extract("hemishadow/_native.pyd", tmp_path)
    dump = subprocess.run([objdump, "-p", tmp_path / "hemishadow" / "_native.pyd"], capture_output=True,
                          text=True, check=True).stdout
    dlls = sorted({line.split(":", 1)[1].strip().lower() for line in dump.splitlines() if "DLL Name:" in line})
    assert "python3.dll" in dlls, dlls
    assert not [d for d in dlls if d.startswith("python3") and d != "python3.dll"], dlls
    # Only system DLLs besides Python: nothing from mingw's runtime that Windows lacks.
    assert not [d for d in dlls if d.startswith(("libgcc", "libwinpthread", "libstdc++"))], dlls
    assert "PyInit__native" in dump


@pytest.mark.parametrize("python_version", sorted(PYTHONS))
def test_engine_runs_under_wine(python_version, tmp_path):
    wine = tool("wine")
    embed = PLATFORM_DIR / f"python-{PYTHONS[python_version]}"
    if not (embed / "python.exe").is_file():
        pytest.skip(f"no embeddable Windows CPython in {embed}: scripts/setup_platforms.sh unpacks it")
    zip_path = platform_zip("windows-x64")
    cp = "cp" + python_version.replace(".", "")
    python = tmp_path / "python"
    shutil.copytree(embed, python)
    site = python / "site"
    # What Blender on Windows installs from this zip for this Python: the engine, OpenEXR.
    for wheel in (engine_wheel(zip_path, tmp_path / "wheels"),
                  extract_member(zip_path, f"openexr-3.4.4-{cp}-{cp}-win_amd64.whl", tmp_path / "wheels"),
                  numpy_wheel(python_version)):
        with zipfile.ZipFile(wheel) as archive:
            archive.extractall(site)
    (python / f"python{cp[2:]}._pth").write_text(f"python{cp[2:]}.zip\n.\nsite\n")
    stub_dll(python)
    exr = tmp_path / "sky.exr"
    pixels = np.random.default_rng(3).random((4, 8, 3), dtype=np.float32)
    from hemishadow.environment import write_exr
    write_exr(exr, {"R": pixels[..., 0], "G": pixels[..., 1], "B": pixels[..., 2]})
    (tmp_path / "smoke.py").write_text(SCRIPT.format(vertices=VERTICES, triangles=TRIANGLES))
    prefix = PLATFORM_DIR / "wineprefix"
    env = dict(os.environ, WINEPREFIX=str(prefix), WINEDEBUG="-all", WINEDLLOVERRIDES="mscoree,mshtml=")
    result = subprocess.run([wine, python / "python.exe", tmp_path / "smoke.py", exr], capture_output=True,
                            text=True, env=env, timeout=600)
    lines = [line for line in result.stdout.splitlines() if line.startswith("RESULT ")]
    assert result.returncode == 0 and len(lines) == 1, result.stdout[-3000:] + result.stderr[-3000:]
    facts = json.loads(lines[0][len("RESULT "):])
    assert facts["python"].startswith(python_version + "."), facts["python"]
    assert facts["native"].lower().endswith("_native.pyd"), facts["native"]
    expected = hemishadow.transfer(np.array(VERTICES, np.float32), np.array(TRIANGLES, np.int32), bands=3)
    got = np.array(facts["transfer"], np.float32)
    assert got.shape == expected.shape
    assert np.abs(got - expected).max() < 1e-5, np.abs(got - expected).max()
    assert np.array_equal(np.array(facts["exr"], np.float32), pixels)
