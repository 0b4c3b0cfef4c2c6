"""The demo (scripts/demo_blender.py, run by `make demo`) installs the built extension and
shades through it: a reduced run (3 frames, no renders) in its own process, with its own
Blender user folder."""

import os
import pathlib
import subprocess
import sys

import pytest

pytest.importorskip("bpy")  # the subprocess imports it

ROOT = pathlib.Path(__file__).resolve().parents[2]
MODULE = "bl_ext.user_default.hemishadow"


@pytest.fixture(scope="module")
def zip_path():
    result = subprocess.run([sys.executable, str(ROOT / "scripts" / "build_extension.py"), "--if-stale"],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr
    (path,) = (ROOT / "dist").glob("hemishadow-*-linux_x64.zip")
    return path


def test_reduced_demo_uses_the_installed_extension(zip_path, tmp_path):
    user, out = tmp_path / "user", tmp_path / "demo"
    (user / "stale").mkdir(parents=True)   # the demo starts from an empty user folder
    env = {k: v for k, v in os.environ.items() if k != "BLENDER_USER_RESOURCES"}
    result = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "demo_blender.py"), str(zip_path), "--frames", "3", "--no-render",
         "--out", str(out), "--user-resources", str(user)],
        capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    assert "Traceback" not in output, output
    assert not (user / "stale").exists()
    assert (user / "extensions" / "user_default" / "hemishadow" / "blender_manifest.toml").is_file()
    site = user / "extensions" / ".local" / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}"
    assert f"{MODULE} enabled" in output, output
    assert f"engine from {site}" in output, output
    for name in ("Cloth", "Suzanne", "Floor"):
        assert f"attributes of {name}: hemishadow_ao, hemishadow_radiance" in output, output
    assert "shadow casters: cloth, Suzanne and floor" in output, output
    assert "Cloth: 1444 vertices, computed on 2 frames" in output, output   # frames 2 and 3, live
    # Static, but shadowed by the falling cloth: computed again on every frame.
    assert "Suzanne: 507 vertices, computed on 2 frames" in output, output
    assert (out / "demo.blend").is_file()
    assert {p.name for p in (out / "hemishadow_cache").iterdir()} == {"Cloth.npz", "Suzanne.npz", "Floor.npz"}
    assert not list(out.glob("*.png"))
