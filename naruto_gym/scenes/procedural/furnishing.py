"""Furnishing a room: furniture against walls or free-standing, paintings, a rug, a light.

The furniture builders (:mod:`naruto_gym.scenes.procedural.furniture`) return parts in a
local frame; here each object is given a place in the room and its parts are turned into
world coordinates. Nothing is placed in front of a doorway and every piece of furniture keeps
a gap of ``gap`` metres to the others and to the walls (except the back of wall-standing
furniture), so an agent can walk into every room and around every object.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from naruto_gym.scenes.procedural.clutter import CLUTTER
from naruto_gym.scenes.procedural.furniture import FURNITURE, RGB, LocalPart, painting, rug
from naruto_gym.scenes.procedural.plan import EPS, Doorway, Part, PlacedObject, Rect, Room

_LIGHT_PANEL_RGB: RGB = (255, 252, 236)

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
        """World (x, y) of local (u, v)."""
        return (
            self.anchor[0] + u * self.along[0] + v * self.facing[0],
            self.anchor[1] + u * self.along[1] + v * self.facing[1],
        )

    def rect(self, u0: float, v0: float, u1: float, v1: float) -> Rect:
        """World rectangle of the local rectangle ``[u0, u1] x [v0, v1]``."""
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
    """Local parts of a furniture builder as world parts (coordinates rounded to 10 um)."""
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


def furnish(
    rng: np.random.Generator,
    room_index: int,
    room: Room,
    doors: list[Doorway],
    ceiling: float,
    density: float,
    gap: float,
    clutter: float = 0.0,
) -> list[PlacedObject]:
    """Furniture of the room's kind, then clutter, then its decorations (see
    :func:`_decorate`).

    Each optional piece is kept with probability ``probability * density`` and tried at up
    to 40 random places (against a wall or free-standing, as the piece asks) until one
    keeps clear of the walls, the doorways and the pieces already placed.

    Args:
        rng: the layout's random stream.
        room_index: index of the room in the layout.
        room: the room.
        doors: every doorway of the layout.
        ceiling: free height in metres.
        density: scales each optional piece's probability.
        gap: plan gap in metres kept between pieces and to the walls.
        clutter: scales the probability of each piece of
            :data:`~naruto_gym.scenes.procedural.clutter.CLUTTER`; 0 places none and draws
            nothing for it, so layouts without clutter keep their random stream.

    Returns:
        The room's placed objects.
    """
    inner = room.interior
    # In a corridor nothing may stand across from a doorway either: the keep-out spans it.
    reach = min(inner.width, inner.depth) if room.kind == "corridor" else min(
        1.0, 0.35 * min(inner.width, inner.depth))
    keepouts = _door_keepouts(room_index, room, doors, reach=reach)
    placed: list[PlacedObject] = []
    occupied: list[Rect] = []
    pieces = [(builder, placement, probability * density)
              for builder, placement, probability in FURNITURE[room.kind]]
    if clutter > 0:
        pieces += [(builder, placement, probability * clutter)
                   for builder, placement, probability in CLUTTER]
    for builder, placement, chance in pieces:
        # Draw the decision and the object whatever happens so the stream stays aligned.
        wanted = rng.random() < min(1.0, chance)
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
                    x0 = float(_draw(rng, inner.x0 + gap, inner.x1 - gap - size_x + EPS))
                    footprint = Rect(x0, inner.y0, x0 + size_x, inner.y0 + size_y)
                elif side == "north":
                    x0 = float(_draw(rng, inner.x0 + gap, inner.x1 - gap - size_x + EPS))
                    footprint = Rect(x0, inner.y1 - size_y, x0 + size_x, inner.y1)
                elif side == "west":
                    y0 = float(_draw(rng, inner.y0 + gap, inner.y1 - gap - size_y + EPS))
                    footprint = Rect(inner.x0, y0, inner.x0 + size_x, y0 + size_y)
                else:
                    y0 = float(_draw(rng, inner.y0 + gap, inner.y1 - gap - size_y + EPS))
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
                x0 = float(_draw(rng, allowed.x0, allowed.x1 - size_x + EPS))
                y0 = float(_draw(rng, allowed.y0, allowed.y1 - size_y + EPS))
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


def _name_of(builder: Callable[..., object]) -> str:
    """The object kind a furniture builder makes (its function name)."""
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
