"""The Blender side of the lightmap bake as a user meets it (issue 11): the modal operator's
steps and Esc, the panel's settings, texel density, albedo from the material, shared meshes,
bad input, Add to Materials. Real bpy data; the add-on imported from the repository."""

import math
import pathlib
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import hemishadow.lightmap as lm  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
import addon  # noqa: E402
from addon import lightmap_albedo, lightmap_job, lightmap_nodes, lightmaps, world  # noqa: E402
from lightmap_scenes import plane, white_world  # noqa: E402

FLAT_B = (1 + 1 / math.sqrt(3)) / 2


def new_material(name):
    """A node material, as Blender 5 makes them (before 5.0 nodes must be switched on)."""
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:
        mat.use_nodes = True
    return mat


@pytest.fixture
def scene():
    scene = white_world(world)
    addon.register()  # last: a failed set-up must not leave it registered
    yield scene
    addon.unregister()


def snapshot():
    """What a bake must never change or leave behind: images, materials, meshes' UV maps."""
    return (sorted(i.name for i in bpy.data.images), sorted(m.name for m in bpy.data.materials),
            sorted((m.name, tuple(u.name for u in m.uv_layers), len(m.vertices)) for m in bpy.data.meshes),
            sorted((o.name, o.data.name if o.data else None) for o in bpy.data.objects))


def run(job, cancel_at=None):
    """Drives a job as the modal operator's timer does; cancels once progress passes `cancel_at`."""
    fractions = []
    while job.step(0.02) == lightmap_job.RUNNING:
        fractions.append(job.fraction)
        if cancel_at is not None and job.fraction > cancel_at:
            job.cancel()
    return job.state, fractions


# -- 1. modal bake: steps, progress, cancel ------------------------------------------------------

def test_cancel_in_the_middle_writes_nothing(scene, tmp_path):
    floor = plane()
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 1.0))
    before = snapshot()
    job = lightmap_job.LightmapBake(scene, [floor], out_dir=str(tmp_path), resolution=64, bounces=1).start()
    state, fractions = run(job, cancel_at=0.0)
    assert state == lightmap_job.CANCELLED
    assert 0 < max(fractions) < 1  # cancelled in the middle, through the progress callback
    assert list(tmp_path.iterdir()) == [] and snapshot() == before


def test_cancel_after_the_engine_finished_still_writes_nothing(scene, tmp_path):
    floor = plane()
    before = snapshot()
    job = lightmap_job.LightmapBake(scene, [floor], out_dir=str(tmp_path), resolution=8, bounces=0).start()
    job._thread.join()  # the worker is done; Esc arrives before the timer's next step
    job.cancel()
    assert job.step() == lightmap_job.CANCELLED
    assert list(tmp_path.iterdir()) == [] and snapshot() == before


def test_modal_steps_give_the_plain_result(scene, tmp_path):
    floor = plane()
    job = lightmap_job.LightmapBake(scene, [floor], out_dir=str(tmp_path / "modal"), resolution=16,
                                    bounces=0).start()
    assert run(job)[0] == lightmap_job.FINISHED and job.fraction == 1.0
    plain = lightmaps.bake_lightmaps(scene, [floor], out_dir=str(tmp_path / "plain"), resolution=16, bounces=0)
    a, b = lm.read_exr(job.written["Floor"]), lm.read_exr(plain["Floor"])
    assert set(a) == set(b) and all(np.array_equal(a[k], b[k]) for k in a)
    assert np.abs(a["b0"] - FLAT_B).max() < 2e-3
    assert sorted(p.name for p in (tmp_path / "modal").iterdir()) == ["Floor.exr"]  # no temporary file left


def test_write_files_is_all_or_nothing(tmp_path):
    good = {"flat": np.ones((4, 4, 3), np.float32), "ao": np.ones((4, 4), np.float32)}
    bad = {"flat": np.ones((4, 4, 3), np.float32), "ao": "not an array"}
    with pytest.raises(Exception):
        lightmaps.write_files(str(tmp_path), [("A", good), ("B", bad)])
    assert list(tmp_path.iterdir()) == []


# -- 2. panel settings drive the operators ----------------------------------------------------------

