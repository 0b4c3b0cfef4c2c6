"""The lightmap atlas in Blender (issue 11): several objects baked into one image through the
baker's UV map `hemishadow_lightmap` (islands packed by Blender's packer at one texel
density), the user's UV maps untouched, the per-object option, the CLI and the materials."""

import math
import pathlib
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import hemishadow.lightmap as lm  # noqa: E402
from hemishadow.lightmap import seams, texels  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
import addon  # noqa: E402
from addon import lightmap_atlas, lightmap_nodes, lightmaps, world  # noqa: E402
from lightmap_scenes import white_world  # noqa: E402

ATLAS_UV = lightmap_atlas.ATLAS_UV


@pytest.fixture
def scene():
    scene = white_world(world)
    addon.register()  # last: a failed set-up must not leave it registered
    yield scene
    addon.unregister()


def plane(name, size, location, uv="lightmap"):
    bpy.ops.mesh.primitive_plane_add(size=size, location=location)
    obj = bpy.context.active_object
    obj.name = obj.data.name = name
    if uv:
        obj.data.uv_layers.new(name=uv)  # a copy of UVMap: the unit square
    return obj


def user_uvs():
    """Every UV map but the baker's, with which one is active and which renders."""
    out = {}
    for mesh in bpy.data.meshes:
        for layer in mesh.uv_layers:
            if layer.name != ATLAS_UV:
                data = np.empty(2 * len(mesh.loops), np.float32)
                layer.uv.foreach_get("vector", data)
                out[(mesh.name, layer.name)] = (data, layer.active, layer.active_render)
    return out


def same_uvs(a, b):
    return a.keys() == b.keys() and all(np.array_equal(a[k][0], b[k][0]) and a[k][1:] == b[k][1:] for k in a)


def atlas_uvs(obj):
    data = lightmaps.read_mesh(obj, bpy.context.evaluated_depsgraph_get(), ATLAS_UV)
    return data, np.array(obj.matrix_world, np.float64)


def test_atlas_packs_every_object_at_one_texel_density(scene, tmp_path):
    big = plane("Big", 4.0, (0, 0, 0))
    small = plane("Small", 2.0, (5, 0, 0), uv=None)              # no 'lightmap': Lightmap Pack
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 5, 0.5))
    box = bpy.context.active_object
    box.name = "Box"
    lightmaps.make_lightmap_uv(box)                               # six islands in 'lightmap'
    before = user_uvs()
    written = lightmaps.bake_lightmaps(scene, [big, small, box], texel_density=8.0, bounces=0, basis="flat",
                                       out_dir=str(tmp_path))
    assert written == {"atlas": str(tmp_path / "atlas.exr")}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["atlas.exr"]
    assert same_uvs(before, user_uvs())                          # the user's UV maps, active and render
    for obj in (big, small, box):
        assert ATLAS_UV in obj.data.uv_layers
    maps = lm.read_exr(tmp_path / "atlas.exr")
    r = maps["flat"].shape[0]
    image = bpy.data.images["hemishadow_atlas_flat"]
    assert list(image[lightmap_atlas.OBJECTS_KEY]) == ["Big", "Small", "Box"]
    islands, density = [], []
    for obj in (big, small, box):
        data, matrix = atlas_uvs(obj)
        tx = texels.rasterize(data.uv, r, 4)
        assert tx.overlapping == 0, obj.name
        grown = np.pad(tx.island, 1)                             # one texel more: bilinear reads
        grown = grown[:-2, 1:-1] | grown[2:, 1:-1] | grown[1:-1, :-2] | grown[1:-1, 2:] | tx.island
        islands.append(grown)
        area, uv_area = lightmaps.surface_areas(data, matrix)
        density.append(r * math.sqrt(uv_area / area))
    count = np.sum(islands, axis=0)
    assert count.max() == 1                                       # no texel is read by two objects
    print(r, density)
    assert max(density) / min(density) < 1.02                    # one texel density across objects
    assert all(abs(d / 8.0 - 1) < 0.1 for d in density)          # the one asked for (R a multiple of 4)


