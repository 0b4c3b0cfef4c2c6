"""The baked lightmaps a probe bake takes its bounce light from (issue 12): a bounce surface
whose object has a hemishadow lightmap shows the probes the radiance that lightmap holds
(`hemishadow.probes.baked`), instead of bounce passes computed again.

A lightmap is found as the lightmap bake leaves it (lightmaps.py): the Blender image
`hemishadow_<object>_flat` read through the UV map the scene's Lightmaps settings name
(default `lightmap`), or its atlas's `hemishadow_<atlas>_flat` through `hemishadow_lightmap`
(whichever is newer, as the materials pick), else the file `<folder>/<object>.exr` (its
`flat` layer; the folder of the Lightmaps settings, default `//lightmaps`). Objects without one,
or without that UV map, are computed as before.
"""

import os

import bpy
import numpy as np

from . import lightmap_nodes, lightmaps


def _settings(scene, name, default):
    return getattr(getattr(scene, "hemishadow_lightmaps", None), name, "") or default


def uv_name(scene):
    return _settings(scene, "uv_name", lightmaps.DEFAULT_UV)


def flat_map(obj, scene):
    """(the object's baked `flat` map (R, R', 3), rows top to bottom, the UV map reading it),
    or (None, None): its own image, or its atlas's through `hemishadow_lightmap`
    (lightmap_nodes.lightmap_of, as the materials read them), else its own EXR."""
    images, uv, _ = lightmap_nodes.lightmap_of(obj, uv_name(scene))
    image = images.get("flat")
    if image is not None and image.size[0] > 0 and image.size[1] > 0:
        w, h = image.size
        pixels = np.empty(w * h * 4, np.float32)
        image.pixels.foreach_get(pixels)
        return pixels.reshape(h, w, 4)[::-1, :, :3], uv  # Blender's rows start at the bottom
    folder = lightmaps.output_folder(_settings(scene, "directory", None))
    path = os.path.join(folder, f"{lightmaps._safe(obj.name)}.exr") if folder else None
    if path and os.path.isfile(path):
        import hemishadow.lightmap as lm

        return lm.read_exr(path).get("flat"), uv_name(scene)
    return None, None


def vertex_light(scene, surfaces, depsgraph=None):
    """{mesh_id: irradiance / pi at the vertices (V, 3)} of the `surfaces` (as
    probes.scene_geometry gives them, named by object) that have a baked lightmap."""
    import hemishadow.probes as hp

    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    out = {}
    for surface in surfaces:
        obj = scene.objects.get(surface.name)
        flat, name = flat_map(obj, scene) if obj is not None else (None, None)
        if flat is None or name not in obj.data.uv_layers:
            continue
        data = lightmaps.read_mesh(obj, depsgraph, name)
        if len(data.triangles) != len(surface.triangles):
            continue  # the mesh changed since `surfaces` was read
        out[surface.mesh_id] = hp.baked.vertex_light(flat, data.uv, data.triangles, len(surface.vertices))
    return out
