"""Seeded procedural indoor scenes: closed rooms joined by doorways, furnished and coloured.

The generator works in two pure steps:

1. :func:`generate_layout` draws a floor plan from a seed: the footprint is split into rooms
   by axis-aligned walls (a binary space partition), every split wall gets a doorway, then
   each room gets furniture (:mod:`naruto_gym.scenes.furniture`), wall paintings, a rug and a
   ceiling light. Nothing is placed in front of a doorway and every piece of furniture
   keeps a gap of ``object_gap_m`` to the others, so an agent (a sphere of radius 0.05 m)
   can walk into every room and around every object. The result is a
   :class:`SceneLayout`: rooms, doorways, objects (each a list of primitive parts) and a
   collision-free start position.
2. :meth:`SceneLayout.to_scene` turns the layout into triangles with per-vertex colours.
   Walls, floor and ceiling are solid slabs (walls ``wall_thickness`` thick, floor and
   ceiling 0.1 m) that overlap at every junction, so no ray can leak out of a room.
   Colours are flat per surface with a fixed directional shade baked in (no textures),
   so the same object looks different from different sides.

Coordinates: metres, z up. The free floor of the footprint is ``[0, W] x [0, D]`` and the
free height is ``[0, H]`` for ``size = (W, D, H)``; the mesh's bounds therefore extend one
wall thickness beyond the footprint and 0.1 m below the floor and above the ceiling.

Determinism: all randomness comes from ``numpy.random.default_rng(seed)``, circles use
Python's ``math`` functions and vertex positions are rounded to 0.1 mm and stored as
float32 values, so the same seed gives a byte-identical PLY file.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import trimesh

from naruto_gym.scenes.furniture import (
    FABRICS,
    FURNITURE,
    RGB,
    ROOM_KIND_ORDER,
    WALL_PAINTS,
    WOODS,
    LocalPart,
    jitter,
    painting,
    pick,
    rug,
)
from naruto_gym.scenes.mesh_scene import Scene, scene_from_trimesh

SceneKind = Literal["room", "apartment"]

# Bump whenever the same arguments start producing a different mesh: it names the cache
# folder where missing catalogue meshes are regenerated, so stale files are never reused.
GENERATOR_VERSION = 1

FLOOR_THICKNESS_M = 0.1
START_HEIGHT_M = 1.5  # camera height of a standing person, as in Replica trajectories
_EPS = 1e-6

# Fixed light direction for the baked shading: faces towards it are brighter.
_LIGHT_NORM = math.sqrt(0.35**2 + 0.55**2 + 0.76**2)
_LIGHT = (0.35 / _LIGHT_NORM, 0.55 / _LIGHT_NORM, 0.76 / _LIGHT_NORM)

_EXTERIOR_RGB: RGB = (150, 150, 150)
_CEILING_RGB: RGB = (242, 240, 236)
_DOOR_FRAME_RGB: RGB = (112, 82, 58)
_LIGHT_PANEL_RGB: RGB = (255, 252, 236)


# ---------------------------------------------------------------------------------------
# Plan geometry
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Rect:
    """Axis-aligned rectangle in the floor plane, ``[x0, x1] x [y0, y1]`` metres."""

    x0: float
    y0: float
    x1: float
    y1: float

    @property
    def width(self) -> float:
        return self.x1 - self.x0

    @property
    def depth(self) -> float:
        return self.y1 - self.y0

    @property
    def area(self) -> float:
        return self.width * self.depth

    @property
    def centre(self) -> tuple[float, float]:
        return (0.5 * (self.x0 + self.x1), 0.5 * (self.y0 + self.y1))

    def inflated(self, margin: float) -> Rect:
        return Rect(self.x0 - margin, self.y0 - margin, self.x1 + margin, self.y1 + margin)

    def intersects(self, other: Rect) -> bool:
        """True when the interiors overlap (touching edges do not count)."""
        return (
            self.x0 < other.x1 - _EPS
            and other.x0 < self.x1 - _EPS
            and self.y0 < other.y1 - _EPS
            and other.y0 < self.y1 - _EPS
        )

    def contains(self, other: Rect) -> bool:
        return (
            self.x0 <= other.x0 + _EPS
            and self.y0 <= other.y0 + _EPS
            and other.x1 <= self.x1 + _EPS
            and other.y1 <= self.y1 + _EPS
        )

    def contains_point(self, x: float, y: float) -> bool:
        return self.x0 <= x <= self.x1 and self.y0 <= y <= self.y1

    def distance_to_points(self, points: np.ndarray) -> np.ndarray:
        """Euclidean distance from (N, 2) points to the rectangle (0 inside)."""
        dx = np.maximum(np.maximum(self.x0 - points[:, 0], points[:, 0] - self.x1), 0.0)
        dy = np.maximum(np.maximum(self.y0 - points[:, 1], points[:, 1] - self.y1), 0.0)
        return np.sqrt(dx * dx + dy * dy)

    def as_list(self) -> list[float]:
        return [round(v, 4) for v in (self.x0, self.y0, self.x1, self.y1)]


@dataclass(frozen=True)
class Room:
    """One room of a layout.

    Attributes:
        name: unique name such as ``"bedroom_2"``.
        kind: room type that chose its furniture (``living_room``, ``bedroom``, ...).
        cell: the room's cell of the plan partition, bounded by wall centre lines.
        interior: the free floor, bounded by the walls' inner faces.
    """

    name: str
    kind: str
    cell: Rect
    interior: Rect


@dataclass(frozen=True)
class Doorway:
    """An opening in a wall between two rooms.

    Attributes:
        along: ``"x"`` when the wall runs along x (it sits at ``y = coord``), else ``"y"``.
        coord: the wall's centre line coordinate.
        lo, hi: the opening's extent along the wall.
        height: height of the opening's top (the lintel's underside).
        rooms: indices of the two rooms it joins.
    """

    along: Literal["x", "y"]
    coord: float
    lo: float
    hi: float
    height: float
    rooms: tuple[int, int] = (-1, -1)

    @property
    def centre(self) -> tuple[float, float]:
        middle = 0.5 * (self.lo + self.hi)
        return (middle, self.coord) if self.along == "x" else (self.coord, middle)

    def passage(self, depth: float, z: float) -> tuple[np.ndarray, np.ndarray]:
        """Two points ``depth`` metres either side of the opening, at height ``z``."""
        cx, cy = self.centre
        normal = np.array([0.0, 1.0, 0.0]) if self.along == "x" else np.array([1.0, 0.0, 0.0])
        centre = np.array([cx, cy, z])
        return centre - depth * normal, centre + depth * normal


@dataclass(frozen=True)
class Part:
    """A coloured primitive in world coordinates.

    ``kind`` is ``"box"`` (``data`` = x0, y0, z0, x1, y1, z1), ``"frustum"`` (``data`` =
    cx, cy, z0, bottom radius, top radius, height) or ``"sphere"`` (``data`` = cx, cy, cz,
    radius). ``colours`` holds one RGB, or six for a box (faces -x, +x, -y, +y, -z, +z).
    """

    kind: Literal["box", "frustum", "sphere"]
    data: tuple[float, ...]
    colours: tuple[RGB, ...]


@dataclass(frozen=True)
class PlacedObject:
    """A piece of furniture or decoration: its plan footprint, height and parts."""

    kind: str
    room: int
    footprint: Rect
    height: float
    parts: tuple[Part, ...]
    blocks_motion: bool = True


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
        return scene_from_trimesh(_to_trimesh(vertices, faces, colours), name=name, up_axis="z")


# ---------------------------------------------------------------------------------------
# Mesh building
# ---------------------------------------------------------------------------------------
def _shade(rgb: Sequence[int], normals: np.ndarray) -> np.ndarray:
    """Colour lit by a fixed light: (N, 3) uint8 for (N, 3) unit normals."""
    # Element-wise products rather than a matrix product: BLAS kernels may round differently
    # from machine to machine, and the colours must be bit-identical everywhere.
    lit = normals[:, 0] * _LIGHT[0] + normals[:, 1] * _LIGHT[1] + normals[:, 2] * _LIGHT[2]
    factor = 0.78 + 0.22 * lit
    return np.clip(np.asarray(rgb, np.float64)[None, :] * factor[:, None] + 0.5, 0, 255).astype(
        np.uint8
    )


_BOX_FACES = (
    # (normal, four corner selectors (ix, iy, iz) in counter-clockwise order seen from outside)
    ((-1.0, 0.0, 0.0), ((0, 0, 0), (0, 0, 1), (0, 1, 1), (0, 1, 0))),
    ((1.0, 0.0, 0.0), ((1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1))),
    ((0.0, -1.0, 0.0), ((0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1))),
    ((0.0, 1.0, 0.0), ((0, 1, 0), (0, 1, 1), (1, 1, 1), (1, 1, 0))),
    ((0.0, 0.0, -1.0), ((0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 0))),
    ((0.0, 0.0, 1.0), ((0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1))),
)


# The box's 24 corners (four per face, in _BOX_FACES order) as selectors into [lo, hi].
_BOX_CORNER_SELECTORS = np.array([corner for _, corners in _BOX_FACES for corner in corners])
_BOX_AXES = np.arange(3)[None, :]
_BOX_TRIANGLES = np.array(
    [(4 * f, 4 * f + a, 4 * f + a + 1) for f in range(len(_BOX_FACES)) for a in (1, 2)], np.int64
)
_QUAD_TRIANGLES = np.array([(0, 1, 2), (0, 2, 3)], np.int64)
def _flat_shade(rgb: Sequence[int], normal: Sequence[float]) -> tuple[int, int, int]:
    """:func:`_shade` of one colour and one normal in plain floats (the same IEEE double
    operations in the same order, so the same bytes), without NumPy's per-call cost: a scene
    shades every box face and floor tile this way, thousands of times."""
    nx, ny, nz = (float(n) for n in normal)
    factor = 0.78 + 0.22 * (nx * _LIGHT[0] + ny * _LIGHT[1] + nz * _LIGHT[2])
    red, green, blue = (int(min(max(float(c) * factor + 0.5, 0.0), 255.0)) for c in rgb)
    return red, green, blue

class _MeshBuilder:
    """Accumulates triangles with per-vertex colours."""

    def __init__(self) -> None:
        self._vertices: list[np.ndarray] = []
        self._faces: list[np.ndarray] = []
        self._colours: list[np.ndarray] = []
        self._count = 0

    def add(self, vertices: np.ndarray, faces: np.ndarray, colours: np.ndarray) -> None:
        self._vertices.append(np.asarray(vertices, np.float64))
        self._faces.append(np.asarray(faces, np.int64) + self._count)
        self._colours.append(np.asarray(colours, np.uint8))
        self._count += len(vertices)

    def box(self, lo: Sequence[float], hi: Sequence[float], colours: Sequence[RGB]) -> None:
        """Solid box; ``colours`` has one RGB or six (faces -x, +x, -y, +y, -z, +z)."""
        corners = np.array([lo, hi], np.float64)
        vertices = corners[_BOX_CORNER_SELECTORS, _BOX_AXES]
        shaded = [
            _flat_shade(colours[index] if len(colours) == 6 else colours[0], normal)
            for index, (normal, _) in enumerate(_BOX_FACES)
        ]
        self.add(vertices, _BOX_TRIANGLES, np.repeat(np.array(shaded, np.uint8), 4, axis=0))

    def quad(self, corners: np.ndarray, colour: RGB, normal: Sequence[float]) -> None:
        """One flat quad; corners (4, 3) counter-clockwise seen from the normal's side."""
        shaded = np.repeat(np.array([_flat_shade(colour, normal)], np.uint8), 4, axis=0)
        self.add(corners, _QUAD_TRIANGLES, shaded)

    def frustum(
        self,
        cx: float,
        cy: float,
        z0: float,
        bottom_radius: float,
        top_radius: float,
        height: float,
        colour: RGB,
        sections: int = 16,
    ) -> None:
        """Closed truncated cone (a cylinder when both radii match), axis along z."""
        angles = [2.0 * math.pi * k / sections for k in range(sections)]
        ring = np.array([(math.cos(a), math.sin(a)) for a in angles])
        z1 = z0 + height
        bottom = np.column_stack(
            [cx + bottom_radius * ring[:, 0], cy + bottom_radius * ring[:, 1],
             np.full(sections, z0)]
        )
        top = np.column_stack(
            [cx + top_radius * ring[:, 0], cy + top_radius * ring[:, 1], np.full(sections, z1)]
        )
        # Side: smooth shading from radial normals.
        side_normals = np.column_stack([ring, np.zeros(sections)])
        k = np.arange(sections)
        k1 = (k + 1) % sections
        side_faces = np.concatenate(
            [np.column_stack([k, k1, sections + k1]), np.column_stack([k, sections + k1,
                                                                        sections + k])]
        )
        self.add(
            np.concatenate([bottom, top]),
            side_faces,
            np.concatenate([_shade(colour, side_normals)] * 2),
        )
        # Caps: flat shading, fan around a centre vertex.
        for ring_points, z, normal in ((bottom, z0, -1.0), (top, z1, 1.0)):
            vertices = np.concatenate([[[cx, cy, z]], ring_points])
            fan = np.column_stack([np.zeros(sections, np.int64), 1 + k, 1 + k1])
            if normal < 0:
                fan = fan[:, [0, 2, 1]]
            shaded = np.repeat(_shade(colour, np.array([[0.0, 0.0, normal]])), sections + 1, 0)
            self.add(vertices, fan, shaded)

    def sphere(
        self, cx: float, cy: float, cz: float, radius: float, colour: RGB,
        rings: int = 8, segments: int = 12,
    ) -> None:
        """UV sphere with smooth shading."""
        normals = [(0.0, 0.0, -1.0)]
        for i in range(1, rings):
            polar = math.pi * i / rings - 0.5 * math.pi
            for j in range(segments):
                azimuth = 2.0 * math.pi * j / segments
                normals.append(
                    (math.cos(polar) * math.cos(azimuth), math.cos(polar) * math.sin(azimuth),
                     math.sin(polar))
                )
        normals.append((0.0, 0.0, 1.0))
        normal_array = np.array(normals)
        faces = []
        top = len(normals) - 1
        for j in range(segments):
            j1 = (j + 1) % segments
            faces.append((0, 1 + j1, 1 + j))
            last = 1 + (rings - 2) * segments
            faces.append((top, last + j, last + j1))
        for i in range(rings - 2):
            row, nxt = 1 + i * segments, 1 + (i + 1) * segments
            for j in range(segments):
                j1 = (j + 1) % segments
                faces += [(row + j, row + j1, nxt + j1), (row + j, nxt + j1, nxt + j)]
        vertices = np.array([cx, cy, cz]) + radius * normal_array
        self.add(vertices, np.array(faces), _shade(colour, normal_array))

    def part(self, part: Part) -> None:
        if part.kind == "box":
            self.box(part.data[:3], part.data[3:], part.colours)
        elif part.kind == "frustum":
            self.frustum(*part.data, colour=part.colours[0])
        else:
            self.sphere(*part.data, colour=part.colours[0])

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        vertices = np.concatenate(self._vertices)
        # 0.1 mm grid, then float32: the file stores float32 and a reloaded scene matches.
        vertices = np.round(vertices, 4).astype(np.float32).astype(np.float64)
        return vertices, np.concatenate(self._faces), np.concatenate(self._colours)


