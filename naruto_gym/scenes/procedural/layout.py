"""A generated layout (:class:`SceneLayout`) and the mesh it makes.

:meth:`SceneLayout.to_scene` turns rooms, doorways and objects into triangles with per-vertex
colours. Walls, floor and ceiling are solid slabs (walls ``wall_thickness`` thick, floor and
ceiling :data:`FLOOR_THICKNESS_M`) that overlap at every junction, so no ray can leak out of a
room; interior walls are merged per line so that no two wall boxes share a coplanar face
(which would flicker). Floors are tiled per room and walls get a skirting board interrupted
at the doorways. Surface colours come from their own random stream (``[seed, 1]``), so they
never shift the plan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from naruto_gym.scenes.mesh_scene import Scene, scene_from_trimesh
from naruto_gym.scenes.procedural.furniture import FABRICS, RGB, WALL_PAINTS, WOODS, jitter, pick
from naruto_gym.scenes.procedural.mesh_builder import MeshBuilder, to_trimesh
from naruto_gym.scenes.procedural.plan import EPS, Doorway, PlacedObject, Rect, Room

FLOOR_THICKNESS_M = 0.1

_EXTERIOR_RGB: RGB = (150, 150, 150)
_CEILING_RGB: RGB = (242, 240, 236)
_DOOR_FRAME_RGB: RGB = (112, 82, 58)


@dataclass
class SceneLayout:
    """A generated floor plan with furniture; :meth:`to_scene` makes the mesh.

    Attributes:
        seed: the generator seed.
        size: free interior size (W, D, H) in metres.
        wall_thickness: wall thickness in metres.
        rooms: the rooms.
        doorways: openings joining the rooms (the room graph is connected).
        objects: furniture and decorations.
        start_position: (x, y, z) with the largest clearance in the first (largest) room.
        start_clearance: plan-view clearance of the start position in metres.
        room_points: one well-clear (x, y, z) point per room, in room order.
    """

    seed: int
    size: tuple[float, float, float]
    wall_thickness: float
    rooms: list[Room]
    doorways: list[Doorway]
    objects: list[PlacedObject]
    start_position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    start_clearance: float = 0.0
    room_points: list[tuple[float, float, float]] = field(default_factory=list)

    def to_mesh_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(vertices (V, 3) float64, faces (F, 3) int64, vertex colours (V, 3) uint8)."""
        return _build_mesh(self)

    def to_scene(self, name: str = "procedural") -> Scene:
        """The layout as a z-up :class:`Scene` with per-vertex colours."""
        vertices, faces, colours = self.to_mesh_arrays()
        return scene_from_trimesh(to_trimesh(vertices, faces, colours), name=name, up_axis="z")


def _room_at(rooms: list[Room], x: float, y: float) -> int:
    """Index of the room whose cell holds (x, y), -1 outside every cell."""
    for index, room in enumerate(rooms):
        if room.cell.contains_point(x, y):
            return index
    return -1


@dataclass(frozen=True)
class _Wall:
    """A wall slab: its centre line ``along`` x or y at ``coord``, from ``lo`` to ``hi``."""

    along: Literal["x", "y"]
    coord: float
    lo: float
    hi: float