def test_panel_settings_bake_a_collection(scene, tmp_path):
    settings = scene.hemishadow_lightmaps
    assert (settings.uv_name, settings.basis, settings.bounces) == ("lightmap", "hl2", 2)
    assert "HEMISHADOW_PT_lightmaps" in dir(bpy.types)
    floor = plane()
    plane("Other", location=(10, 0, 0))
    group = bpy.data.collections.new("Baked")
    scene.collection.children.link(group)
    group.objects.link(floor)
    settings.source, settings.collection = "COLLECTION", group
    settings.resolution, settings.bounces, settings.basis = 8, 0, "flat"
    settings.directory = str(tmp_path)
    assert bpy.ops.hemishadow.bake_lightmaps() == {"FINISHED"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Floor.exr"]
    maps = lm.read_exr(tmp_path / "Floor.exr")
    assert set(maps) == {"flat", "ao", "coverage"} and maps["flat"].shape == (8, 8, 3)
    settings.size_mode, settings.texel_density = "DENSITY", 2.0  # 4 m -> 8 texels per side
    (tmp_path / "Floor.exr").unlink()
    assert bpy.ops.hemishadow.bake_lightmaps("INVOKE_DEFAULT", basis="hl2") == {"FINISHED"}  # no window: plain
    maps = lm.read_exr(tmp_path / "Floor.exr")
    assert set(maps) == {"flat", "b0", "b1", "b2", "ao", "coverage"} and maps["flat"].shape == (8, 8, 3)


class Layout:
    """Records what a panel's draw() asks for (no UI in background mode)."""

    def __init__(self):
        self.items = []
        self.use_property_split = False

    def prop(self, data, name, **_):
        self.items.append(("prop", name))

    def operator(self, idname, **_):
        self.items.append(("operator", idname))

    def label(self, text="", icon="NONE"):
        self.items.append(("label", text))


def test_panel_shows_settings_warnings_and_buttons(scene):
    import types

    from addon.lightmap_panel import HEMISHADOW_PT_lightmaps

    floor = plane()
    bare = plane("Bare", uv=None, location=(10, 0, 0))
    twin = bpy.data.objects.new("Twin", floor.data)
    scene.collection.objects.link(twin)

    def draw(selected):
        panel = types.SimpleNamespace(layout=Layout())
        HEMISHADOW_PT_lightmaps.draw(panel, types.SimpleNamespace(scene=scene, selected_objects=selected))
        return panel.layout.items

    items = draw([floor, bare])
    props = [name for kind, name in items if kind == "prop"]
    assert props == ["source", "layout", "atlas_name", "uv_name", "size_mode", "resolution", "basis", "bounces", "samples",
                     "adaptive", "margin", "directory"]
    assert ("label", "No 'lightmap' UV map (Lightmap Pack in the atlas): Bare") in items  # two objects: an atlas
    scene.hemishadow_lightmaps.layout = "OBJECT"
    assert ("label", "No 'lightmap' UV map: Bare") in draw([floor, bare])
    assert ("prop", "atlas_name") not in draw([floor, bare])
    assert ("label", "Shared meshes: Floor") in items and ("operator", "hemishadow.lightmap_single_user") in items
    for idname in ("hemishadow.make_lightmap_uv", "hemishadow.bake_lightmaps", "hemishadow.add_lightmap_nodes"):
        assert ("operator", idname) in items
    scene.hemishadow_lightmaps.size_mode = "DENSITY"
    scene.hemishadow_lightmaps.source = "COLLECTION"
    items = draw([])
    assert ("prop", "texel_density") in items and ("prop", "collection") in items
    assert ("label", "0 mesh object(s)") in items


def test_add_to_materials_adds_and_removes_nothing(scene, tmp_path):
    floor = plane()
    mat = new_material("Paint")
    floor.data.materials.append(mat)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.5, 0.25, 1.0, 1.0)
    old_nodes = {n.name for n in mat.node_tree.nodes}
    old_links = {(l.from_node.name, l.to_node.name) for l in mat.node_tree.links}
    lightmaps.bake_lightmaps(scene, [floor], resolution=8, bounces=0, out_dir=str(tmp_path))
    floor.select_set(True)
    assert bpy.ops.hemishadow.add_lightmap_nodes() == {"FINISHED"}
    tree = mat.node_tree
    assert old_nodes < {n.name for n in tree.nodes}
    assert old_links <= {(l.from_node.name, l.to_node.name) for l in tree.links}
    group = next(n for n in tree.nodes if n.type == "GROUP")
    assert group.node_tree.name == lightmap_nodes.GROUP_NAME
    images = {n.image.name for n in tree.nodes if n.type == "TEX_IMAGE"}
    assert images == {f"hemishadow_Floor_{m}" for m in ("b0", "b1", "b2", "flat")}
    active = [n for n in tree.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output]
    assert [n.name for n in active] == ["Hemishadow Lightmap Output"]
    assert bpy.ops.hemishadow.add_lightmap_nodes() == {"FINISHED"}  # a second click adds nothing
    assert sum(n.type == "GROUP" for n in tree.nodes) == 1
    lightmaps.bake_lightmaps(scene, [floor], resolution=16, bounces=0, out_dir=str(tmp_path))  # a new size
    textures = [n for n in tree.nodes if n.type == "TEX_IMAGE"]
    assert {(n.image.name, tuple(n.image.size)) for n in textures} == {
        (f"hemishadow_Floor_{m}", (16, 16)) for m in ("b0", "b1", "b2", "flat")}


