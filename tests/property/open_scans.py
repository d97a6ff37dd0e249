"""Partial room scans of the ScanNet kind, built procedurally for the stuck-policy tests.

A ScanNet reconstruction of a room is open: no ceiling (the sensor rarely looked up), walls
captured only up to about 1.3 m, part of the floor missing; rooms are about 3.5 x 3 m. The
scans here are cut from a furnished procedural room the same way, without any stray
fragments, so the mesh's bounds end at the scan.
"""

from __future__ import annotations

import numpy as np

from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.scenes.open_scans import (
    building_envelope,
    faces_on_box_planes,
    keep_faces,
    subtract_boxes,
)
from naruto_gym.scenes.procedural import generate_layout

#: Wall height captured by the scan.
WALL_TOP_M = 1.3


def scannet_like_scan(
    seed: int = 0, size: tuple[float, float] = (3.5, 3.0), floor_hole: bool = True,
    missing_wall: bool = False, hole_size_m: tuple[float, float] = (1.2, 1.0),
) -> Scene:
    """A furnished ``size`` room (2.5 m high) cut to a partial scan: everything above
    ``WALL_TOP_M`` removed, the outer shell dropped, and (``floor_hole``) a ``hole_size_m``
    piece of the floor missing at a seeded place along a wall; ``missing_wall`` also removes
    the wall at the largest x."""
    layout = generate_layout(seed, (*size, 2.5), 1)
    scene = layout.to_scene(f"scannet_like_{seed}")
    scene = keep_faces(scene, ~faces_on_box_planes(scene, building_envelope(layout)))
    low, high = scene.bounds
    boxes = [[[low[0] - 1, low[1] - 1, WALL_TOP_M], [high[0] + 1, high[1] + 1, high[2] + 1]]]
    rng = np.random.default_rng(seed)
    if floor_hole:
        hole_x, hole_y = hole_size_m
        x0 = rng.uniform(low[0] - 0.3, high[0] - hole_x + 0.3)
        y0 = low[1] - 0.5 if rng.random() < 0.5 else high[1] + 0.5 - hole_y
        boxes.append([[x0, y0, low[2] - 1], [x0 + hole_x, y0 + hole_y, low[2] + 0.05]])
    if missing_wall:
        boxes.append([[high[0] - 0.2, low[1] - 1, low[2] - 1], [high[0] + 1, high[1] + 1, 3]])
    return compact(subtract_boxes(scene, boxes, name=scene.name))


def compact(scene: Scene) -> Scene:
    """``scene`` without the vertices no face uses (their bounds are the scan's)."""
    used, faces = np.unique(scene.faces, return_inverse=True)
    return Scene(scene.vertices[used], faces.reshape(-1, 3), scene.corner_colours, scene.name,
                 scene.corner_uvs, scene.face_texture_ids, scene.textures)