def _walls_of(layout: SceneLayout) -> list[_Wall]:
    """Exterior walls plus one wall per distinct interior cell edge."""
    width, depth, _ = layout.size
    t = layout.wall_thickness
    walls = [
        _Wall("x", -0.5 * t, -t, width + t),
        _Wall("x", depth + 0.5 * t, -t, width + t),
        _Wall("y", -0.5 * t, -t, depth + t),
        _Wall("y", width + 0.5 * t, -t, depth + t),
    ]
    # Interior walls: every cell edge off the boundary, merged per line into maximal
    # segments so that no two wall boxes overlap with coplanar faces.
    lines: dict[tuple[str, float], list[tuple[float, float]]] = {}
    for room in layout.rooms:
        cell = room.cell
        for along, coord, lo, hi in (
            ("x", cell.y0, cell.x0, cell.x1), ("x", cell.y1, cell.x0, cell.x1),
            ("y", cell.x0, cell.y0, cell.y1), ("y", cell.x1, cell.y0, cell.y1),
        ):
            limit = depth if along == "x" else width
            if abs(coord) < EPS or abs(coord - limit) < EPS:
                continue
            lines.setdefault((along, round(coord, 6)), []).append((lo, hi))
    for (along, coord), spans in sorted(lines.items()):
        spans.sort()
        merged = [list(spans[0])]
        for lo, hi in spans[1:]:
            if lo <= merged[-1][1] + EPS:
                merged[-1][1] = max(merged[-1][1], hi)
            else:
                merged.append([lo, hi])
        # Extended by half a thickness at both ends, into the walls they meet.
        # Ends stop 1 mm short of the far face of the wall they meet, so that end faces
        # never lie in the plane of a visible wall face (which would flicker).
        reach = 0.5 * t - 0.001
        walls += [_Wall(along, coord, lo - reach, hi + reach) for lo, hi in merged]
    return walls


def _emit_walls(builder: MeshBuilder, layout: SceneLayout, wall_colours: list[RGB]) -> None:
    """Every wall as boxes split at the cell corners and doorways, each face in the colour of
    the room it faces; above a doorway only the lintel remains."""
    t = layout.wall_thickness
    height = layout.size[2]
    z_low, z_high = -FLOOR_THICKNESS_M, height + FLOOR_THICKNESS_M
    cuts_x = sorted({round(v, 6) for r in layout.rooms for v in (r.cell.x0, r.cell.x1)})
    cuts_y = sorted({round(v, 6) for r in layout.rooms for v in (r.cell.y0, r.cell.y1)})
    for wall in _walls_of(layout):
        doors = [
            d for d in layout.doorways
            if d.along == wall.along and abs(d.coord - wall.coord) < EPS
            and d.lo >= wall.lo - EPS and d.hi <= wall.hi + EPS
        ]
        cuts = cuts_x if wall.along == "x" else cuts_y
        breaks = {wall.lo, wall.hi}
        breaks.update(c for c in cuts if wall.lo < c < wall.hi)
        for door in doors:
            breaks.update((door.lo, door.hi))
        points = sorted(breaks)
        for a, b in zip(points[:-1], points[1:], strict=True):
            if b - a < 1e-4:
                continue
            middle = 0.5 * (a + b)
            door = next((d for d in doors if d.lo - EPS <= middle <= d.hi + EPS), None)
            side_colours = []
            for sign in (-1.0, 1.0):
                offset = wall.coord + sign * (0.5 * t + 0.01)
                x, y = (middle, offset) if wall.along == "x" else (offset, middle)
                room = _room_at(layout.rooms, x, y)
                side_colours.append(wall_colours[room] if room >= 0 else _EXTERIOR_RGB)
            z0 = z_low if door is None else door.height
            if wall.along == "x":
                lo, hi = (a, wall.coord - 0.5 * t, z0), (b, wall.coord + 0.5 * t, z_high)
                colours = (_DOOR_FRAME_RGB, _DOOR_FRAME_RGB, side_colours[0], side_colours[1],
                           _DOOR_FRAME_RGB, _CEILING_RGB)
            else:
                lo, hi = (wall.coord - 0.5 * t, a, z0), (wall.coord + 0.5 * t, b, z_high)
                colours = (side_colours[0], side_colours[1], _DOOR_FRAME_RGB, _DOOR_FRAME_RGB,
                           _DOOR_FRAME_RGB, _CEILING_RGB)
            builder.box(lo, hi, colours)


