"""Invalid probes: inside walls or objects, where most of what a probe sees are back faces.

A probe is invalid when `Scene.valid` rejects at least 3 of its 6 hemispheres (back faces
over more than half of each; asked only where a mask is more than 45 % blocked, as the
lightmap baker does). An invalid probe with a cell size moves to the nearest valid position
among offsets of a quarter and half a cell towards its 26 neighbours (within half a cell on
every axis, nearest first); where none is valid it stays, marked invalid.
"""

import itertools

import numpy as np

from ..lightmap.bake import hemisphere_valid
from . import capture
from .cube import AXES

MIN_BAD_HEMISPHERES = 3
_STEPS = (0.25, 0.5)


def check(scene, points, masks, offset=None):
    """bool (P,): True for valid probes, given their six masks (6, P, 16). Hemispheres are
    asked in turn and a probe stops being asked once decided (3 bad, or 4 good): inside dense
    geometry `Scene.valid` costs about a millisecond a query."""
    bad = np.zeros(len(points), np.int64)
    good = np.zeros(len(points), np.int64)
    for j in range(6):
        todo = np.flatnonzero((bad < MIN_BAD_HEMISPHERES) & (good <= 6 - MIN_BAD_HEMISPHERES))
        if not len(todo):
            break
        normals = np.broadcast_to(AXES[j], (len(todo), 3))
        ok = hemisphere_valid(scene, points[todo], normals, masks[j][todo], offset)
        bad[todo] += ~ok
        good[todo] += ok
    return bad < MIN_BAD_HEMISPHERES


def _offsets(cell):
    """Candidate offsets (S, 3) in world units, nearest first: the 26 directions to a cell's
    neighbours, a quarter and half a cell (in index units) along each."""
    directions = np.array([o for o in itertools.product((-1, 0, 1), repeat=3) if any(o)], dtype=np.float64)
    steps = np.concatenate([directions * s for s in _STEPS])
    world = steps @ np.asarray(cell, np.float64).T
    return world[np.argsort(np.linalg.norm(world, axis=1), kind="stable")]


def relocate(scene, points, valid, cell, offset=None):
    """New positions (P, 3) and a bool (P,) of probes moved; invalid probes try the candidate
    offsets, in groups of equal distance, nearest first. cell: (3, 3), columns = world step
    of one grid index along x, y, z."""
    points = points.copy()
    moved = np.zeros(len(points), bool)
    todo = np.flatnonzero(~valid)
    if not len(todo):
        return points, moved
    offsets = _offsets(cell)
    lengths = np.round(np.linalg.norm(offsets, axis=1), 9)
    for length in np.unique(lengths):
        if not len(todo):
            break
        shell = offsets[lengths == length]
        trial = (points[todo][:, None] + shell[None]).reshape(-1, 3)
        ok = check(scene, trial, capture.masks(scene, trial, offset), offset).reshape(len(todo), len(shell))
        found = ok.any(axis=1)
        first = np.argmax(ok, axis=1)
        points[todo[found]] += shell[first[found]]
        moved[todo[found]] = True
        todo = todo[~found]
    return points, moved
