"""Open scans made from closed scenes: no ceiling, holes in floor and walls, a missing wall.

Real reconstructions (ScanNet, Replica, MP3D, HM3D, Gibson) are rarely closed: the ceiling is
often missing, the floor has holes where the sensor saw nothing, and partial scans lack whole
walls. The project ships no real scans, so it makes such scans from its procedural scenes:

* :func:`subtract_boxes` removes the parts of a mesh's triangles that lie inside axis-aligned
  boxes, clipping the triangles exactly at the box faces (colours and texture coordinates are
  interpolated at the new corners), so holes have straight edges and the rest of the mesh is
  untouched. It works on any :class:`~naruto_gym.scenes.mesh_scene.Scene`.
* :func:`open_scan_variant` cuts a procedural layout's scene into an open scan. Openings:

  - ``no_ceiling``: the ceiling slab, the ceiling lights and the wall tops are removed (all
    surface above ``height - 0.03`` m);
  - ``floor_hole``: a 1.4 x 1.4 m hole through the floor (tiles, rug and slab) in the first room;
  - ``wall_holes``: two 1.0 x 0.9 m window-like holes through two exterior walls;
  - ``missing_wall``: one exterior wall removed over its whole length and height;
  - ``holes``: short for ``floor_hole+wall_holes``;
  - ``fragments``: nothing cut: the closed scene as a scan, the reference for the others.

  Every variant is a scan, not a solid model: the building's outer shell (the outer faces of
  the exterior walls and the slabs' outer faces, which no camera inside could capture) is
  dropped, so walls and floor are single surfaces, as in a reconstruction. Every variant also
  gets six small stray fragments 1.2 m outside the building (above, below and on each side),
  as real scans get from surfaces seen through windows and doors: they widen the mesh's
  bounds, so that leaving the scanned space is possible within the bounds and the env's
  escape rule is what must stop it. ``NAME:fragments`` has the same bounds as the open
  variants of ``NAME`` (so the env draws the same start poses) and differs from them only by
  the openings.

Placement is seeded and deterministic (``numpy.random.default_rng``). The shipped catalogue
meshes are never changed: variants are built in memory, and ``resolve_scene`` accepts them as
``"NAME:OPENINGS"``, e.g. ``"replica_like_room:no_ceiling+holes"``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.scenes.procedural import FLOOR_THICKNESS_M, SceneLayout

OPENINGS = ("no_ceiling", "floor_hole", "wall_holes", "missing_wall")
ALIASES: dict[str, tuple[str, ...]] = {"holes": ("floor_hole", "wall_holes"), "fragments": ()}

CEILING_CUT_BELOW_M = 0.03
FLOOR_HOLE_SIZE_M = 1.4
WALL_HOLE_SIZE_M = (1.0, 0.9)  # width along the wall, height
FRAGMENT_SIZE_M = 0.2
FRAGMENT_DISTANCE_M = 1.2
_FRAGMENT_RGB = (128, 124, 118)
_PLANE_EPS = 1e-9


# ---------------------------------------------------------------------------------------
# Exact subtraction of boxes from a triangle mesh
# ---------------------------------------------------------------------------------------
def _clip_polygon(
    points: np.ndarray, weights: np.ndarray, distance: np.ndarray, keep_positive: bool
) -> tuple[np.ndarray, np.ndarray]:
    """The part of a convex polygon on one side of a plane (Sutherland-Hodgman, one plane).

    ``weights`` are the corners' barycentric coordinates in the original triangle; they are
    interpolated with the positions.
    """
    side = distance > _PLANE_EPS if keep_positive else distance <= _PLANE_EPS
    if side.all():
        return points, weights
    if not side.any():
        return points[:0], weights[:0]
    out_points, out_weights = [], []
    count = len(points)
    for index in range(count):
        following = (index + 1) % count
        if side[index]:
            out_points.append(points[index])
            out_weights.append(weights[index])
        if side[index] != side[following]:
            t = distance[index] / (distance[index] - distance[following])
            out_points.append(points[index] + t * (points[following] - points[index]))
            out_weights.append(weights[index] + t * (weights[following] - weights[index]))
    return np.array(out_points), np.array(out_weights)


def _polygon_minus_box(
    points: np.ndarray, weights: np.ndarray, low: np.ndarray, high: np.ndarray
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Convex pieces of a convex polygon that lie outside an axis-aligned box."""
    pieces = []
    for axis in range(3):
        for sign, bound in ((-1.0, low[axis]), (1.0, high[axis])):
            distance = sign * (points[:, axis] - bound)
            outside = _clip_polygon(points, weights, distance, keep_positive=True)
            if len(outside[0]) >= 3:
                pieces.append(outside)
            points, weights = _clip_polygon(points, weights, distance, keep_positive=False)
            if len(points) < 3:
                return pieces
    return pieces  # what is left lies inside the box and is dropped


