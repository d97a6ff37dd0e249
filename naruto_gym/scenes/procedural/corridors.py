"""House plans with corridors: a hallway spine, an optional branch, rooms on both sides.

Large houses are not a grid of rooms opening into each other: most rooms open onto a hallway,
so an explorer must follow the corridors and look into every door. :func:`corridor_partition`
draws such a plan. A spine corridor crosses the footprint along its longer side; with
``branch`` a second corridor leaves it at right angles and runs to the exterior wall of the
deeper side. The blocks left between the corridors and the exterior walls are split into
rooms by :func:`~naruto_gym.scenes.procedural.plan.partition` (so the rooms of a block are
joined by doorways among themselves), and every room that borders a corridor gets a doorway
onto it. Every block borders a corridor, so every room is reachable from the hallway.
"""

from __future__ import annotations

import numpy as np

from naruto_gym.scenes.procedural.plan import Doorway, Rect, partition, shared_edge

#: Smallest depth of a block of rooms beside a corridor, in metres.
MIN_BLOCK_DEPTH_M = 3.0


def _shifted(door: Doorway, dx: float, dy: float) -> Doorway:
    """A block-frame doorway in the footprint's frame (the block's origin at (dx, dy))."""
    if door.along == "x":
        return Doorway("x", round(door.coord + dy, 4), round(door.lo + dx, 4),
                       round(door.hi + dx, 4), door.height)
    return Doorway("y", round(door.coord + dx, 4), round(door.lo + dy, 4), round(door.hi + dy, 4),
                   door.height)


def _snap(value: float) -> float:
    """``value`` on the plan's 5 cm grid (walls of different blocks then line up exactly)."""
    return round(round(value / 0.05) * 0.05, 4)


def corridor_partition(
    rng: np.random.Generator,
    width: float,
    depth: float,
    num_rooms: int,
    corridor_width: float,
    branch: bool,
    min_room: float,
    thickness: float,
    door_width: float,
    door_height: float,
) -> tuple[list[Rect], list[Doorway], list[int]]:
    """Split a footprint into corridors and ``num_rooms`` rooms that open onto them.

    Args:
        rng: the layout's random stream.
        width: footprint extent along x in metres.
        depth: footprint extent along y in metres.
        num_rooms: number of rooms, corridors not counted.
        corridor_width: corridor width between wall centre lines, in metres.
        branch: add a corridor at right angles to the spine.
        min_room: smallest side of a room's cell in metres.
        thickness: wall thickness in metres.
        door_width: doorway width in metres.
        door_height: doorway height in metres.

    Returns:
        The cells (rooms and corridors), the doorways (``rooms`` not set yet: see
        :func:`~naruto_gym.scenes.procedural.plan.door_rooms`) and the indices of the
        corridor cells.

    Raises:
        ValueError: the footprint is too small for the corridors and the rooms.
    """
    along_x = width >= depth
    # Work in a frame whose x runs along the spine, then map back (swap x and y).
    length, across = (width, depth) if along_x else (depth, width)
    free = across - corridor_width
    if free < 2 * MIN_BLOCK_DEPTH_M:
        raise ValueError(
            f"a {width} x {depth} m footprint leaves no room for a {corridor_width} m corridor "
            f"with blocks of at least {MIN_BLOCK_DEPTH_M} m either side; use a larger size"
        )
    low = _snap(float(rng.uniform(max(MIN_BLOCK_DEPTH_M, 0.38 * free),
                                  min(free - MIN_BLOCK_DEPTH_M, 0.55 * free))))
    spine = Rect(0.0, low, length, _snap(low + corridor_width))
    corridors = [spine]
    blocks = [Rect(0.0, 0.0, length, spine.y0)]
    far = Rect(0.0, spine.y1, length, across)
    if branch and length >= 2 * MIN_BLOCK_DEPTH_M + corridor_width + 2.0:
        x0 = _snap(float(rng.uniform(0.35 * length, 0.65 * length - corridor_width)))
        stem = Rect(x0, spine.y1, _snap(x0 + corridor_width), across)
        corridors.append(stem)
        blocks += [Rect(0.0, far.y0, stem.x0, across), Rect(stem.x1, far.y0, length, across)]
    else:
        blocks.append(far)
    # Rooms per block in proportion to its area, at least one each.
    total = sum(block.area for block in blocks)
    counts = [max(1, int(round(num_rooms * block.area / total))) for block in blocks]
    while sum(counts) > num_rooms:
        counts[int(np.argmax(counts))] -= 1
    while sum(counts) < num_rooms:
        shares = [block.area / count for block, count in zip(blocks, counts, strict=True)]
        counts[int(np.argmax(shares))] += 1
    cells: list[Rect] = []
    doors: list[Doorway] = []
    for block, count in zip(blocks, counts, strict=True):
        block_cells, block_doors = partition(
            rng, block.width, block.depth, count, min_room, thickness, door_width, door_height
        )
        cells += [Rect(c.x0 + block.x0, c.y0 + block.y0, c.x1 + block.x0, c.y1 + block.y0)
                  for c in block_cells]
        doors += [_shifted(d, block.x0, block.y0) for d in block_doors]
    first_corridor = len(cells)
    cells += corridors
    margin = 0.5 * thickness + 0.25
    # Every room that borders a corridor opens onto it.
    for corridor in corridors:
        for cell in cells[:first_corridor]:
            shared = shared_edge(cell, corridor)
            if shared is None:
                continue
            along, coord, lo, hi = shared
            if hi - lo < door_width + 2 * margin:
                continue
            start = round(float(rng.uniform(lo + margin, hi - margin - door_width)), 3)
            doors.append(Doorway(along, coord, start, round(start + door_width, 3), door_height))  # type: ignore[arg-type]
    # The branch opens onto the spine over its whole width (less the wall ends).
    for stem in corridors[1:]:
        opening = 0.5 * thickness + 0.1
        doors.append(Doorway("x", stem.y0, round(stem.x0 + opening, 3),
                             round(stem.x1 - opening, 3), door_height))
    indices = list(range(first_corridor, len(cells)))
    if along_x:
        return cells, doors, indices
    swapped = [Rect(c.y0, c.x0, c.y1, c.x1) for c in cells]
    swapped_doors = [Doorway("y" if d.along == "x" else "x", d.coord, d.lo, d.hi, d.height)
                     for d in doors]
    return swapped, swapped_doors, indices
