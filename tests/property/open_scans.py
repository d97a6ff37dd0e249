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
    add_boxes,
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
    wall_top_m: float = WALL_TOP_M,
) -> Scene:
    """A furnished ``size`` room (2.5 m high) cut to a partial scan: everything above
    ``wall_top_m`` removed, the outer shell dropped, and (``floor_hole``) a ``hole_size_m``
    piece of the floor missing at a seeded place along a wall; ``missing_wall`` also removes
    the wall at the largest x."""
    layout = generate_layout(seed, (*size, 2.5), 1)
    scene = layout.to_scene(f"scannet_like_{seed}")
    scene = keep_faces(scene, ~faces_on_box_planes(scene, building_envelope(layout)))
    low, high = scene.bounds
    boxes = [[[low[0] - 1, low[1] - 1, wall_top_m], [high[0] + 1, high[1] + 1, high[2] + 1]]]
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


#: Floors :func:`real_scan_like` draws.
FLOORS = ("flat", "sloped", "stepped")


def real_scan_like(
    seed: int = 0, size: tuple[float, float] = (3.0, 3.0), wall_top_m: float = 1.3,
    floor: str = "flat", bumps_m: float = 0.0, fragments: int = 0, clutter: int = 0,
    floor_holes: int = 0,
) -> Scene:
    """A partial room scan with the shapes real reconstructions have and
    :func:`scannet_like_scan` lacks (everything seeded).

    Args:
        seed: placement seed.
        size: the room's free interior (metres), 2-4 m a side in a real scan.
        wall_top_m: height the scan's walls end at; real partial scans stop at 1.0-1.6 m,
            at or below the agent's working height.
        floor: ``"flat"``, ``"sloped"`` (the whole scan sheared, rising 8 cm per metre along
            x, as a scan registered a little off level) or ``"stepped"`` (a 0.15-0.25 m
            platform over a third of the floor).
        bumps_m: TSDF-style bumpy surfaces: every surface is cut into triangles of at most
            0.15 m and each corner moved by up to this much (0: smooth); corners are shared,
            so the surface stays closed.
        fragments: disconnected 5-15 cm pieces floating inside and around the room, as a
            TSDF fuses from noise and from surfaces seen through openings.
        clutter: extra furniture-sized boxes reaching the agent's height (0.6-1.1 m).
        floor_holes: small (0.3-0.6 m) holes through the floor where the sensor saw nothing.
    """
    if floor not in FLOORS:
        raise ValueError(f"floor must be one of {FLOORS}, got {floor!r}")
    rng = np.random.default_rng([seed, 46])
    scene = scannet_like_scan(seed, size, floor_hole=False, wall_top_m=wall_top_m)
    low, high = scene.bounds
    boxes = []
    for _ in range(floor_holes):
        extent = rng.uniform(0.3, 0.6, 2)
        corner = rng.uniform(low[:2], high[:2] - extent)
        boxes.append([[*corner, low[2] - 1], [*(corner + extent), low[2] + 0.03]])
    if boxes:
        scene = subtract_boxes(scene, boxes)
    extra = []
    if floor == "stepped":
        width = (high[0] - low[0]) / 3.0
        extra.append([[low[0], low[1], low[2]],
                      [low[0] + width, high[1], low[2] + rng.uniform(0.15, 0.25)]])
    for _ in range(clutter):
        extent = rng.uniform(0.3, 0.6, 2)
        corner = rng.uniform(low[:2] + 0.2, high[:2] - extent - 0.2)
        extra.append([[*corner, low[2]], [*(corner + extent), low[2] + rng.uniform(0.6, 1.1)]])
    for _ in range(fragments):
        piece = rng.uniform(0.05, 0.15)
        centre = rng.uniform(low - [0.5, 0.5, 0.0], high + [0.5, 0.5, 0.4])
        extra.append([centre - piece / 2, centre + piece / 2])
    if extra:
        scene = add_boxes(scene, np.array(extra), (150, 140, 130))
    if bumps_m > 0:
        scene = _bumpy(scene, bumps_m, rng)
    vertices = scene.vertices.copy()
    if floor == "sloped":
        vertices[:, 2] += 0.08 * (vertices[:, 0] - low[0])
    name = f"real_scan_like_{seed}_{floor}"
    return compact(Scene(vertices, scene.faces, scene.corner_colours, name))


def _bumpy(scene: Scene, bumps_m: float, rng: np.random.Generator) -> Scene:
    """``scene`` cut into triangles of at most 0.15 m, each (shared) corner moved by up to
    ``bumps_m`` (texture coordinates are dropped; every triangle keeps its mean colour)."""
    import trimesh

    vertices, faces, index = trimesh.remesh.subdivide_to_size(
        scene.vertices, scene.faces, max_edge=0.15, max_iter=12, return_index=True)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    mesh.merge_vertices()
    colours = scene.corner_colours.mean(axis=1).astype(np.uint8)[index]
    moved = mesh.vertices + rng.uniform(-bumps_m, bumps_m, mesh.vertices.shape)
    return Scene(moved, np.asarray(mesh.faces), np.repeat(colours[:, None], 3, axis=1),
                 scene.name)
