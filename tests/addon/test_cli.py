"""`blender --background FILE.blend --command hemishadow ...`, called as Blender calls it.

The bpy module does not parse --command, so these tests call the function the add-on
registers with `bpy.utils.register_cli_command` (addon.cli.main) with argv lists, on the
.blend file that is open, exactly as Blender would after loading FILE.blend.
"""

import os
import pathlib
import signal

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

ROOT = pathlib.Path(__file__).resolve().parents[2]
FIGURE = ROOT.parent / "shared" / "data" / "rigged_figure.glb"


@pytest.fixture
def cli(addon):
    assert addon.cli._handle is not None, "register() did not register the `hemishadow` command"
    return addon.cli.main


@pytest.fixture
def blend(addon, tmp_path):
    """figure.blend: the walking figure (`Proxy`, hemishadow not enabled) and a static Icosphere."""
    if not FIGURE.is_file():
        pytest.skip(f"{FIGURE} is missing")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=str(FIGURE))
    bpy.context.scene.hemishadow.lighting_source = "BUILTIN"
    path = tmp_path / "figure.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def reopen(path):
    bpy.ops.wm.open_mainfile(filepath=str(path))
    return bpy.context.scene


def test_help(cli, capsys):
    assert cli(["--help"]) == 0
    out = capsys.readouterr().out
    assert "--command hemishadow" in out and "compute" in out and "bake" in out
    assert cli(["bake", "--help"]) == 0
    out = capsys.readouterr().out
    assert "--start" in out and "--pack" in out and "--cache-dir" in out


def test_compute_one_frame_and_save(cli, blend, capsys):
    assert cli(["compute", "--frame", "7", "--objects", "Proxy", "--save"]) == 0
    out = capsys.readouterr().out
    assert "Proxy: frame 7: 370 vertices" in out and "saved" in out
    scene = reopen(blend)
    obj = scene.objects["Proxy"]
    assert scene.frame_current == 7
    assert obj.hemishadow.enabled
    ao = np.empty(len(obj.data.vertices), np.float32)
    obj.data.attributes["hemishadow_ao"].data.foreach_get("value", ao)
    assert 0 < ao.min() < ao.max() <= 1.0 + 1e-5
    assert "hemishadow_radiance" in obj.data.color_attributes
    # The untouched object stays untouched.
    assert "hemishadow_radiance" not in scene.objects["Icosphere"].data.color_attributes


def test_compute_without_save_leaves_the_file_alone(cli, blend):
    before = blend.stat().st_mtime_ns
    assert cli(["compute", "--objects", "Proxy"]) == 0
    assert blend.stat().st_mtime_ns == before


def test_bake_to_files_beside_the_blend(cli, addon, blend, capsys):
    old = os.umask(0o027)
    try:
        assert cli(["bake", "--start", "1", "--end", "4", "--objects", "Proxy", "Icosphere", "--save"]) == 0
    finally:
        os.umask(old)
    output = capsys.readouterr()
    assert "Proxy: frames 1..4 -> //hemishadow_cache/Proxy.npz" in output.out
    # Progress on stderr, a line per 10 % band reached (not a terminal here), within frames too.
    percents = [int(line.split()[1]) for line in output.err.splitlines()]
    assert all(line.startswith("bake: ") for line in output.err.splitlines())
    assert percents[0] == 0 and percents[-1] == 100 and percents == sorted(set(percents))
    assert (blend.parent / "hemishadow_cache" / "Proxy.npz").stat().st_mode & 0o777 == 0o640
    assert (blend.parent / "hemishadow_cache" / "Proxy.npz").is_file()
    assert (blend.parent / "hemishadow_cache" / "Icosphere.npz").is_file()
    scene = reopen(blend)
    for name in ("Proxy", "Icosphere"):
        assert addon.cache.is_valid(scene.objects[name], scene, 3)


