"""The lightmap atlas (issue 11): several objects baked into one image through the baker's own
UV map `hemishadow_lightmap`, which places each object's islands in its own slot.

The islands come from the object's lightmap UV map (by default `lightmap`), copied, or from
Blender's Lightmap Pack where the mesh has none; Blender's own operators then give every
island the same texel density across the objects (`uv.average_islands_scale`) and pack them
together (`uv.pack_islands`), all objects at once in multi-object Edit Mode. Blender's packer
is used rather than one of ours: it is the one users know, handles concave islands and is
kept up to date with Blender. `hemishadow_lightmap` is the baker's layer and is remade on
each atlas bake; the user's UV maps, and which map is active or renders, never change.
"""

import contextlib

import bpy
import numpy as np

ATLAS_UV = "hemishadow_lightmap"
DEFAULT_ATLAS = "atlas"
OBJECTS_KEY = "hemishadow_atlas_objects"  # on the atlas images: the objects they hold


def _uv_of(mesh, name):
    data = np.empty(2 * len(mesh.loops), np.float32)
    mesh.uv_layers[name].uv.foreach_get("vector", data)
    return data


def _layer_states(meshes):
    return {m.name: (m.uv_layers.active.name if m.uv_layers.active else None,
                     next((u.name for u in m.uv_layers if u.active_render), None)) for m in meshes}


def _restore_layers(meshes, states):
    for mesh in meshes:
        active, render = states[mesh.name]
        if active is not None and active in mesh.uv_layers:
            mesh.uv_layers.active = mesh.uv_layers[active]
        if render is not None and render in mesh.uv_layers:
            mesh.uv_layers[render].active_render = True


def _seed(meshes, source_uv):
    """Makes ATLAS_UV the active layer of every mesh holding a copy of `source_uv`; returns
    the meshes without one (they need unwrapping)."""
    bare = []
    for mesh in meshes:
        layer = mesh.uv_layers.get(ATLAS_UV) or mesh.uv_layers.new(name=ATLAS_UV, do_init=False)
        mesh.uv_layers.active = layer
        if source_uv in mesh.uv_layers and source_uv != ATLAS_UV:
            mesh.uv_layers[ATLAS_UV].uv.foreach_set("vector", _uv_of(mesh, source_uv))
        elif source_uv != ATLAS_UV:
            bare.append(mesh)
    return bare


class _EditMode:
    """Multi-object Edit Mode on `objects` with every face selected and UV sync selection on
    (UV operators then act on all faces); selection, active object and modes restored."""

    def __init__(self, objects):
        self.objects = objects

    def __enter__(self):
        layer = bpy.context.view_layer
        self.active, self.selected = layer.objects.active, [o for o in layer.objects if o.select_get()]
        tools = bpy.context.scene.tool_settings
        self.sync = tools.use_uv_select_sync
        if bpy.context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        for o in self.selected:
            o.select_set(False)
        for o in self.objects:
            o.select_set(True)
        layer.objects.active = self.objects[0]
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_all(action="SELECT")
        tools.use_uv_select_sync = True
        return self

    def __exit__(self, *exc):
        bpy.ops.object.mode_set(mode="OBJECT")
        bpy.context.scene.tool_settings.use_uv_select_sync = self.sync
        for o in self.objects:
            o.select_set(False)
        for o in self.selected:
            o.select_set(True)
        bpy.context.view_layer.objects.active = self.active
        return False


@contextlib.contextmanager
def _object_mode():
    """Object Mode for the duration (mesh data is only current there); the user's mode
    (Edit Mode, Sculpt, ...) back afterwards."""
    active = bpy.context.view_layer.objects.active
    mode = active.mode if active is not None else "OBJECT"
    if mode != "OBJECT":
        bpy.ops.object.mode_set(mode="OBJECT")
    try:
        yield
    finally:
        if mode != "OBJECT" and bpy.context.view_layer.objects.active == active:
            bpy.ops.object.mode_set(mode=mode)


def _unique_meshes(objects):
    seen, out = set(), []
    for obj in objects:
        if obj.data.name not in seen:
            seen.add(obj.data.name)
            out.append(obj)
    return out


def layout(objects, source_uv, margin):
    """Remakes ATLAS_UV on the objects' meshes: their `source_uv` islands (Lightmap Pack where
    a mesh has none) at one texel density, packed into the unit square with `margin` (a
    fraction of the square) between islands. Returns nothing; only ATLAS_UV changes."""
    owners = _unique_meshes(objects)
    meshes = [o.data for o in owners]
    with _object_mode():
        _layout(owners, meshes, source_uv, margin)


def _layout(owners, meshes, source_uv, margin):
    states = _layer_states(meshes)
    try:
        bare = _seed(meshes, source_uv)
        if bare:
            with _EditMode([o for o in owners if o.data in bare]):
                bpy.ops.uv.lightmap_pack(PREF_CONTEXT="ALL_FACES", PREF_MARGIN_DIV=0.05)
        with _EditMode(owners):
            bpy.ops.uv.average_islands_scale()
            bpy.ops.uv.pack_islands(rotate=True, rotate_method="CARDINAL", scale=True, margin_method="FRACTION",
                                    margin=float(margin), shape_method="CONCAVE")
    finally:
        _restore_layers(meshes, states)


MAX_MARGIN = 0.2  # Blender's packer gives up (islands outside the square) near 0.375


def margin_fraction(resolution, margin_texels):
    """Blender's FRACTION margin (space around each island and at the border, so twice it
    between islands) for `margin_texels` of padding plus one texel, so that padding and
    bilinear reads stay with their own object; capped for tiny atlases (the bake still keeps
    each object's padding off the others' islands)."""
    return min((int(margin_texels) + 1) / float(resolution), MAX_MARGIN)


def atlas_name(name):
    return name or DEFAULT_ATLAS
