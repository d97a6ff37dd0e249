"""Small synthetic scenes for the planner tests, built from trimesh boxes.

Triangles face free space, as in scans: the room is a box turned inside out (normals into the
room); walls and furniture are solid boxes with outward normals; the hollow box is an
outer box plus an inside-out inner box (a free pocket that nothing can reach).
"""

from __future__ import annotations

import numpy as np
import trimesh

# Room interior: x in [-2, 2], y in [-1.5, 1.5], z in [0, 2.5].
ROOM_MIN = np.array([-2.0, -1.5, 0.0])
ROOM_MAX = np.array([2.0, 1.5, 2.5])
# Internal wall at x = 0 (0.1 m thick) with a doorway 0.6 m wide and 2 m tall at y in +-0.3.
DOOR_HALF_WIDTH = 0.3
DOOR_HEIGHT = 2.0
# A solid cabinet and a hollow closed box, both in the x > 0 half.
SOLID_BOX_CENTRE = np.array([1.2, -0.9, 0.4])
SOLID_BOX_SIZE = np.array([0.6, 0.6, 0.8])
HOLLOW_BOX_CENTRE = np.array([1.2, 0.9, 0.6])
HOLLOW_BOX_OUTER = np.array([0.9, 0.9, 1.2])
HOLLOW_BOX_WALL = 0.1


def box(lower, upper, inward: bool = False) -> trimesh.Trimesh:
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    mesh = trimesh.creation.box(extents=upper - lower)
    mesh.apply_translation((lower + upper) / 2.0)
    if inward:
        mesh.invert()
    return mesh


def room_mesh(doorway: bool = True, furniture: bool = True) -> trimesh.Trimesh:
    parts = [box(ROOM_MIN, ROOM_MAX, inward=True)]
    wall_x = (-0.05, 0.05)
    if doorway:
        parts += [
            box([wall_x[0], ROOM_MIN[1], 0.0], [wall_x[1], -DOOR_HALF_WIDTH, ROOM_MAX[2]]),
            box([wall_x[0], DOOR_HALF_WIDTH, 0.0], [wall_x[1], ROOM_MAX[1], ROOM_MAX[2]]),
            box([wall_x[0], -DOOR_HALF_WIDTH, DOOR_HEIGHT],
                [wall_x[1], DOOR_HALF_WIDTH, ROOM_MAX[2]]),
        ]
    else:
        parts.append(box([wall_x[0], ROOM_MIN[1], 0.0], [wall_x[1], ROOM_MAX[1], ROOM_MAX[2]]))
    if furniture:
        half = SOLID_BOX_SIZE / 2
        parts.append(box(SOLID_BOX_CENTRE - half, SOLID_BOX_CENTRE + half))
        outer = HOLLOW_BOX_OUTER / 2
        inner = outer - HOLLOW_BOX_WALL
        parts.append(box(HOLLOW_BOX_CENTRE - outer, HOLLOW_BOX_CENTRE + outer))
        parts.append(box(HOLLOW_BOX_CENTRE - inner, HOLLOW_BOX_CENTRE + inner, inward=True))
    return trimesh.util.concatenate(parts)


def inside_room(points: np.ndarray) -> np.ndarray:
    return np.all((points > ROOM_MIN) & (points < ROOM_MAX), axis=1)