def _to_trimesh(vertices: np.ndarray, faces: np.ndarray, colours: np.ndarray) -> trimesh.Trimesh:
    rgba = np.concatenate([colours, np.full((len(colours), 1), 255, np.uint8)], axis=1)
    return trimesh.Trimesh(vertices, faces, vertex_colors=rgba, process=False)


def _room_at(rooms: list[Room], x: float, y: float) -> int:
    for index, room in enumerate(rooms):
        if room.cell.contains_point(x, y):
            return index
    return -1


@dataclass(frozen=True)
class _Wall:
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
            if abs(coord) < _EPS or abs(coord - limit) < _EPS:
                continue
            lines.setdefault((along, round(coord, 6)), []).append((lo, hi))
    for (along, coord), spans in sorted(lines.items()):
        spans.sort()
        merged = [list(spans[0])]
        for lo, hi in spans[1:]:
            if lo <= merged[-1][1] + _EPS:
                merged[-1][1] = max(merged[-1][1], hi)
            else:
                merged.append([lo, hi])
        # Extended by half a thickness at both ends, into the walls they meet.
        # Ends stop 1 mm short of the far face of the wall they meet, so that end faces
        # never lie in the plane of a visible wall face (which would flicker).
        reach = 0.5 * t - 0.001
        walls += [_Wall(along, coord, lo - reach, hi + reach) for lo, hi in merged]
    return walls