def subtract_boxes(
    scene: Scene, boxes: Sequence[Sequence[Sequence[float]]], name: str | None = None
) -> Scene:
    """``scene`` without the surface inside any of the axis-aligned ``boxes``.

    Triangles that cross a box face are clipped exactly; the new corners get interpolated
    colours (and texture coordinates). Triangles away from every box are kept as they are.

    Args:
        scene: the mesh to cut.
        boxes: ``(K, 2, 3)`` boxes as ``[[x0, y0, z0], [x1, y1, z1]]``.
        name: name of the result (default: the scene's name).

    Raises:
        ValueError: a box is malformed or removes every triangle.
    """
    boxes = np.asarray(boxes, np.float64).reshape(-1, 2, 3)
    if np.any(boxes[:, 1] <= boxes[:, 0]):
        raise ValueError(f"every box needs low < high on each axis, got {boxes.tolist()}")
    triangles = scene.vertices[scene.faces]
    low_corner, high_corner = triangles.min(axis=1), triangles.max(axis=1)
    touched = np.zeros(len(triangles), bool)
    for low, high in boxes:
        touched |= np.all(high_corner > low, axis=1) & np.all(low_corner < high, axis=1)

    new_vertices, new_colours, new_uvs, new_texture_ids, kept_faces = [], [], [], [], []
    uvs = scene.corner_uvs
    texture_ids = scene.face_texture_ids
    for face in np.flatnonzero(touched):
        polygons = [(triangles[face], np.eye(3))]
        for low, high in boxes:
            polygons = [
                piece for points, weights in polygons
                for piece in _polygon_minus_box(points, weights, low, high)
            ]
        for points, weights in polygons:
            for k in range(1, len(points) - 1):
                corners = [0, k, k + 1]
                triangle = points[corners]
                if np.linalg.norm(np.cross(triangle[1] - triangle[0], triangle[2] - triangle[0])) \
                        < 1e-12:
                    continue
                corner_weights = weights[corners]
                new_vertices.append(triangle)
                colour = corner_weights @ scene.corner_colours[face].astype(np.float64)
                new_colours.append(np.clip(np.round(colour), 0, 255))
                if uvs is not None:
                    new_uvs.append(corner_weights @ uvs[face].astype(np.float64))
                    new_texture_ids.append(texture_ids[face])
                kept_faces.append(face)

    untouched = np.flatnonzero(~touched)
    count_new = len(new_vertices)
    if len(untouched) + count_new == 0:
        raise ValueError("the boxes remove every triangle of the scene")
    vertices = scene.vertices
    faces = scene.faces[untouched]
    corner_colours = scene.corner_colours[untouched]
    corner_uvs = None if uvs is None else uvs[untouched]
    face_texture_ids = None if texture_ids is None else texture_ids[untouched]
    if count_new:
        base = len(vertices)
        vertices = np.concatenate([vertices, np.concatenate(new_vertices)])
        faces = np.concatenate([faces, base + np.arange(3 * count_new).reshape(-1, 3)])
        corner_colours = np.concatenate(
            [corner_colours, np.array(new_colours, np.float64).astype(np.uint8)]
        )
        if uvs is not None:
            corner_uvs = np.concatenate([corner_uvs, np.array(new_uvs, np.float32)])
            face_texture_ids = np.concatenate(
                [face_texture_ids, np.array(new_texture_ids, np.int32)]
            )
    return Scene(
        vertices=vertices,
        faces=faces,
        corner_colours=corner_colours,
        name=name or scene.name,
        corner_uvs=corner_uvs,
        face_texture_ids=face_texture_ids,
        textures=list(scene.textures),
    )


def keep_faces(scene: Scene, keep: np.ndarray, name: str | None = None) -> Scene:
    """``scene`` with only the triangles where ``keep`` (F,) is True."""
    keep = np.asarray(keep, bool)
    return Scene(
        vertices=scene.vertices,
        faces=scene.faces[keep],
        corner_colours=scene.corner_colours[keep],
        name=name or scene.name,
        corner_uvs=None if scene.corner_uvs is None else scene.corner_uvs[keep],
        face_texture_ids=None if scene.face_texture_ids is None else scene.face_texture_ids[keep],
        textures=list(scene.textures),
    )


def faces_on_box_planes(scene: Scene, box: np.ndarray, tolerance_m: float = 1e-4) -> np.ndarray:
    """(F,) mask of the triangles lying in one of the six face planes of ``box`` ((2, 3))."""
    triangles = scene.vertices[scene.faces]
    on_plane = np.zeros(len(triangles), bool)
    for side in range(2):
        for axis in range(3):
            on_plane |= np.all(np.abs(triangles[:, :, axis] - box[side, axis]) <= tolerance_m, 1)
    return on_plane


