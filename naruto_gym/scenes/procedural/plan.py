"""The floor plan of a procedural scene and the partition that makes it.

A plan lives in the floor plane (metres, x and y): :class:`Rect` is an axis-aligned
rectangle, a :class:`Room` is one cell of the footprint, a :class:`Doorway` an opening in the
wall between two rooms, and a :class:`PlacedObject` a piece of furniture or decoration made of
world-frame :class:`Part` primitives. :func:`partition` splits a footprint into rooms by
axis-aligned walls (a binary space partition), giving every split wall a doorway, so the
rooms are always connected. Everything here is plain data and pure functions of a seeded
generator; the mesh is made elsewhere (:mod:`naruto_gym.scenes.procedural.layout`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from naruto_gym.scenes.procedural.furniture import RGB

#: Tolerance of plan comparisons in metres: coordinates are rounded to 0.1 mm or coarser, so
#: two edges closer than this are the same edge.
EPS = 1e-6


@dataclass(frozen=True)
class Rect:
    """Axis-aligned rectangle in the floor plane, ``[x0, x1] x [y0, y1]`` metres."""

    x0: float
    y0: float
    x1: float
    y1: float

    @property
    def width(self) -> float:
        """Extent along x in metres."""
        return self.x1 - self.x0

    @property
    def depth(self) -> float:
        """Extent along y in metres."""
        return self.y1 - self.y0

    @property
    def area(self) -> float:
        """Area in square metres."""
        return self.width * self.depth

    @property
    def centre(self) -> tuple[float, float]:
        """The (x, y) centre."""
        return (0.5 * (self.x0 + self.x1), 0.5 * (self.y0 + self.y1))

    def inflated(self, margin: float) -> Rect:
        """The rectangle grown by ``margin`` metres on every side (shrunk when negative)."""
        return Rect(self.x0 - margin, self.y0 - margin, self.x1 + margin, self.y1 + margin)

    def intersects(self, other: Rect) -> bool:
        """True when the interiors overlap (touching edges do not count)."""
        return (
            self.x0 < other.x1 - EPS
            and other.x0 < self.x1 - EPS
            and self.y0 < other.y1 - EPS
            and other.y0 < self.y1 - EPS
        )

    def contains(self, other: Rect) -> bool:
        """True when ``other`` lies inside (up to :data:`EPS`)."""
        return (
            self.x0 <= other.x0 + EPS
            and self.y0 <= other.y0 + EPS
            and other.x1 <= self.x1 + EPS
            and other.y1 <= self.y1 + EPS
        )

    def contains_point(self, x: float, y: float) -> bool:
        """True when (x, y) lies inside or on the boundary."""
        return self.x0 <= x <= self.x1 and self.y0 <= y <= self.y1

    def distance_to_points(self, points: np.ndarray) -> np.ndarray:
        """Euclidean distance from (N, 2) points to the rectangle (0 inside)."""
        dx = np.maximum(np.maximum(self.x0 - points[:, 0], points[:, 0] - self.x1), 0.0)
        dy = np.maximum(np.maximum(self.y0 - points[:, 1], points[:, 1] - self.y1), 0.0)
        return np.sqrt(dx * dx + dy * dy)

    def as_list(self) -> list[float]:
        """``[x0, y0, x1, y1]`` rounded to 0.1 mm (for JSON records)."""
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
        """The (x, y) middle of the opening on the wall's centre line."""
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


# ---------------------------------------------------------------------------------------
# Partition of a footprint into rooms
# ---------------------------------------------------------------------------------------
def _door_blocks(doors: list[Doorway], along: str, coord: float, lo: float, hi: float) -> bool:
    """True when a doorway of the wall line ``(along, coord)`` overlaps ``(lo, hi)``."""
    return any(
        d.along == along and abs(d.coord - coord) < EPS and d.lo < hi and lo < d.hi
        for d in doors
    )


def partition(
    rng: np.random.Generator,
    width: float,
    depth: float,
    num_rooms: int,
    min_room: float,
    thickness: float,
    door_width: float,
    door_height: float,
) -> tuple[list[Rect], list[Doorway]]:
    """Split the footprint into ``num_rooms`` cells, with one doorway per split wall.

    The largest cell that can be split is cut first, usually across its longer side, on a
    5 cm grid; a cut never ends inside an existing doorway, so every doorway stays usable.

    Args:
        rng: the layout's random stream.
        width: footprint extent along x in metres.
        depth: footprint extent along y in metres.
        num_rooms: number of cells to make.
        min_room: smallest side of a cell in metres.
        thickness: wall thickness in metres.
        door_width: doorway width in metres.
        door_height: doorway height in metres.

    Returns:
        The cells (bounded by wall centre lines) and the doorways of the split walls (their
        ``rooms`` not set yet: see :func:`door_rooms`).

    Raises:
        ValueError: the footprint cannot hold ``num_rooms`` cells of ``min_room``.
    """
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
                if not (lo + min_room - EPS <= s <= hi - min_room + EPS):
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


def shared_edge(a: Rect, b: Rect) -> tuple[str, float, float, float] | None:
    """(along, coord, lo, hi) of the wall segment shared by two cells, if any."""
    for along, a_edge, b_edge, a_span, b_span in (
        ("y", a.x1, b.x0, (a.y0, a.y1), (b.y0, b.y1)),
        ("y", a.x0, b.x1, (a.y0, a.y1), (b.y0, b.y1)),
        ("x", a.y1, b.y0, (a.x0, a.x1), (b.x0, b.x1)),
        ("x", a.y0, b.y1, (a.x0, a.x1), (b.x0, b.x1)),
    ):
        if abs(a_edge - b_edge) < EPS:
            lo, hi = max(a_span[0], b_span[0]), min(a_span[1], b_span[1])
            if hi > lo:
                return along, a_edge, lo, hi
    return None


def door_rooms(door: Doorway, cells: list[Rect], thickness: float) -> tuple[int, int]:
    """Indices (lower first) of the two cells either side of a doorway."""
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


def room_interior(cell: Rect, width: float, depth: float, thickness: float) -> Rect:
    """A cell's free floor: the cell less half a wall on every interior side (the
    footprint's own boundary is already the exterior walls' inner face)."""
    h = 0.5 * thickness
    return Rect(
        cell.x0 + (h if cell.x0 > EPS else 0.0),
        cell.y0 + (h if cell.y0 > EPS else 0.0),
        cell.x1 - (h if cell.x1 < width - EPS else 0.0),
        cell.y1 - (h if cell.y1 < depth - EPS else 0.0),
    )

