"""Small scenes for the panorama tests: a floor, a box, a sphere and a mirrored copy of the
box, as a `scene_reference.WorldScene` (world triangles for Embree) and its engine scene."""

import numpy as np
import trimesh

import scene_reference as sref


def translation(x, y, z, scale=(1.0, 1.0, 1.0)):
    m = np.diag([*scale, 1.0])
    m[:3, 3] = (x, y, z)
    return m


def world_scene(rotation=None):
    """Outward-facing closed meshes around the viewpoint (0, 0, 0); `rotation` (3x3) turns the
    whole scene about the origin."""
    world = sref.WorldScene()
    floor = trimesh.creation.box((8.0, 8.0, 0.2))
    box = trimesh.creation.box((0.8, 0.8, 1.4))
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.6)
    ids = [world.add_mesh(m.vertices, m.faces) for m in (floor, box, ball)]
    placements = [(ids[0], translation(0, 0, -1.1)), (ids[1], translation(1.6, 0.9, -0.3)),
                  (ids[2], translation(-1.4, -1.2, -0.4)),
                  (ids[1], translation(-1.0, 1.8, -0.5, scale=(-1.0, 1.0, 0.6)))]  # mirrored
    turn = np.eye(4)
    if rotation is not None:
        turn[:3, :3] = rotation
    for mesh, m in placements:
        world.add_instance(mesh, turn @ m)
    return world


def engine_scene(hemishadow, rotation=None):
    world = world_scene(rotation)
    return world, world.engine(hemishadow)