def test_bake_packed_and_to_a_chosen_folder(cli, addon, blend, tmp_path):
    assert cli(["bake", "--start", "2", "--end", "3", "--objects", "Proxy", "--pack"]) == 0   # --pack saves
    scene = reopen(blend)
    assert addon.cache.PACKED_KEY in scene.objects["Proxy"]
    assert addon.cache.is_valid(scene.objects["Proxy"], scene, 2)
    folder = tmp_path / "elsewhere"
    assert cli(["bake", "--start", "1", "--end", "2", "--cache-dir", str(folder), "--no-transfer"]) == 0
    assert (folder / "Proxy.npz").is_file()   # Proxy is enabled now: the default selection
    assert addon.cache.load(scene.objects["Proxy"]).transfer is None


@pytest.mark.parametrize("argv, code, message", [
    ([], 2, "a command is needed"),
    (["frobnicate"], 2, "invalid choice: 'frobnicate'"),
    (["compute", "--objects", "Nope"], 2, "no object 'Nope' in scene 'Scene'; mesh objects: Proxy, Icosphere"),
    (["compute", "--objects", "Armature"], 2, "armature object, not a mesh: 'Armature'"),
    (["compute"], 2, "no object has hemishadow enabled"),
    (["bake", "--start", "x"], 2, "argument --start: invalid int value: 'x'"),
    (["bake", "--start", "5", "--end", "1", "--objects", "Proxy"], 2, "--end 1 is before --start 5"),
    (["bake", "--pack", "--cache-dir", "/tmp", "--objects", "Proxy"], 2, "not allowed with argument"),
    (["compute", "--scene", "Nope", "--objects", "Proxy"], 2, "no scene named 'Nope'"),
])
def test_bad_arguments_give_a_message_and_a_non_zero_exit(cli, blend, capsys, argv, code, message):
    assert cli(argv) == code
    err = capsys.readouterr().err
    assert message in err
    assert err.startswith("blender --background FILE.blend --command hemishadow")


def test_failures_exit_1_with_a_message(cli, capsys):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_cube_add()
    # An unsaved file: the default cache folder (//) does not exist.
    assert cli(["bake", "--start", "1", "--end", "2", "--objects", "Cube"]) == 1
    assert "hemishadow: error: the .blend file is not saved" in capsys.readouterr().err
    assert cli(["compute", "--objects", "Cube", "--save"]) == 1
    assert "never been saved" in capsys.readouterr().err


def test_compute_shows_the_engine_progress(cli, blend, capsys):
    assert cli(["compute", "--objects", "Proxy"]) == 0
    lines = capsys.readouterr().err.splitlines()
    assert lines[0] == "compute: 0 %" and lines[-1] == "compute: 100 %", lines


@pytest.fixture
def ctrl_c_at_first_progress(monkeypatch):
    """Press Ctrl-C (a real SIGINT to this process) when the first progress is shown."""
    import hemishadow.cli

    class Interrupting(hemishadow.cli.ProgressBar):
        def __call__(self, fraction):
            if fraction > 0 and not self.interrupted.is_set():
                os.kill(os.getpid(), signal.SIGINT)
            return super().__call__(fraction)

    monkeypatch.setattr(hemishadow.cli, "ProgressBar", Interrupting)


@pytest.mark.parametrize("command", [["compute"], ["bake", "--start", "1", "--end", "6"]])
def test_ctrl_c_cancels_and_saves_nothing(cli, addon, blend, capsys, ctrl_c_at_first_progress, command):
    before = blend.stat().st_mtime_ns
    assert cli([*command, "--objects", "Proxy", "--save"]) == 130
    err = capsys.readouterr().err
    assert "hemishadow: cancelled (Ctrl-C): nothing saved" in err and "Traceback" not in err
    assert blend.stat().st_mtime_ns == before
    assert not (blend.parent / "hemishadow_cache").exists()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler   # Ctrl-C behaves as before


def test_a_bad_cache_folder_fails_before_baking(cli, blend, capsys):
    (blend.parent / "taken").write_text("a file where the folder should be")
    folder = blend.parent / "taken" / "cache"
    assert cli(["bake", "--start", "1", "--end", "3", "--objects", "Proxy", "--cache-dir", str(folder)]) == 1
    output = capsys.readouterr()
    assert f"hemishadow: error: cannot use the cache folder {folder}: " in output.err
    assert "is a file, not a folder" in output.err
    assert "bake:" not in output.err and "baked" not in output.out   # not a frame computed