def render_centre(scene, path):
    bpy.ops.object.camera_add(location=(0, 0, 3))
    scene.camera = bpy.context.active_object
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 1
    scene.render.resolution_x = scene.render.resolution_y = 8
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    from hemishadow.environment import read_exr

    return read_exr(path)[4, 4]


@pytest.mark.parametrize("normal_map", [False, True])
def test_added_material_renders_base_color_times_lightmap(scene, tmp_path, normal_map):
    """Cycles renders what Add to Materials made: Base Color x flat (1.0 under a white sky)
    without a normal map; with one, the HL2 combination (every b_i is 0.7887 here)."""
    floor = plane(size=2.0)
    mat = new_material("Paint")
    floor.data.materials.append(mat)
    tree = mat.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    base = np.array([0.5, 0.25, 1.0])
    bsdf.inputs["Base Color"].default_value = (*base, 1.0)
    if normal_map:
        rgb = tree.nodes.new("ShaderNodeRGB")
        rgb.outputs[0].default_value = (0.6, 0.45, 0.95, 1.0)
        normal = tree.nodes.new("ShaderNodeNormalMap")
        tree.links.new(rgb.outputs[0], normal.inputs["Color"])
        tree.links.new(normal.outputs["Normal"], bsdf.inputs["Normal"])
    lightmaps.bake_lightmaps(scene, [floor], resolution=8, bounces=0, out_dir=str(tmp_path))
    assert lightmap_nodes.add_to_objects(scene, [floor], "lightmap") == (["Paint"], [])
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    pixel = render_centre(scene, tmp_path / "show.exr")
    expected = base * (FLAT_B if normal_map else 1.0)
    assert np.abs(pixel - expected).max() < 0.015, (pixel, expected)  # the film's 1 % (test_lightmaps.py)


def test_add_to_materials_warns_on_a_material_shared_with_others(scene, tmp_path):
    floor, other = plane(), plane("Other", location=(10, 0, 0))
    mat = new_material("Shared")
    floor.data.materials.append(mat)
    other.data.materials.append(mat)
    lightmaps.bake_lightmaps(scene, [floor], resolution=8, bounces=0, out_dir=str(tmp_path))
    count = len(mat.node_tree.nodes)
    added, warnings = lightmap_nodes.add_to_objects(scene, [floor], "lightmap")
    assert added == [] and len(mat.node_tree.nodes) == count
    assert warnings == ["Floor: material 'Shared' is shared with Other: left as it is (give the object its own "
                        "copy of the material)"]


def test_add_to_materials_before_baking_names_the_object(scene):
    floor = plane()
    floor.data.materials.append(new_material("Paint"))
    before = len(bpy.data.materials["Paint"].node_tree.nodes)
    with pytest.raises(ValueError, match="Floor: no baked lightmap images"):
        lightmap_nodes.add_to_objects(scene, [floor], "lightmap")
    assert len(bpy.data.materials["Paint"].node_tree.nodes) == before


# -- 3. texel density ------------------------------------------------------------------------------