def remapped(atlas, alone, obj):
    """The alone map (its 'lightmap' UVs) read bilinearly at the atlas's covered texel centres
    of `obj` (through their point on the surface): (atlas values, alone values)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    own = lightmaps.read_mesh(obj, depsgraph, "lightmap").uv
    packed = lightmaps.read_mesh(obj, depsgraph, ATLAS_UV).uv
    r, ra = atlas.shape[0], alone.shape[0]
    tri = texels.texel_space(packed, r)
    rows, cols = np.mgrid[0:r, 0:r]
    centres = np.stack([cols.ravel() + 0.5, rows.ravel() + 0.5], axis=1)
    got, want = [], []
    for k in range(len(tri)):
        w = texels.barycentric(np.repeat(tri[k][None], len(centres), 0), centres)
        inside = (w >= 1e-6).all(axis=1)
        points = texels.texel_space((w[inside, :, None] * own[k][None]).sum(1), ra)
        got.append(atlas.reshape(-1, atlas.shape[2])[inside])
        want.append(seams.lookup(alone, points))
    return np.concatenate(got), np.concatenate(want)


def test_atlas_reads_what_each_object_baked_alone_reads(scene, tmp_path):
    """Two planes, one under a floating box (a soft shadow), baked into the atlas and each
    alone at the same texel density: the alone maps, remapped through the slots, agree with
    the atlas to 2.5 % of the open sky (texel centres fall elsewhere in the two layouts, and a
    texel's sky light is a mean over its neighbours', lightmap/tilts.py)."""
    big = plane("Big", 4.0, (0, 0, 0))
    small = plane("Small", 2.0, (5, 0, 0))
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 0.8))
    kwargs = dict(texel_density=8.0, bounces=1, basis="hl2", samples=4)
    atlas = lm.read_exr(lightmaps.bake_lightmaps(scene, [big, small], out_dir=str(tmp_path / "a"), **kwargs)["atlas"])
    alone = lightmaps.bake_lightmaps(scene, [big, small], layout="OBJECT", out_dir=str(tmp_path / "o"), **kwargs)
    worst = {}
    for obj in (big, small):
        maps = lm.read_exr(alone[obj.name])
        for name in ("flat", "b0", "b1", "b2"):
            got, want = remapped(atlas[name], maps[name], obj)
            assert len(got) > 100
            worst[(obj.name, name)] = np.abs(got - want).max()
    print(worst)
    assert max(worst.values()) < 0.025
    dark = lm.read_exr(alone["Big"])["flat"].min()
    assert dark < 0.8                                             # the shadow is there to be matched


def test_per_object_option_and_the_cli(scene, tmp_path):
    from addon import cli

    plane("Big", 4.0, (0, 0, 0))
    plane("Small", 2.0, (5, 0, 0))
    before = user_uvs()
    common = ["--resolution", "16", "--bounces", "0", "--basis", "flat"]
    assert cli.main(["lightmaps", "--objects", "Big", "Small", "--per-object", *common, "--out", str(tmp_path / "p")]) == 0
    assert sorted(p.name for p in (tmp_path / "p").iterdir()) == ["Big.exr", "Small.exr"]
    assert cli.main(["lightmaps", "--objects", "Big", "Small", "--uv", "lightmap", *common,
                     "--out", str(tmp_path / "u")]) == 0                     # --uv: that layout, as it is
    assert sorted(p.name for p in (tmp_path / "u").iterdir()) == ["Big.exr", "Small.exr"]
    assert not any(ATLAS_UV in m.uv_layers for m in bpy.data.meshes)       # no atlas, no atlas UV map
    assert cli.main(["lightmaps", "--objects", "Big", "Small", "--atlas", "Yard", *common,
                     "--out", str(tmp_path / "a")]) == 0
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["Yard.exr"]
    assert lm.read_exr(tmp_path / "a" / "Yard.exr")["flat"].shape == (16, 16, 3)
    assert cli.main(["lightmaps", "--objects", "Big", *common, "--out", str(tmp_path / "one")]) == 0
    assert sorted(p.name for p in (tmp_path / "one").iterdir()) == ["Big.exr"]  # one object: its own UVs
    assert same_uvs(before, user_uvs())


def test_panel_option_and_materials_reading_the_atlas(scene, tmp_path):
    big = plane("Big", 4.0, (0, 0, 0))
    small = plane("Small", 2.0, (5, 0, 0))
    paint = bpy.data.materials.new("Paint")
    if paint.node_tree is None:
        paint.use_nodes = True
    for obj in (big, small):
        obj.data.materials.append(paint)                          # one material: one image to read
    settings = scene.hemishadow_lightmaps
    assert settings.layout == "ATLAS"
    settings.resolution, settings.bounces, settings.directory, settings.atlas_name = 16, 0, str(tmp_path), "Yard"
    for obj in (big, small):
        obj.select_set(True)
    assert bpy.ops.hemishadow.bake_lightmaps() == {"FINISHED"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Yard.exr"]
    assert bpy.ops.hemishadow.add_lightmap_nodes() == {"FINISHED"}
    tree = paint.node_tree
    uv_nodes = [n for n in tree.nodes if n.type == "UVMAP"]
    assert [n.uv_map for n in uv_nodes] == [ATLAS_UV]
    images = {n.image.name for n in tree.nodes if n.type == "TEX_IMAGE"}
    assert images == {f"hemishadow_Yard_{m}" for m in ("flat", "b0", "b1", "b2")}
    settings.layout = "OBJECT"                                    # per object: the newest bake wins
    assert bpy.ops.hemishadow.bake_lightmaps() == {"FINISHED"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Big.exr", "Small.exr", "Yard.exr"]
    images, uv, sharing = lightmap_nodes.lightmap_of(big, "lightmap")
    assert images["flat"].name == "hemishadow_Big_flat" and uv == "lightmap" and sharing == ["Big"]