def _emit_walls(builder: _MeshBuilder, layout: SceneLayout, wall_colours: list[RGB]) -> None:
    t = layout.wall_thickness
    height = layout.size[2]
    z_low, z_high = -FLOOR_THICKNESS_M, height + FLOOR_THICKNESS_M
    cuts_x = sorted({round(v, 6) for r in layout.rooms for v in (r.cell.x0, r.cell.x1)})
    cuts_y = sorted({round(v, 6) for r in layout.rooms for v in (r.cell.y0, r.cell.y1)})
    for wall in _walls_of(layout):
        doors = [
            d for d in layout.doorways
            if d.along == wall.along and abs(d.coord - wall.coord) < _EPS
            and d.lo >= wall.lo - _EPS and d.hi <= wall.hi + _EPS
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
            door = next((d for d in doors if d.lo - _EPS <= middle <= d.hi + _EPS), None)
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
    builder: _MeshBuilder, cell: Rect, material: dict, rng: np.random.Generator
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
    if kind in ("kitchen", "bathroom"):
        light = jitter(rng, (222, 222, 216), 12)
        dark = jitter(rng, (150, 156, 160), 20)
        return {"tile": (0.5, 0.5), "colours": [light, dark], "jitter": 4}
    if kind == "bedroom":
        return {"tile": (1.0, 1.0), "colours": [pick(rng, FABRICS)], "jitter": 6}
    wood = pick(rng, WOODS)
    return {"tile": (0.2, 1.2), "colours": [wood], "jitter": 14}


def _build_mesh(layout: SceneLayout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    # Surface colours come from their own stream so that they never shift the plan.
    rng = np.random.default_rng([layout.seed, 1])
    builder = _MeshBuilder()
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
    builder: _MeshBuilder, layout: SceneLayout, index: int, room: Room, wall_colour: RGB
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


# Facing direction (into the room) per wall side, and the along-wall direction
# (right-handed with z up: along x facing = +z).
_SIDES = {
    "south": ((0.0, 1.0), (1.0, 0.0)),
    "north": ((0.0, -1.0), (-1.0, 0.0)),
    "west": ((1.0, 0.0), (0.0, -1.0)),
    "east": ((-1.0, 0.0), (0.0, 1.0)),
}


@dataclass(frozen=True)
class _Frame:
    """Maps local (along, into-room) plan coordinates to world coordinates."""

    anchor: tuple[float, float]
    facing: tuple[float, float]
    along: tuple[float, float]

    def point(self, u: float, v: float) -> tuple[float, float]:
        return (
            self.anchor[0] + u * self.along[0] + v * self.facing[0],
            self.anchor[1] + u * self.along[1] + v * self.facing[1],
        )

    def rect(self, u0: float, v0: float, u1: float, v1: float) -> Rect:
        (ax, ay), (bx, by) = self.point(u0, v0), self.point(u1, v1)
        return Rect(min(ax, bx), min(ay, by), max(ax, bx), max(ay, by))


def _frame_for(side: str, footprint: Rect, width: float) -> _Frame:
    """Frame whose local footprint [0, width] x [0, depth] lands on ``footprint``."""
    facing, along = _SIDES[side]
    # Local origin = the footprint corner that is at u = 0, v = 0.
    x = footprint.x0 if along[0] > 0 or facing[0] > 0 else footprint.x1
    y = footprint.y0 if along[1] > 0 or facing[1] > 0 else footprint.y1
    return _Frame((x, y), facing, along)


def _world_parts(frame: _Frame, parts: list[LocalPart]) -> tuple[Part, ...]:
    out = []
    for kind, data, colours in parts:
        if kind == "box":
            rect = frame.rect(data[0], data[1], data[3], data[4])
            world = (rect.x0, rect.y0, data[2], rect.x1, rect.y1, data[5])
            if len(colours) == 6:
                colours = _rotate_box_colours(frame, colours)
            out.append(Part("box", tuple(round(v, 5) for v in world), colours))
        else:
            x, y = frame.point(data[0], data[1])
            out.append(Part(kind, tuple(round(v, 5) for v in (x, y, *data[2:])), colours))
    return tuple(out)


def _rotate_box_colours(frame: _Frame, colours: tuple[RGB, ...]) -> tuple[RGB, ...]:
    """Local face colours (-u, +u, -v, +v, -z, +z) to world faces (-x, +x, -y, +y, -z, +z)."""
    world = list(colours)
    local_axes = {0: frame.along, 1: frame.along, 2: frame.facing, 3: frame.facing}
    for local_face in range(4):
        axis = local_axes[local_face]
        sign = 1.0 if local_face % 2 else -1.0
        direction = (sign * axis[0], sign * axis[1])
        if abs(direction[0]) > 0.5:
            world[1 if direction[0] > 0 else 0] = colours[local_face]
        else:
            world[3 if direction[1] > 0 else 2] = colours[local_face]
    return tuple(world)


# ---------------------------------------------------------------------------------------
# Layout generation
# ---------------------------------------------------------------------------------------
def _door_blocks(doors: list[Doorway], along: str, coord: float, lo: float, hi: float) -> bool:
    return any(
        d.along == along and abs(d.coord - coord) < _EPS and d.lo < hi and lo < d.hi
        for d in doors
    )


def _partition(
    rng: np.random.Generator,
    width: float,
    depth: float,
    num_rooms: int,
    min_room: float,
    thickness: float,
    door_width: float,
    door_height: float,
) -> tuple[list[Rect], list[Doorway]]:
    """Split the footprint into ``num_rooms`` cells, with one doorway per split wall."""
    cells = [Rect(0.0, 0.0, width, depth)]
    doors: list[Doorway] = []
    margin = 0.5 * thickness + 0.25  # doorway edge to any wall junction
    while len(cells) < num_rooms:
        order = sorted(range(len(cells)), key=lambda i: (-cells[i].area, i))
        split = None
        for index in order:
            cell = cells[index]
            options = []
            if cell.width >= 2 * min_room:
                options.append("x")  # cut across x: a wall running along y
            if cell.depth >= 2 * min_room:
                options.append("y")
            if not options:
                continue
            longer = "x" if cell.width >= cell.depth else "y"
            axis = longer if len(options) == 1 or rng.random() < 0.8 else (
                "y" if longer == "x" else "x")
            axis = axis if axis in options else options[0]
            lo, hi = (cell.x0, cell.x1) if axis == "x" else (cell.y0, cell.y1)
            for _ in range(30):
                s = round(round(float(rng.uniform(lo + min_room, hi - min_room)) / 0.05) * 0.05, 4)
                if not (lo + min_room - _EPS <= s <= hi - min_room + _EPS):
                    continue
                # The new wall must not end inside an existing doorway of the cell's walls.
                if axis == "x":
                    blocked = any(
                        _door_blocks(doors, "x", c, s - margin, s + margin)
                        for c in (cell.y0, cell.y1)
                    )
                else:
                    blocked = any(
                        _door_blocks(doors, "y", c, s - margin, s + margin)
                        for c in (cell.x0, cell.x1)
                    )
                if not blocked:
                    split = (index, axis, s)
                    break
            if split is not None:
                break
        if split is None:
            raise ValueError(
                f"cannot split a {width} x {depth} m footprint into {num_rooms} rooms of at "
                f"least {min_room} m; use a larger size, fewer rooms or a smaller min_room_size"
            )
        index, axis, s = split
        cell = cells[index]
        if axis == "x":
            first, second = Rect(cell.x0, cell.y0, s, cell.y1), Rect(s, cell.y0, cell.x1, cell.y1)
            wall_lo, wall_hi, along = cell.y0, cell.y1, "y"
        else:
            first, second = Rect(cell.x0, cell.y0, cell.x1, s), Rect(cell.x0, s, cell.x1, cell.y1)
            wall_lo, wall_hi, along = cell.x0, cell.x1, "x"
        start = round(float(rng.uniform(wall_lo + margin, wall_hi - margin - door_width)), 3)
        doors.append(Doorway(along, s, start, round(start + door_width, 3), door_height))
        cells[index:index + 1] = [first, second]
    return cells, doors


def _shared_edge(a: Rect, b: Rect) -> tuple[str, float, float, float] | None:
    """(along, coord, lo, hi) of the wall segment shared by two cells, if any."""
    for along, a_edge, b_edge, a_span, b_span in (
        ("y", a.x1, b.x0, (a.y0, a.y1), (b.y0, b.y1)),
        ("y", a.x0, b.x1, (a.y0, a.y1), (b.y0, b.y1)),
        ("x", a.y1, b.y0, (a.x0, a.x1), (b.x0, b.x1)),
        ("x", a.y0, b.y1, (a.x0, a.x1), (b.x0, b.x1)),
    ):
        if abs(a_edge - b_edge) < _EPS:
            lo, hi = max(a_span[0], b_span[0]), min(a_span[1], b_span[1])
            if hi > lo:
                return along, a_edge, lo, hi
    return None


def _door_rooms(door: Doorway, cells: list[Rect], thickness: float) -> tuple[int, int]:
    cx, cy = door.centre
    offset = 0.5 * thickness + 0.01
    if door.along == "x":
        a, b = (cx, cy - offset), (cx, cy + offset)
    else:
        a, b = (cx - offset, cy), (cx + offset, cy)
    found = []
    for x, y in (a, b):
        found.append(next(i for i, c in enumerate(cells) if c.contains_point(x, y)))
    return (min(found), max(found))


def _interior(cell: Rect, width: float, depth: float, thickness: float) -> Rect:
    h = 0.5 * thickness
    return Rect(
        cell.x0 + (h if cell.x0 > _EPS else 0.0),
        cell.y0 + (h if cell.y0 > _EPS else 0.0),
        cell.x1 - (h if cell.x1 < width - _EPS else 0.0),
        cell.y1 - (h if cell.y1 < depth - _EPS else 0.0),
    )


def _door_keepouts(room_index: int, room: Room, doors: list[Doorway], reach: float) -> list[Rect]:
    """Plan areas in front of the room's doorways where nothing may stand."""
    inner = room.interior
    out = []
    for door in doors:
        if room_index not in door.rooms:
            continue
        lo, hi = door.lo - 0.15, door.hi + 0.15
        if door.along == "x":
            if abs(door.coord - inner.y0) < abs(door.coord - inner.y1):
                out.append(Rect(lo, inner.y0 - 0.2, hi, inner.y0 + reach))
            else:
                out.append(Rect(lo, inner.y1 - reach, hi, inner.y1 + 0.2))
        else:
            if abs(door.coord - inner.x0) < abs(door.coord - inner.x1):
                out.append(Rect(inner.x0 - 0.2, lo, inner.x0 + reach, hi))
            else:
                out.append(Rect(inner.x1 - reach, lo, inner.x1 + 0.2, hi))
    return out


def _furnish(
    rng: np.random.Generator,
    room_index: int,
    room: Room,
    doors: list[Doorway],
    ceiling: float,
    density: float,
    gap: float,
) -> list[PlacedObject]:
    inner = room.interior
    keepouts = _door_keepouts(room_index, room, doors, reach=min(1.0, 0.35 * min(
        inner.width, inner.depth)))
    placed: list[PlacedObject] = []
    occupied: list[Rect] = []
    for builder, placement, probability in FURNITURE[room.kind]:
        # Draw the decision and the object whatever happens so the stream stays aligned.
        wanted = rng.random() < min(1.0, probability * density)
        width, depth, height, local = builder(rng, ceiling)
        if not wanted:
            continue
        for _ in range(40):
            side = ("south", "north", "west", "east")[int(rng.integers(4))]
            facing, _along = _SIDES[side]
            across_x = abs(facing[0]) > 0.5  # object depth runs along x
            size_x, size_y = (depth, width) if across_x else (width, depth)
            if placement == "wall":
                if side == "south":
                    x0 = float(_draw(rng, inner.x0 + gap, inner.x1 - gap - size_x + _EPS))
                    footprint = Rect(x0, inner.y0, x0 + size_x, inner.y0 + size_y)
                elif side == "north":
                    x0 = float(_draw(rng, inner.x0 + gap, inner.x1 - gap - size_x + _EPS))
                    footprint = Rect(x0, inner.y1 - size_y, x0 + size_x, inner.y1)
                elif side == "west":
                    y0 = float(_draw(rng, inner.y0 + gap, inner.y1 - gap - size_y + _EPS))
                    footprint = Rect(inner.x0, y0, inner.x0 + size_x, y0 + size_y)
                else:
                    y0 = float(_draw(rng, inner.y0 + gap, inner.y1 - gap - size_y + _EPS))
                    footprint = Rect(inner.x1 - size_x, y0, inner.x1, y0 + size_y)
                # Every side but the back keeps the gap to the walls.
                allowed = Rect(
                    inner.x0 if side == "west" else inner.x0 + gap,
                    inner.y0 if side == "south" else inner.y0 + gap,
                    inner.x1 if side == "east" else inner.x1 - gap,
                    inner.y1 if side == "north" else inner.y1 - gap,
                )
            else:
                allowed = inner.inflated(-gap)
                x0 = float(_draw(rng, allowed.x0, allowed.x1 - size_x + _EPS))
                y0 = float(_draw(rng, allowed.y0, allowed.y1 - size_y + _EPS))
                footprint = Rect(x0, y0, x0 + size_x, y0 + size_y)
            footprint = Rect(*(round(v, 4) for v in (footprint.x0, footprint.y0, footprint.x1,
                                                        footprint.y1)))
            if not allowed.contains(footprint):
                continue
            if any(footprint.intersects(k) for k in keepouts):
                continue
            if any(footprint.intersects(o.inflated(gap)) for o in occupied):
                continue
            frame = _frame_for(side, footprint, width)
            parts = _world_parts(frame, local)
            placed.append(PlacedObject(_name_of(builder), room_index, footprint, height, parts))
            occupied.append(footprint)
            break
    placed += _decorate(rng, room_index, room, doors, placed, ceiling)
    return placed


def _draw(rng: np.random.Generator, low: float, high: float) -> float:
    """Uniform draw that tolerates ``high < low`` (the caller rejects the result then)."""
    return low + (high - low) * float(rng.random())


def _name_of(builder) -> str:
    return builder.__name__.lstrip("_")


def _decorate(
    rng: np.random.Generator,
    room_index: int,
    room: Room,
    doors: list[Doorway],
    furniture: list[PlacedObject],
    ceiling: float,
) -> list[PlacedObject]:
    """Paintings on free wall stretches, a rug and a ceiling light panel."""
    inner = room.interior
    out: list[PlacedObject] = []
    # Ceiling light: a bright panel hanging 2 cm below the ceiling in the room's middle.
    cx, cy = inner.centre
    size = 0.3 if min(inner.width, inner.depth) > 1.5 else 0.15
    light = Part("box", (cx - size, cy - size, ceiling - 0.02, cx + size, cy + size, ceiling),
                 (_LIGHT_PANEL_RGB,))
    out.append(PlacedObject("ceiling_light", room_index,
                            Rect(cx - size, cy - size, cx + size, cy + size), 0.02, (light,),
                            blocks_motion=False))
    # Rug, free-standing, flat (no motion blocking), avoiding nothing but the walls.
    if rng.random() < 0.7 and inner.width > 2.2 and inner.depth > 2.2:
        width, depth, height, local = rug(rng, inner.width, inner.depth)
        x0 = float(_draw(rng, inner.x0 + 0.4, inner.x1 - 0.4 - width))
        y0 = float(_draw(rng, inner.y0 + 0.4, inner.y1 - 0.4 - depth))
        footprint = Rect(x0, y0, x0 + width, y0 + depth)
        frame = _frame_for("south", footprint, width)
        out.append(PlacedObject("rug", room_index, footprint, height, _world_parts(frame, local),
                                blocks_motion=False))
    # Paintings: 1-3 per room on wall stretches free of doorways and tall furniture.
    tall = [f.footprint for f in furniture if f.height > 1.1]
    for _ in range(int(rng.integers(1, 4))):
        width = float(_draw(rng, 0.5, 1.2))
        height = float(_draw(rng, 0.4, 0.9))
        z0 = float(_draw(rng, 1.15, 1.45))
        z0 = min(z0, ceiling - 0.3 - height)
        for _attempt in range(20):
            side = ("south", "north", "west", "east")[int(rng.integers(4))]
            facing, _along = _SIDES[side]
            span = inner.x1 - inner.x0 if abs(facing[1]) > 0.5 else inner.y1 - inner.y0
            if span < width + 0.6:
                continue
            offset = float(_draw(rng, 0.3, span - 0.3 - width))
            depth = 0.035
            if side == "south":
                footprint = Rect(inner.x0 + offset, inner.y0, inner.x0 + offset + width,
                                 inner.y0 + depth)
            elif side == "north":
                footprint = Rect(inner.x0 + offset, inner.y1 - depth, inner.x0 + offset + width,
                                 inner.y1)
            elif side == "west":
                footprint = Rect(inner.x0, inner.y0 + offset, inner.x0 + depth,
                                 inner.y0 + offset + width)
            else:
                footprint = Rect(inner.x1 - depth, inner.y0 + offset, inner.x1,
                                 inner.y0 + offset + width)
            near_door = _door_keepouts(room_index, room, doors, reach=0.3)
            others = tall + [o.footprint for o in out if o.kind == "painting"]
            if any(footprint.intersects(k.inflated(0.1)) for k in near_door + others):
                continue
            frame = _frame_for(side, footprint, width)
            out.append(PlacedObject("painting", room_index, footprint, z0 + height,
                                    _world_parts(frame, painting(rng, width, height, z0))))
            break
    return out


def _clearance_point(
    room: Room, objects: list[PlacedObject], ceiling: float, step: float = 0.05
) -> tuple[tuple[float, float, float], float]:
    """The grid point of the room with the largest plan distance to walls and furniture."""
    inner = room.interior
    nx = max(1, int((inner.width - 1e-9) / step))
    ny = max(1, int((inner.depth - 1e-9) / step))
    xs = inner.x0 + (np.arange(nx) + 0.5) * inner.width / nx
    ys = inner.y0 + (np.arange(ny) + 0.5) * inner.depth / ny
    grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
    clearance = np.minimum.reduce([
        grid[:, 0] - inner.x0, inner.x1 - grid[:, 0], grid[:, 1] - inner.y0, inner.y1 - grid[:, 1]
    ])
    for item in objects:
        if item.blocks_motion:
            clearance = np.minimum(clearance, item.footprint.distance_to_points(grid))
    # Round before the argmax so that last-bit differences cannot change the winner.
    best = int(np.argmax(np.round(clearance, 6)))
    z = min(START_HEIGHT_M, ceiling - 0.8)
    point = (round(float(grid[best, 0]), 4), round(float(grid[best, 1]), 4), round(z, 4))
    return point, float(min(clearance[best], z, ceiling - z))


def generate_layout(
    seed: int,
    size: Sequence[float] = (5.0, 5.0, 3.0),
    num_rooms: int = 1,
    *,
    wall_thickness: float = 0.12,
    door_width: float = 0.9,
    door_height: float = 2.1,
    min_room_size: float = 2.4,
    furniture_density: float = 1.0,
    extra_door_probability: float = 0.35,
    object_gap_m: float = 0.4,
) -> SceneLayout:
    """Draw a furnished floor plan from a seed.

    Args:
        seed: non-negative integer; the same arguments always give the same layout.
        size: free interior (width along x, depth along y, height) in metres.
        num_rooms: number of rooms the footprint is split into (1 = one closed room).
        wall_thickness: thickness of every wall in metres.
        door_width: doorway width in metres.
        door_height: doorway height in metres (below ``size[2]``).
        min_room_size: smallest side of a room's cell in metres.
        furniture_density: scales each optional object's probability (0 = empty rooms
            apart from decorations).
        extra_door_probability: chance that two adjacent rooms not joined yet get their own
            doorway, which makes loops in the room graph.
        object_gap_m: plan gap kept between furniture and to walls (except the back of
            wall-standing furniture).

    Returns:
        A :class:`SceneLayout`.

    Raises:
        ValueError: a setting is out of range or the rooms cannot fit the footprint.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    size_tuple = tuple(float(v) for v in size)
    if len(size_tuple) != 3 or min(size_tuple) <= 0:
        raise ValueError(f"size must be three positive metres (width, depth, height), got {size!r}")
    width, depth, height = size_tuple
    if num_rooms < 1:
        raise ValueError(f"num_rooms must be at least 1, got {num_rooms}")
    if min(width, depth) < 2.0:
        raise ValueError(f"width and depth must be at least 2 m, got {width} x {depth}")
    if not 1.5 <= door_height <= height - 0.2:
        raise ValueError(
            f"door_height {door_height} m must lie in [1.5, height - 0.2 = {height - 0.2}] m; "
            "raise the height or lower the doors"
        )
    if not 0.5 <= door_width <= min_room_size - wall_thickness - 0.6:
        raise ValueError(
            f"door_width {door_width} m must lie in [0.5, min_room_size - wall_thickness - 0.6]"
        )
    if not 0.0 < wall_thickness <= 0.5:
        raise ValueError(f"wall_thickness must be in (0, 0.5] m, got {wall_thickness}")
    if furniture_density < 0:
        raise ValueError(f"furniture_density must be >= 0, got {furniture_density}")
    rng = np.random.default_rng(int(seed))
    cells, doors = _partition(
        rng, width, depth, int(num_rooms), min_room_size, wall_thickness, door_width, door_height
    )
    doors = [Doorway(d.along, d.coord, d.lo, d.hi, d.height,
                     _door_rooms(d, cells, wall_thickness)) for d in doors]
    # Extra doorways make loops: exploring agents then have more than one way round.
    margin = 0.5 * wall_thickness + 0.25
    for a in range(len(cells)):
        for b in range(a + 1, len(cells)):
            draw = rng.random()
            shared = _shared_edge(cells[a], cells[b])
            if shared is None or any(d.rooms == (a, b) for d in doors):
                continue
            along, coord, lo, hi = shared
            if draw >= extra_door_probability or hi - lo < door_width + 2 * margin:
                continue
            start = round(float(rng.uniform(lo + margin, hi - margin - door_width)), 3)
            doors.append(Doorway(along, coord, start, round(start + door_width, 3), door_height,
                                 (a, b)))
    # Room kinds: the largest is the living room, the smallest may be a bathroom.
    by_area = sorted(range(len(cells)), key=lambda i: (-cells[i].area, i))
    kinds = [""] * len(cells)
    for rank, index in enumerate(by_area):
        if rank == 0:
            kinds[index] = "living_room"
        elif rank == len(cells) - 1 and len(cells) >= 4 and cells[index].area < 9.0:
            kinds[index] = "bathroom"
        else:
            kinds[index] = ROOM_KIND_ORDER[(rank - 1) % len(ROOM_KIND_ORDER)]
    counts: dict[str, int] = {}
    rooms = []
    for index, cell in enumerate(cells):
        counts[kinds[index]] = counts.get(kinds[index], 0) + 1
        rooms.append(Room(f"{kinds[index]}_{counts[kinds[index]]}", kinds[index], cell,
                          _interior(cell, width, depth, wall_thickness)))
    objects: list[PlacedObject] = []
    for index, room in enumerate(rooms):
        objects += _furnish(rng, index, room, doors, height, furniture_density, object_gap_m)
    room_points, clearances = [], []
    for index, room in enumerate(rooms):
        point, clearance = _clearance_point(room, [o for o in objects if o.room == index], height)
        room_points.append(point)
        clearances.append(clearance)
    start_room = by_area[0]
    return SceneLayout(
        seed=int(seed),
        size=size_tuple,  # type: ignore[arg-type]
        wall_thickness=wall_thickness,
        rooms=rooms,
        doorways=doors,
        objects=objects,
        start_position=room_points[start_room],
        start_clearance=clearances[start_room],
        room_points=room_points,
    )


# ---------------------------------------------------------------------------------------
# Public generators
# ---------------------------------------------------------------------------------------
def generate_room(
    seed: int,
    size: Sequence[float] = (5.0, 5.0, 3.0),
    *,
    furniture_density: float = 1.0,
    name: str | None = None,
) -> Scene:
    """One closed, furnished room (Replica-like), free interior ``size`` = (W, D, H) metres.

    Args:
        seed: non-negative integer seed; the same seed gives the same mesh.
        size: free interior width (x), depth (y) and height (z) in metres.
        furniture_density: scales how many optional objects are placed.
        name: scene name, default ``"room_<seed>"``.
    """
    layout = generate_layout(seed, size, 1, furniture_density=furniture_density)
    return layout.to_scene(name or f"room_{seed}")


def generate_apartment(
    seed: int,
    num_rooms: int = 6,
    size: Sequence[float] = (12.0, 9.0, 2.8),
    *,
    furniture_density: float = 1.0,
    extra_door_probability: float = 0.35,
    name: str | None = None,
) -> Scene:
    """A multi-room apartment (Matterport3D-like) of ``num_rooms`` rooms joined by doorways.

    Args:
        seed: non-negative integer seed; the same seed gives the same mesh.
        num_rooms: number of rooms (at least 2).
        size: free interior width (x), depth (y) and height (z) of the whole footprint.
        furniture_density: scales how many optional objects are placed.
        extra_door_probability: chance of an extra doorway between adjacent rooms.
        name: scene name, default ``"apartment_<seed>"``.
    """
    if num_rooms < 2:
        raise ValueError(f"an apartment needs num_rooms >= 2, got {num_rooms}; use generate_room")
    layout = generate_layout(
        seed, size, num_rooms, furniture_density=furniture_density,
        extra_door_probability=extra_door_probability,
    )
    return layout.to_scene(name or f"apartment_{seed}")


def random_layout(seed: int, kind: SceneKind = "room") -> SceneLayout:
    """A layout with its size and room count also drawn from ``seed`` (see
    :func:`make_random_scene`)."""
    if kind not in ("room", "apartment"):
        raise ValueError(f"kind must be 'room' or 'apartment', got {kind!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    rng = np.random.default_rng([int(seed), 2])
    if kind == "room":
        size = (round(float(rng.uniform(4.0, 7.0)), 2), round(float(rng.uniform(4.0, 7.0)), 2),
                round(float(rng.uniform(2.6, 3.2)), 2))
        return generate_layout(seed, size, 1)
    width = round(float(rng.uniform(10.0, 16.0)), 2)
    depth = round(float(rng.uniform(7.5, 12.0)), 2)
    height = round(float(rng.uniform(2.6, 3.0)), 2)
    most = max(4, min(9, int(width * depth / 14.0)))
    num_rooms = int(rng.integers(4, most + 1))
    while True:
        try:
            return generate_layout(seed, (width, depth, height), num_rooms)
        except ValueError:
            # The drawn partition left no cell large enough to split again: fewer rooms.
            if num_rooms <= 4:
                raise
            num_rooms -= 1


def make_random_scene(seed: int, kind: SceneKind = "room") -> Scene:
    """A training scene whose size, room count and contents all follow from ``seed``.

    ``kind="room"``: one room of 4-7 m x 4-7 m x 2.6-3.2 m. ``kind="apartment"``: a
    10-16 m x 7.5-12 m footprint with 4 or more rooms. Seeds map to distinct scenes, so
    ``[make_random_scene(s) for s in range(100)]`` is a training set and other seeds a
    held-out one. The layout, including a safe start position, is :func:`random_layout`.
    """
    return random_layout(seed, kind).to_scene(f"{kind}_{seed}")


# ---------------------------------------------------------------------------------------
# PLY output
# ---------------------------------------------------------------------------------------
def scene_to_ply_bytes(scene: Scene, comment: str = "generated by naruto-gym") -> bytes:
    """Binary little-endian PLY with float32 positions and uchar RGB vertex colours.

    A vertex shared by triangles whose corners disagree on its colour is split, since PLY
    stores one colour per vertex.
    """
    vertices, faces, corners = scene.vertices, scene.faces, scene.corner_colours
    per_vertex = np.zeros((len(vertices), 3), np.uint8)
    per_vertex[faces.ravel()] = corners.reshape(-1, 3)
    if not np.array_equal(per_vertex[faces], corners):
        keys = np.concatenate([faces.reshape(-1, 1), corners.reshape(-1, 3).astype(np.int64)], 1)
        unique, inverse = np.unique(keys, axis=0, return_inverse=True)
        vertices = vertices[unique[:, 0]]
        per_vertex = unique[:, 1:].astype(np.uint8)
        faces = inverse.reshape(-1, 3)
    if "\n" in comment:
        raise ValueError("the PLY comment must be a single line")
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"comment {comment}\n"
        f"element vertex {len(vertices)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        f"element face {len(faces)}\n"
        "property list uchar int vertex_indices\nend_header\n"
    ).encode("ascii")
    vertex_type = np.dtype([("p", "<f4", 3), ("c", "u1", 3)])
    vertex_data = np.empty(len(vertices), vertex_type)
    vertex_data["p"] = vertices
    vertex_data["c"] = per_vertex
    face_type = np.dtype([("n", "u1"), ("i", "<i4", 3)])
    face_data = np.empty(len(faces), face_type)
    face_data["n"] = 3
    face_data["i"] = faces
    return header + vertex_data.tobytes() + face_data.tobytes()


def save_scene_ply(
    scene: Scene, path: str | Path, comment: str = "generated by naruto-gym"
) -> Path:
    """Write ``scene`` as a binary PLY with vertex colours (see :func:`scene_to_ply_bytes`).

    The file is written to a temporary name and moved into place, so a reader never sees a
    half-written file.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f".{path.name}.tmp")
    temporary.write_bytes(scene_to_ply_bytes(scene, comment))
    temporary.replace(path)
    return path