def test_texel_density_sets_the_resolution_from_the_area(scene, tmp_path):
    assert lightmaps.density_resolution(16.0, 1.0, 8.0) == 32          # 4 m x 8 texels per metre
    assert lightmaps.density_resolution(16.0, 0.25, 8.0) == 64         # islands on a quarter of the square
    assert lightmaps.density_resolution(16.0, 1.0, 4.6) == 20          # 18.4 -> nearest multiple of 4
    assert lightmaps.density_resolution(16.0, 1.0, 1e6) == lightmaps.MAX_RESOLUTION
    assert lightmaps.density_resolution(1e-6, 1.0, 8.0) == lightmaps.MIN_RESOLUTION
    floor = plane()
    floor.scale = (2, 1, 1)  # world area 32 m^2
    small = plane("Small", size=1.0, location=(10, 0, 0))
    from addon import cli

    assert cli.main(["lightmaps", "--objects", "Floor", "Small", "--texel-density", "8", "--bounces", "0",
                     "--basis", "flat", "--per-object", "--out", str(tmp_path)]) == 0
    assert lm.read_exr(tmp_path / "Floor.exr")["flat"].shape == (44, 44, 3)  # 8 sqrt(32) = 45.3 -> 44
    assert lm.read_exr(tmp_path / "Small.exr")["flat"].shape == (8, 8, 3)
    assert cli.main(["lightmaps", "--objects", "Floor", "--texel-density", "8", "--resolution", "8",
                     "--out", str(tmp_path)]) == 2


# -- 4. albedo from the material -------------------------------------------------------------------

def textured(obj, image):
    mat = new_material("Textured")
    obj.data.materials.append(mat)
    tree = mat.node_tree
    texture = tree.nodes.new("ShaderNodeTexImage")
    texture.image = image
    tree.links.new(texture.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    return mat


def test_albedo_from_base_color_value_and_texture(scene):
    floor = plane()
    mat = new_material("Value")
    mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.1, 0.2, 0.3, 1.0)
    floor.data.materials.append(mat)
    assert np.allclose(lightmap_albedo.base_color(floor, floor.data), (0.1, 0.2, 0.3))
    # a texture: left half red, right half blue (float, linear); the plane's 4 corners sit on
    # texel corners, so each vertex averages its column of the image, wrapped (Repeat)
    image = bpy.data.images.new("Halves", 4, 4, float_buffer=True)
    pixels = np.zeros((4, 4, 4), np.float32)
    pixels[:, :2] = (1, 0, 0, 1)
    pixels[:, 2:] = (0, 0, 1, 1)
    image.pixels.foreach_set(pixels.ravel())
    other = plane("Textured", location=(10, 0, 0))
    textured(other, image)
    albedo = lightmap_albedo.base_color(other, other.data)
    assert albedo.shape == (4, 3) and np.allclose(albedo, (0.5, 0, 0.5))  # u = 0 and 1 wrap to both halves
    image.pixels.foreach_set(np.tile(np.float32([0.25, 0.5, 0.75, 1]), 16))
    image.update()
    assert np.allclose(lightmap_albedo.base_color(other, other.data), (0.25, 0.5, 0.75), atol=1e-6)
    byte = bpy.data.images.new("Grey", 2, 2)  # 8-bit sRGB: 0.5 stored is 0.214 linear
    byte.pixels.foreach_set(np.full(16, 0.5, np.float32))
    other.active_material.node_tree.nodes["Image Texture"].image = byte
    assert np.allclose(lightmap_albedo.base_color(other, other.data), 0.2140, atol=3e-3)


def test_texture_albedo_reaches_the_bounce(scene, tmp_path):
    """A floor under a wall textured black reflects no light onto it; the same wall's Base
    Color value (0.8, unused while the texture feeds it) would. The wall's bounce shows."""
    floor = plane(size=2.0)
    wall = plane("Wall", size=2.0, uv=None, location=(0, 0, 1.0))
    wall.rotation_euler = (math.pi, 0, 0)  # facing down, at 1 m: it blocks the sky and reflects the floor
    black = bpy.data.images.new("Black", 2, 2, float_buffer=True)
    black.pixels.foreach_set(np.tile(np.float32([0, 0, 0, 1]), 4))
    bpy.ops.object.light_add(type="SUN")
    bpy.context.active_object.data.energy = 3.0
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    prepared = lightmaps.prepare(scene, [floor], resolution=8, bounces=1)
    assert np.allclose(prepared.surfaces[0].albedo, 0.8)
    textured(wall, black)
    prepared = lightmaps.prepare(scene, [floor], resolution=8, bounces=1)
    wall_surface = prepared.surfaces[0]  # subdivided for bounce light: per vertex, all black
    assert wall_surface.albedo.shape == (len(wall_surface.vertices), 3) and np.abs(wall_surface.albedo).max() == 0


