"""The procedural scene generators: a seed in, a furnished floor plan or a mesh out.

:func:`generate_layout` draws a plan (:func:`~naruto_gym.scenes.procedural.plan.partition`),
extra doorways that make loops in the room graph, the room kinds, the furniture
(:func:`~naruto_gym.scenes.procedural.furnishing.furnish`) and one well-clear point per room,
the largest room's being the start position. :func:`generate_room`,
:func:`generate_apartment` and :func:`make_random_scene` wrap it for the usual cases.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np

from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.scenes.procedural.corridors import corridor_partition
from naruto_gym.scenes.procedural.furnishing import furnish
from naruto_gym.scenes.procedural.furniture import ROOM_KIND_ORDER
from naruto_gym.scenes.procedural.layout import SceneLayout
from naruto_gym.scenes.procedural.plan import (
    Doorway,
    PlacedObject,
    Rect,
    Room,
    door_rooms,
    partition,
    room_interior,
    shared_edge,
)

SceneKind = Literal["room", "apartment"]

# Bump whenever the same arguments start producing a different mesh: it names the cache
# folder where missing catalogue meshes are regenerated, so stale files are never reused.
GENERATOR_VERSION = 1

START_HEIGHT_M = 1.5  # camera height of a standing person, as in Replica trajectories

# Kinds of the rooms of a house plan after its living room, kitchen and dining room.
HOUSE_ROOM_ORDER = ["bedroom", "office", "bedroom", "bedroom", "office"]


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


def _house_kinds(cells: list[Rect], by_area: list[int], kinds: list[str]) -> None:
    """Room kinds of a plan with corridors, written into ``kinds``: one living room (the
    largest), one kitchen and one dining room, a bathroom per four rooms among the smallest,
    the rest bedrooms and offices."""
    bathrooms = max(1, len(by_area) // 4)
    for index in reversed(by_area[1:]):
        if bathrooms and cells[index].area < 9.0:
            kinds[index] = "bathroom"
            bathrooms -= 1
    others = [index for index in by_area if not kinds[index]]
    order = ["living_room", "kitchen", "dining_room"] + HOUSE_ROOM_ORDER * len(others)
    for index, kind in zip(others, order, strict=False):
        kinds[index] = kind


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
    corridor_width: float = 0.0,
    corridor_branch: bool = False,
    clutter: float = 0.0,
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
        corridor_width: 0 splits the footprint into rooms that open into each other; a
            width (at least 1.1 m) draws a house plan instead: a hallway spine with rooms on
            both sides (see :func:`~naruto_gym.scenes.procedural.corridors.corridor_partition`;
            ``num_rooms`` then counts the rooms, not the corridors).
        corridor_branch: with a corridor, add a second one at right angles to the spine.
        clutter: scales the probability of the small clutter objects (boxes, stray chairs,
            baskets, see :mod:`~naruto_gym.scenes.procedural.clutter`) placed in every room
            besides its furniture; 0 places none.

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
    if clutter < 0:
        raise ValueError(f"clutter must be >= 0, got {clutter}")
    if corridor_width != 0 and not 1.1 <= corridor_width <= 3.0:
        raise ValueError(
            f"corridor_width must be 0 (no corridor) or in [1.1, 3.0] m, got {corridor_width}"
        )
    rng = np.random.default_rng(int(seed))
    corridor_cells: list[int] = []
    if corridor_width > 0:
        cells, doors, corridor_cells = corridor_partition(
            rng, width, depth, int(num_rooms), float(corridor_width), bool(corridor_branch),
            min_room_size, wall_thickness, door_width, door_height,
        )
    else:
        cells, doors = partition(
            rng, width, depth, int(num_rooms), min_room_size, wall_thickness, door_width,
            door_height,
        )
    doors = [Doorway(d.along, d.coord, d.lo, d.hi, d.height,
                     door_rooms(d, cells, wall_thickness)) for d in doors]
    # Extra doorways make loops: exploring agents then have more than one way round.
    margin = 0.5 * wall_thickness + 0.25
    for a in range(len(cells)):
        for b in range(a + 1, len(cells)):
            draw = rng.random()
            shared = shared_edge(cells[a], cells[b])
            if shared is None or any(d.rooms == (a, b) for d in doors):
                continue
            along, coord, lo, hi = shared
            if draw >= extra_door_probability or hi - lo < door_width + 2 * margin:
                continue
            start = round(float(rng.uniform(lo + margin, hi - margin - door_width)), 3)
            doors.append(Doorway(along, coord, start, round(start + door_width, 3), door_height,
                                 (a, b)))
    # Room kinds: the largest is the living room, the smallest may be a bathroom.
    # Room kinds: the largest is the living room, the smallest may be a bathroom.
    by_area = sorted((i for i in range(len(cells)) if i not in corridor_cells),
                     key=lambda i: (-cells[i].area, i))
    kinds = ["corridor" if i in corridor_cells else "" for i in range(len(cells))]
    if corridor_cells:
        _house_kinds(cells, by_area, kinds)
    for rank, index in enumerate(by_area):
        if kinds[index]:
            continue
        if rank == 0:
            kinds[index] = "living_room"
        elif rank == len(by_area) - 1 and len(by_area) >= 4 and cells[index].area < 9.0:
            kinds[index] = "bathroom"
        else:
            kinds[index] = ROOM_KIND_ORDER[(rank - 1) % len(ROOM_KIND_ORDER)]
    counts: dict[str, int] = {}
    rooms = []
    for index, cell in enumerate(cells):
        counts[kinds[index]] = counts.get(kinds[index], 0) + 1
        rooms.append(Room(f"{kinds[index]}_{counts[kinds[index]]}", kinds[index], cell,
                          room_interior(cell, width, depth, wall_thickness)))
    objects: list[PlacedObject] = []
    for index, room in enumerate(rooms):
        objects += furnish(rng, index, room, doors, height, furniture_density, object_gap_m,
                           clutter=0.0 if room.kind == "corridor" else clutter)
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
