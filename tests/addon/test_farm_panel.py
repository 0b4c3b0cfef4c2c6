"""The Farm section of the Actions panel (issue 14): it submits the saved .blend's job as
`PYTHON -m hemishadow farm KIND FILE --scheduler ADDRESS [options]`, refuses an unsaved file
(and saves nothing itself), follows the process and cancels it with Ctrl-C."""

import os
import sys
import time

import pytest

bpy = pytest.importorskip("bpy")


@pytest.fixture
def saved(scene, tmp_path):
    bpy.ops.mesh.primitive_cube_add()
    cube = bpy.context.object
    cube.name = "Cube"
    cube.hemishadow.enabled = True
    scene.frame_start, scene.frame_end = 3, 9
    path = tmp_path / "farm.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def test_unsaved_file_is_refused_and_nothing_is_saved(scene):
    from addon import farm_panel

    assert not bpy.data.filepath
    scene.hemishadow_farm.python = sys.executable
    with pytest.raises(ValueError, match="save the .blend first"):
        farm_panel.farm_command(bpy.context)
    with pytest.raises(RuntimeError, match="save the .blend first"):   # the operator's error report
        bpy.ops.hemishadow.farm_submit()
    assert not bpy.data.filepath and farm_panel.current() is None


def test_the_command_is_the_bake_buttons_job_on_the_saved_file(saved):
    from addon import farm_panel

    settings = bpy.context.scene.hemishadow_farm
    settings.python = "/opt/venv/bin/python"
    command = farm_panel.farm_command(bpy.context)
    assert command[:6] == ["/opt/venv/bin/python", "-m", "hemishadow", "farm", "bake", str(saved)]
    assert command[6:8] == ["--scheduler", "tcp://127.0.0.1:8786"]   # loopback unless told
    assert command[8:] == ["--start", "3", "--end", "9", "--scene", "Scene", "--objects", "Cube"]
    settings.kind, settings.address = "lightmaps", "tls://farm:8786"
    bpy.context.scene.hemishadow_lightmaps.resolution = 128
    bpy.context.scene.objects["Cube"].select_set(True)
    command = farm_panel.farm_command(bpy.context)
    assert command[4] == "lightmaps" and "tls://farm:8786" in command
    assert command[command.index("--resolution") + 1] == "128" and "Cube" in command


def test_submit_follows_the_process_and_cancel_sends_ctrl_c(saved, tmp_path):
    from addon import farm_panel

    fake = tmp_path / "python"   # prints a progress line, then waits; Ctrl-C exits 130 as the client does
    fake.write_text("#!/bin/sh\ntrap 'echo cancelled; exit 130' INT\necho \"hemishadow farm: [1/4] $4\"\n"
                    "while true; do sleep 0.1; done\n")
    fake.chmod(0o755)
    bpy.context.scene.hemishadow_farm.python = str(fake)
    mtime = os.stat(saved).st_mtime_ns
    assert bpy.ops.hemishadow.farm_submit() == {"FINISHED"}
    run = farm_panel.current()
    deadline = time.time() + 10
    while not run.lines and time.time() < deadline:
        time.sleep(0.05)
    assert run.status == "running: hemishadow farm: [1/4] bake"
    with pytest.raises(RuntimeError, match="a farm job is running"):   # one job at a time
        bpy.ops.hemishadow.farm_submit()
    assert bpy.ops.hemishadow.farm_cancel() == {"FINISHED"}
    assert run.process.wait(timeout=10) == 130
    assert run.status == "cancelled: nothing written"
    assert os.stat(saved).st_mtime_ns == mtime   # nothing saved


def test_the_lightmap_and_panorama_jobs_follow_their_panels(saved):
    """What the panel submits parses with the headless commands' own parser into the panels'
    settings: the Lightmaps panel's atlas (or per-object layout) and the Panorama panel's
    viewpoint, size, coefficients and bounces."""
    from addon import cli, farm_panel

    scene = bpy.context.scene
    scene.hemishadow_farm.python = "/opt/venv/bin/python"
    bpy.ops.mesh.primitive_plane_add(location=(0, 0, -1))
    for obj in scene.objects:
        obj.select_set(obj.type == "MESH")
    scene.hemishadow_farm.kind = "lightmaps"
    lm = scene.hemishadow_lightmaps
    lm.layout, lm.atlas_name, lm.uv_name = "ATLAS", "level", "islands_here"
    bpy.ops.wm.save_mainfile()
    args = cli.build_parser().parse_args(["lightmaps", *farm_panel.farm_command(bpy.context)[8:]])
    assert args.uv is None and not args.per_object and (args.atlas, args.islands) == ("level", "islands_here")
    lm.layout = "OBJECT"
    bpy.ops.wm.save_mainfile()
    args = cli.build_parser().parse_args(["lightmaps", *farm_panel.farm_command(bpy.context)[8:]])
    assert args.uv == "islands_here" and not args.uniform
    lm.adaptive = False
    bpy.ops.wm.save_mainfile()
    assert cli.build_parser().parse_args(["lightmaps", *farm_panel.farm_command(bpy.context)[8:]]).uniform

    scene.hemishadow_farm.kind = "panorama"
    pano = scene.hemishadow_panorama
    pano.source, pano.point = "POINT", (1.0, -2.5, 0.75)
    pano.width, pano.height, pano.coefficients, pano.bounces = 256, 128, "25", 1
    bpy.ops.wm.save_mainfile()
    command = farm_panel.farm_command(bpy.context)
    assert command[4] == "panorama"
    args = cli.build_parser().parse_args(["panorama", *command[8:]])
    assert tuple(args.at) == (1.0, -2.5, 0.75) and tuple(args.size) == (256, 128)
    assert (args.coefficients, args.bounces) == (25, 1)
