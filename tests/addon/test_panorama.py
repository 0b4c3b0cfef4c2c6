"""The panorama bake from Blender (issue 13): `--command hemishadow panorama`, the operator and
its job (cancel writes nothing), bad input, and the live relight in Blender (the image follows
a Sun or Point lamp and equals the engine's relight for it)."""

import math
import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import hemishadow.panorama as hp  # noqa: E402

SIZE = "48x24"


@pytest.fixture
def room(addon):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.world.clear_cache()
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    bpy.context.active_object.name = "Floor"
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(2.0, 0.0, 0.5))
    bpy.context.active_object.name = "Box"
    bpy.ops.object.light_add(type="SUN", rotation=(math.radians(30), 0, 0))
    sun = bpy.context.active_object
    sun.name, sun.data.energy = "Sun", 3.0
    bpy.context.view_layer.update()
    return scene


def _files(folder):
    return sorted(os.path.relpath(os.path.join(d, f), folder) for d, _, fs in os.walk(folder) for f in fs)


def test_command_line_writes_both_forms(room, addon, tmp_path, capsys):
    out = tmp_path / "pano.exr"
    assert addon.cli.main(["panorama", "--at", "0,0,1", "--size", SIZE, "--coefficients", "9", "--out", str(out)]) == 0
    printed = capsys.readouterr()
    assert "panorama 48 x 24, 9 coefficients" in printed.out and "100 %" in printed.err
    exr, compact = hp.Panorama.load(out), hp.Panorama.load(tmp_path / "pano" / "panorama.json")
    assert exr.coefficients.shape == (24, 48, 9, 3) and exr.bands == 3
    assert np.allclose(exr.origin, (0, 0, 1)) and np.allclose(exr.rotation, np.eye(3))
    assert exr.mask[-1].all() and not exr.mask[0].any()  # floor below, sky above
    lit = hp.relight(exr, [hp.Sun((0, 0, 1), 3.0)])
    # the open floor straight below: albedo 0.8 (no material: Blender's default grey) x 3 W/m^2 / pi,
    # times what 9 coefficients make of the clamped cosine at its peak: (1 + 2 + 5/4) / 4
    assert abs(lit[-1, 0, 0] / (0.8 * 3 / np.pi * 1.0625) - 1) < 0.01  # the 32 x 32 cell disk: 0.6 %
    scale = np.abs(exr.coefficients).max()
    assert np.abs(compact.coefficients - exr.coefficients).max() < scale / 100  # 8 bits and float16


def test_bounce_adds_light(room, addon, tmp_path):
    assert addon.cli.main(["panorama", "--at", "0,0,1", "--size", SIZE, "--bounces", "1", "--out",
                           str(tmp_path / "b.exr")]) == 0
    pano = hp.Panorama.load(tmp_path / "b.exr")
    assert pano.bounce is not None and pano.bounce.shape == (24, 48, 3)
    assert (pano.bounce >= 0).all() and pano.bounce[pano.mask].max() > 0  # the box lights the floor and back
    assert not pano.bounce[~pano.mask].any()


def test_bad_input_names_the_problem_and_writes_nothing(room, addon, tmp_path, capsys):
    assert addon.cli.main(["panorama", "--at", "2,0,0.5", "--size", SIZE, "--out", str(tmp_path / "in.exr")]) == 1
    assert "Box: the viewpoint (2, 0, 0.5) is inside it" in capsys.readouterr().err
    assert addon.cli.main(["panorama", "--camera", "Nope", "--out", str(tmp_path / "c.exr")]) == 2
    assert "no camera or Empty named 'Nope'" in capsys.readouterr().err
    assert addon.cli.main(["panorama", "--at", "0,0", "--out", str(tmp_path / "c.exr")]) == 2
    locked = tmp_path / "locked"
    locked.mkdir()
    (locked / "file").write_text("a file, not a folder")
    assert addon.cli.main(["panorama", "--at", "0,0,1", "--size", SIZE, "--out",
                           str(locked / "file" / "p.exr")]) == 1
    assert "cannot write the panorama to" in capsys.readouterr().err
    for obj in [o for o in room.objects if o.type == "MESH"]:
        bpy.data.objects.remove(obj)
    assert addon.cli.main(["panorama", "--at", "0,0,1", "--size", SIZE, "--out", str(tmp_path / "e.exr")]) == 1
    assert "no visible, renderable mesh to bake a panorama of" in capsys.readouterr().err
    assert _files(tmp_path) == ["locked/file"]