def _emit_floor_tiles(
    builder: MeshBuilder, cell: Rect, material: dict, rng: np.random.Generator
) -> None:
    """Floor of one room cell as flat tiles of slightly varying colour."""
    tile_x, tile_y = material["tile"]
    nx = max(1, int(math.ceil(cell.width / tile_x - 1e-9)))
    ny = max(1, int(math.ceil(cell.depth / tile_y - 1e-9)))
    xs = [cell.x0 + min(i * tile_x, cell.width) for i in range(nx)] + [cell.x1]
    ys = [cell.y0 + min(j * tile_y, cell.depth) for j in range(ny)] + [cell.y1]
    base = np.array(material["colours"], np.float64)
    jitter = rng.integers(-material["jitter"], material["jitter"] + 1, size=(nx, ny))
    for i in range(nx):
        for j in range(ny):
            colour = base[(i + j) % len(base)] + jitter[i, j]
            colour = tuple(int(c) for c in np.clip(colour, 0, 255))
            corners = np.array(
                [(xs[i], ys[j], 0.0), (xs[i + 1], ys[j], 0.0), (xs[i + 1], ys[j + 1], 0.0),
                 (xs[i], ys[j + 1], 0.0)]
            )
            builder.quad(corners, colour, (0.0, 0.0, 1.0))


def _floor_material(rng: np.random.Generator, kind: str) -> dict:
    """Tile size, colours and colour jitter of a room kind's floor."""
    if kind in ("kitchen", "bathroom"):
        light = jitter(rng, (222, 222, 216), 12)
        dark = jitter(rng, (150, 156, 160), 20)
        return {"tile": (0.5, 0.5), "colours": [light, dark], "jitter": 4}
    if kind == "bedroom":
        return {"tile": (1.0, 1.0), "colours": [pick(rng, FABRICS)], "jitter": 6}
    wood = pick(rng, WOODS)
    return {"tile": (0.2, 1.2), "colours": [wood], "jitter": 14}


def _build_mesh(layout: SceneLayout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The layout's (vertices, faces, vertex colours): slabs, floors, walls, skirting boards
    and objects, in that order."""
    # Surface colours come from their own stream so that they never shift the plan.
    rng = np.random.default_rng([layout.seed, 1])
    builder = MeshBuilder()
    width, depth, height = layout.size
    t = layout.wall_thickness
    wall_colours = [jitter(rng, pick(rng, WALL_PAINTS), 8) for _ in layout.rooms]
    # Floor and ceiling slabs under/over everything: the floor's top sits 5 mm below the
    # tiles so the two never fight over a pixel.
    builder.box((-t, -t, -FLOOR_THICKNESS_M), (width + t, depth + t, -0.005), [_EXTERIOR_RGB])
    builder.box((-t, -t, height), (width + t, depth + t, height + FLOOR_THICKNESS_M),
                [_CEILING_RGB])
    for room in layout.rooms:
        _emit_floor_tiles(builder, room.cell, _floor_material(rng, room.kind), rng)
    _emit_walls(builder, layout, wall_colours)
    for index, room in enumerate(layout.rooms):
        _emit_baseboards(builder, layout, index, room, wall_colours[index])
    for item in layout.objects:
        for part in item.parts:
            builder.part(part)
    return builder.arrays()


def _emit_baseboards(
    builder: MeshBuilder, layout: SceneLayout, index: int, room: Room, wall_colour: RGB
) -> None:
    """A low skirting strip along the room's walls, interrupted at doorways."""
    inner = room.interior
    thickness, board_height = 0.015, 0.08
    colour = tuple(int(c * 0.75) for c in wall_colour)
    for along, coord, lo, hi, sign in (
        ("x", inner.y0, inner.x0, inner.x1, 1.0), ("x", inner.y1, inner.x0, inner.x1, -1.0),
        ("y", inner.x0, inner.y0, inner.y1, 1.0), ("y", inner.x1, inner.y0, inner.y1, -1.0),
    ):
        gaps = sorted(
            (d.lo, d.hi) for d in layout.doorways
            if index in d.rooms and d.along == along
            and abs(d.coord - coord) <= 0.5 * layout.wall_thickness + 1e-4
        )
        start = lo
        for gap_lo, gap_hi in gaps + [(hi, hi)]:
            end = min(gap_lo, hi)
            if end - start > 0.05:
                inner_face = coord + sign * thickness
                a, b = sorted((coord, inner_face))
                if along == "x":
                    builder.box((start, a, 0.0), (end, b, board_height), [colour])
                else:
                    builder.box((a, start, 0.0), (b, end, board_height), [colour])
            start = max(start, gap_hi)