def add_boxes(
    scene: Scene, boxes: np.ndarray, rgb: Sequence[int], name: str | None = None
) -> Scene:
    """``scene`` plus closed, outward-facing boxes ``(K, 2, 3)`` of one colour."""
    import trimesh

    parts = [
        trimesh.creation.box(bounds=box) for box in np.asarray(boxes, np.float64).reshape(-1, 2, 3)
    ]
    extra = trimesh.util.concatenate(parts)
    base = len(scene.vertices)
    extra_faces = np.asarray(extra.faces, np.int64)
    colours = np.broadcast_to(np.asarray(rgb, np.uint8), (len(extra_faces), 3, 3))
    corner_uvs = scene.corner_uvs
    texture_ids = scene.face_texture_ids
    if corner_uvs is not None:
        corner_uvs = np.concatenate([corner_uvs, np.zeros((len(extra_faces), 3, 2), np.float32)])
        texture_ids = np.concatenate([texture_ids, np.full(len(extra_faces), -1, np.int32)])
    return Scene(
        vertices=np.concatenate([scene.vertices, np.asarray(extra.vertices, np.float64)]),
        faces=np.concatenate([scene.faces, base + extra_faces]),
        corner_colours=np.concatenate([scene.corner_colours, colours]),
        name=name or scene.name,
        corner_uvs=corner_uvs,
        face_texture_ids=texture_ids,
        textures=list(scene.textures),
    )


# ---------------------------------------------------------------------------------------
# Openings of a procedural layout
# ---------------------------------------------------------------------------------------
def parse_openings(text: str | Sequence[str]) -> tuple[str, ...]:
    """``"no_ceiling+holes"`` (or a sequence of names) to the opening names, in canonical order
    (``"fragments"`` gives none).

    Raises:
        ValueError: an unknown or empty name (the message lists the known ones).
    """
    names = text.split("+") if isinstance(text, str) else list(text)
    expanded: set[str] = set()
    for name in names:
        name = name.strip()
        if name in ALIASES:
            expanded.update(ALIASES[name])
        elif name in OPENINGS:
            expanded.add(name)
        else:
            raise ValueError(
                f"unknown scan opening {name!r}; use {', '.join(OPENINGS)} or "
                f"{', '.join(ALIASES)}, joined by '+' (e.g. 'no_ceiling+holes')"
            )
    return tuple(name for name in OPENINGS if name in expanded)


def building_envelope(layout: SceneLayout) -> np.ndarray:
    """(2, 3) bounds of the closed building: walls' outer faces, floor and ceiling slabs."""
    width, depth, height = layout.size
    t = layout.wall_thickness
    return np.array(
        [[-t, -t, -FLOOR_THICKNESS_M], [width + t, depth + t, height + FLOOR_THICKNESS_M]]
    )


def _exterior_walls(layout: SceneLayout) -> list[tuple[str, int]]:
    """(side, room index) for every exterior wall stretch of every room."""
    width, depth, _ = layout.size
    found = []
    for index, room in enumerate(layout.rooms):
        cell = room.cell
        if cell.x0 < 1e-6:
            found.append(("west", index))
        if cell.x1 > width - 1e-6:
            found.append(("east", index))
        if cell.y0 < 1e-6:
            found.append(("south", index))
        if cell.y1 > depth - 1e-6:
            found.append(("north", index))
    return found


def _wall_box(
    layout: SceneLayout, side: str, lo: float, hi: float, z0: float, z1: float, reach_in: float
) -> list[list[float]]:
    """Box through the exterior wall ``side`` over ``[lo, hi]`` along it and ``[z0, z1]``."""
    width, depth, _ = layout.size
    t = layout.wall_thickness + 0.02
    if side == "west":
        return [[-t, lo, z0], [reach_in, hi, z1]]
    if side == "east":
        return [[width - reach_in, lo, z0], [width + t, hi, z1]]
    if side == "south":
        return [[lo, -t, z0], [hi, reach_in, z1]]
    return [[lo, depth - reach_in, z0], [hi, depth + t, z1]]


