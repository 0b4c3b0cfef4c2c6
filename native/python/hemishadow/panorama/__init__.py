"""Relightable panoramas (issue 13; Wong, Or, Fu 2003): from one viewpoint, every pixel of an
equirectangular panorama stores the SH coefficients of how it responds to light from each
direction, so the panorama can be relit by suns, point lights and environments without the
scene. The contract with the Blender side and the web viewer: notes in docs/panoramas.md.

    hits = primary_hits(scene, origin)          # first surface per pixel (a BVH ray cast)
    pano = bake(scene, origin, bands=4)         # per-pixel transfer x albedo / pi
    pano.save("pano.exr"); pano.save("pano/panorama.json")   # float16 EXR; 8-bit PNG maps
    image = relight(pano, [Sun((0, 0, 1), 3.0), Point((1, 2, 2), 500.0)])
"""

from .bake import bake
from .directions import directions
from .hits import Hits, primary_hits
from .lights import Environment, Point, Sun
from .panorama import Panorama
from .relight import relight

__all__ = ["Environment", "Hits", "Panorama", "Point", "Sun", "bake", "directions", "primary_hits", "relight"]
