"""Invalid probes: inside walls or objects, where most of what a probe sees are back faces.

A probe is invalid when the nearest blockers of more than half of its sphere show their
backs: the mean over its +Z and -Z hemispheres of the fraction of cells that do
(`capture.views`, from the walks of its gather; each cell is an equal share of its disk).
An invalid probe with a cell size moves to the nearest valid position
among offsets of a quarter and half a cell towards its 26 neighbours (within half a cell on
every axis, nearest first); where none is valid it stays, marked invalid.
"""

import itertools

import numpy as np

from .. import _native
from . import capture

BACK_FACE_LIMIT = _native.BACK_FACE_LIMIT  # of the sphere, as `Scene.valid` allows of a hemisphere
_STEPS = (0.25, 0.5)


def check(back):
    """bool (P,): True for valid probes, given the back-face fractions (2, P) of their +Z and
    -Z hemispheres (`capture.views`)."""
    return back.mean(axis=0) <= BACK_FACE_LIMIT


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
        ok = check(capture.views(scene, trial, offset, sides=False).back).reshape(len(todo), len(shell))
        found = ok.any(axis=1)
        first = np.argmax(ok, axis=1)
        points[todo[found]] += shell[first[found]]
        moved[todo[found]] = True
        todo = todo[~found]
    return points, moved