def opening_boxes(
    layout: SceneLayout, openings: str | Sequence[str], seed: int = 0
) -> np.ndarray:
    """(K, 2, 3) boxes whose surface :func:`open_scan_variant` removes (seeded placement)."""
    names = parse_openings(openings)
    rng = np.random.default_rng([layout.seed, seed, 11])
    width, depth, height = layout.size
    t = layout.wall_thickness
    margin = t + 0.5
    boxes: list[list[list[float]]] = []
    if "no_ceiling" in names:
        boxes.append([[-margin, -margin, height - CEILING_CUT_BELOW_M],
                      [width + margin, depth + margin, height + 1.0]])
    if "floor_hole" in names:
        inner = layout.rooms[0].interior
        size = min(FLOOR_HOLE_SIZE_M, inner.width - 0.8, inner.depth - 0.8)
        x0 = inner.x0 + 0.4 + rng.random() * (inner.width - 0.8 - size)
        y0 = inner.y0 + 0.4 + rng.random() * (inner.depth - 0.8 - size)
        boxes.append([[x0, y0, -2.0 * FLOOR_THICKNESS_M], [x0 + size, y0 + size, 0.02]])
    walls = _exterior_walls(layout)
    order = [walls[i] for i in rng.permutation(len(walls))]
    used_sides: list[str] = []
    if "wall_holes" in names:
        hole_width, hole_height = WALL_HOLE_SIZE_M
        for side, room_index in order:
            if side in used_sides or len(used_sides) == 2:
                continue
            inner = layout.rooms[room_index].interior
            lo, hi = (inner.y0, inner.y1) if side in ("west", "east") else (inner.x0, inner.x1)
            if hi - lo < hole_width + 0.8:
                continue
            start = lo + 0.4 + rng.random() * (hi - lo - 0.8 - hole_width)
            z0 = 0.7 + 0.4 * rng.random()
            boxes.append(_wall_box(layout, side, start, start + hole_width, z0,
                                   min(z0 + hole_height, height - 0.2), reach_in=0.02))
            used_sides.append(side)
    if "missing_wall" in names:
        # A side without a wall hole, so that both openings show.
        side = next(side for side, _ in order if side not in used_sides)
        span = depth if side in ("west", "east") else width
        boxes.append(_wall_box(layout, side, -t - 0.02, span + t + 0.02,
                               -0.004, height + 1.0, reach_in=0.02))
    return np.array(boxes, np.float64).reshape(-1, 2, 3)


def fragment_boxes(layout: SceneLayout, seed: int = 0) -> np.ndarray:
    """(6, 2, 3) small boxes 1.2 m outside the building: above, below and on each side."""
    rng = np.random.default_rng([layout.seed, seed, 12])
    envelope = building_envelope(layout)
    centre = envelope.mean(axis=0)
    half = 0.5 * FRAGMENT_SIZE_M
    d = FRAGMENT_DISTANCE_M + half
    centres = [
        (envelope[0, 0] - d, centre[1], 1.0),
        (envelope[1, 0] + d, centre[1], 1.0),
        (centre[0], envelope[0, 1] - d, 1.0),
        (centre[0], envelope[1, 1] + d, 1.0),
        (centre[0], centre[1], envelope[1, 2] + d),
        (centre[0], centre[1], envelope[0, 2] - d),
    ]
    jitter = rng.uniform(-0.3, 0.3, size=(6, 3)) * np.array([[0, 1, 1], [0, 1, 1], [1, 0, 1],
                                                              [1, 0, 1], [1, 1, 0], [1, 1, 0]])
    points = np.asarray(centres) + jitter
    return np.stack([points - half, points + half], axis=1)


def open_scan_variant(
    layout: SceneLayout,
    openings: str | Sequence[str],
    seed: int = 0,
    scene: Scene | None = None,
    fragments: bool = True,
    shell: bool = False,
    name: str | None = None,
) -> Scene:
    """An open scan made from a procedural layout.

    Args:
        layout: the closed scene's layout (``generate_layout`` / ``random_layout``, or
            ``catalogue_entry(name).layout()``).
        openings: ``"no_ceiling"``, ``"floor_hole"``, ``"wall_holes"``, ``"missing_wall"``,
            ``"holes"``, joined by ``"+"`` (or a sequence of them).
        seed: placement seed of the holes and fragments.
        scene: the layout's mesh when already loaded (default: ``layout.to_scene()``).
        fragments: add the stray fragments outside the building (see the module docstring).
        shell: keep the building's outer shell (default: dropped, as a scan has none).
        name: name of the result (default ``"<scene name>:<openings>"``).
    """
    names = parse_openings(openings)
    base = scene if scene is not None else layout.to_scene()
    label = name or f"{base.name}:{'+'.join(names) or 'fragments'}"
    if not shell:
        base = keep_faces(base, ~faces_on_box_planes(base, building_envelope(layout)))
    cut = subtract_boxes(base, opening_boxes(layout, names, seed), name=label)
    if fragments:
        cut = add_boxes(cut, fragment_boxes(layout, seed), _FRAGMENT_RGB, name=label)
    return cut