def test_missing_texture_warns_naming_object_and_image(scene):
    floor = plane()
    image = bpy.data.images.new("brick.png", 4, 4)
    image.source, image.filepath = "FILE", "/nonexistent/brick.png"  # as a .blend whose texture moved
    textured(floor, image)
    with pytest.warns(RuntimeWarning, match=r"Floor: image 'brick.png' \(/nonexistent/brick.png\) cannot be read"):
        albedo = lightmap_albedo.base_color(floor, floor.data)
    assert np.allclose(albedo, 0.8)


# -- 5. shared meshes ------------------------------------------------------------------------------

def test_shared_mesh_warns_and_single_user_only_when_asked(scene, tmp_path):
    floor = plane()
    twin = bpy.data.objects.new("Twin", floor.data)
    scene.collection.objects.link(twin)
    twin.location = (10, 0, 0)
    with pytest.warns(RuntimeWarning, match="Floor: its mesh 'Plane' is shared with 'Twin'"):
        lightmaps.bake_lightmaps(scene, [floor], resolution=8, bounces=0, out_dir=str(tmp_path))
    assert floor.data == twin.data  # never made single-user unasked
    bpy.ops.object.select_all(action="DESELECT")
    floor.select_set(True)
    assert bpy.ops.hemishadow.lightmap_single_user() == {"FINISHED"}
    assert floor.data != twin.data and twin.data.name == "Plane"
    assert [u.name for u in floor.data.uv_layers] == ["UVMap", "lightmap"]
    assert lightmaps.shared_meshes(scene, [floor]) == {}


# -- 6. bad input: clear messages, nothing written, user data unchanged --------------------------

def _refused(scene, objects, tmp_path, match, **settings):
    before = snapshot()
    with pytest.raises(ValueError, match=match):
        lightmap_job.LightmapBake(scene, objects, out_dir=str(tmp_path), **settings)
    assert list(tmp_path.iterdir()) == [] and snapshot() == before


def test_bad_input_is_refused_before_anything_is_written(scene, tmp_path):
    floor = plane()
    mesh = bpy.data.meshes.new("Points")
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [], [])
    points = bpy.data.objects.new("Points", mesh)
    scene.collection.objects.link(points)
    _refused(scene, [floor, points], tmp_path, "Points: no UV map named 'lightmap'", layout="OBJECT")
    _refused(scene, [floor, points], tmp_path, "Points: the mesh has no faces")  # atlas: before any UV map is made
    mesh.uv_layers.new(name="lightmap")
    _refused(scene, [floor, points], tmp_path, "Points: the mesh has no faces", layout="OBJECT")
    _refused(scene, [floor, points], tmp_path, "layout must be one of", layout="GRID")
    _refused(scene, [plane("Bare", uv=None, location=(10, 0, 0))], tmp_path, "Bare: no UV map named 'lightmap'")
    _refused(scene, [floor], tmp_path, "resolution must be at least 1 texel, got 0", resolution=0)
    _refused(scene, [], tmp_path, "no objects to bake")
    bpy.ops.object.camera_add()
    _refused(scene, [bpy.context.active_object], tmp_path, "Camera: only mesh objects can have lightmaps")


def test_overlapping_islands_warn_naming_the_object(scene, tmp_path):
    mesh = bpy.data.meshes.new("Folded")  # two quads side by side, both on the whole UV square
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (2, 1, 0)], [],
                     [(0, 1, 2, 3), (1, 4, 5, 2)])
    layer = mesh.uv_layers.new(name="lightmap")
    layer.uv.foreach_set("vector", np.tile(np.float32([0, 0, 1, 0, 1, 1, 0, 1]), 2))
    folded = bpy.data.objects.new("Folded", mesh)
    scene.collection.objects.link(folded)
    job = lightmap_job.LightmapBake(scene, [folded], out_dir=str(tmp_path), resolution=8, bounces=0).start()
    assert run(job)[0] == lightmap_job.FINISHED
    assert any(w.startswith("Folded: its lightmap UV islands overlap") for w in job.warnings), job.warnings
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Folded.exr"]  # a warning, not an error