def test_cancelled_job_writes_nothing_and_operator_bakes(room, addon, tmp_path):
    from addon import panorama_job

    path = str(tmp_path / "job.exr")
    job = panorama_job.PanoramaBake(room, path, at=(0, 0, 1), size=(48, 24))
    job.cancel()
    job.start()
    while job.step(0.1) == panorama_job.RUNNING:
        pass
    assert job.state == panorama_job.CANCELLED and _files(tmp_path) == []
    settings = room.hemishadow_panorama
    settings.source, settings.point, settings.width, settings.height = "POINT", (0, 0, 1), 48, 24
    settings.filepath = path
    assert bpy.ops.hemishadow.bake_panorama() == {"FINISHED"}
    assert settings.baked == str(tmp_path / "job" / "panorama.json")
    assert "job.exr" in _files(tmp_path)


@pytest.fixture
def live(room, addon, tmp_path, monkeypatch):
    from addon import panorama_live

    monkeypatch.setattr(panorama_live, "INTERVAL", 0.0)
    settings = room.hemishadow_panorama
    settings.source, settings.point, settings.width, settings.height = "POINT", (0, 0, 1), 48, 24
    settings.filepath = str(tmp_path / "live.exr")
    assert bpy.ops.hemishadow.bake_panorama() == {"FINISHED"}
    settings.live = True
    return panorama_live


def _image():
    image = bpy.data.images["hemishadow_panorama"]
    w, h = image.size
    px = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(px)
    return px.reshape(h, w, 4)[::-1, :, :3]


def test_live_image_follows_a_sun_and_a_point_lamp(live, room):
    pano = hp.Panorama.load(room.hemishadow_panorama.baked)
    sun = room.objects["Sun"]
    first = _image()
    sun.rotation_euler = (math.radians(70), 0, math.radians(40))
    bpy.context.view_layer.update()  # depsgraph_update_post: the handler relights
    after = _image()
    direction = np.array(sun.matrix_world.to_3x3().col[2])
    expected = hp.relight(pano, [hp.Sun(direction, 3.0)])
    assert np.abs(after - first).max() > 0.05
    assert np.abs(after - expected).max() < 1e-4 * max(1.0, expected.max())
    sun.hide_render = sun.hide_viewport = True
    bpy.ops.object.light_add(type="POINT", location=(1.0, -1.0, 1.5))
    lamp = bpy.context.active_object
    lamp.data.energy = 200.0
    bpy.context.view_layer.update()
    lamp.location = (-1.0, 1.0, 1.2)
    bpy.context.view_layer.update()
    expected = hp.relight(pano, [hp.Point((-1.0, 1.0, 1.2), 200.0)])
    got = _image()
    assert np.abs(got - expected).max() < 1e-4 * max(1.0, expected.max()) and got.max() > 0.1


def test_panel_direction_and_save(live, room, tmp_path):
    settings = room.hemishadow_panorama
    settings.lights, settings.direction, settings.strength = "DIRECTION", (0.0, 0.6, 0.8), 5.0
    pano = hp.Panorama.load(settings.baked)
    expected = hp.relight(pano, [hp.Sun((0.0, 0.6, 0.8), 5.0)])
    assert np.abs(_image() - expected).max() < 1e-4 * max(1.0, expected.max())
    png, exr = tmp_path / "relit.png", tmp_path / "relit.exr"
    assert bpy.ops.hemishadow.save_relit_panorama(filepath=str(png)) == {"FINISHED"}
    assert bpy.ops.hemishadow.save_relit_panorama(filepath=str(exr)) == {"FINISHED"}
    from hemishadow.environment import read_exr

    assert np.allclose(read_exr(exr), expected, atol=1e-6)
    image = bpy.data.images.load(str(png))
    assert tuple(image.size) == (48, 24)
