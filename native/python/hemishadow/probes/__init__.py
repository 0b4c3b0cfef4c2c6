"""Ambient cubes and SH9 on probe grids (issue 12), the engine part: points in, probes out.

    from hemishadow.probes import bake_grid, volume_matrix, evaluate, write_npz
    probes = bake_grid(scene, volume_matrix(object_matrix, (4, 4, 2)), (4, 4, 2),
                       lighting=L, suns=[Sun((0, 0, 1), 3.0)], lamps=[Point((0, 0, 2), 100.0)],
                       surfaces=[...], bounces=2)
    lit = evaluate(probes, points, normals, blockers=world_triangles)["value"]

One idea per module: grid (Blender's sample placement), capture (six hemispheres per probe;
suns and lamps), cube (sides, n-squared sampling, cube <-> SH), validity (invalid probes,
moving them), baked (bounce light from baked lightmaps), bake, segments (segment
occlusion), evaluate (interpolation without leaks), files.
Units and formulas: docs/probes.md.
"""

from .bake import bake, bake_grid
from .cube import AXES, cube_to_sh, sample, sh_to_cube
from .evaluate import evaluate
from .files import read_npz, to_json, write_json, write_npz, y_up
from .grid import bounds_matrix, grid_points, volume_matrix

__all__ = ["AXES", "bake", "bake_grid", "bounds_matrix", "cube_to_sh", "evaluate", "grid_points", "read_npz",
           "sample", "sh_to_cube", "to_json", "volume_matrix", "write_json", "write_npz", "y_up"]
