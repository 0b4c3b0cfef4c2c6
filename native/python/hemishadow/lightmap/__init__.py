"""Directional lightmaps of a static scene (issue 11), the engine part: texels in, maps out.

    from hemishadow.lightmap import Surface, Target, Sun, bake, write_exr
    maps = bake(scene, [Target(Surface(mesh_id, vertices, triangles, matrix), uv)],
                resolution=256, lighting=L, suns=[Sun((0, 0, 1), 3.0)], bounces=2)[0]
    write_exr("out/plane.exr", maps)

One idea per module: texels (UV rasterization), cells (the mask's hemisphere quadrature),
basis (HL2 frames, L1 SH), light (environment and suns), bounce (gather), dilate (padding,
invalid texels), seams, exr. Units, conventions and what is not done: docs/lightmaps.md.
"""

from .bake import BASES, bake
from .basis import HL2
from .exr import read as read_exr
from .exr import write as write_exr
from .geometry import Surface, Target
from .lamps import Area, Point, Spot
from .light import Sun

__all__ = ["Area", "BASES", "HL2", "Point", "Spot", "Sun", "Surface", "Target", "bake", "read_exr", "write_exr"]
