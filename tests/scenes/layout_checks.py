"""Checks that a generated layout is usable by every policy: open doorways, reachable rooms,
clear start, furniture off the doorways (shared by the generator's and the suite's tests)."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest

from naruto_gym.scenes.procedural import SceneLayout
from naruto_gym.sensors.raycaster import RayCaster

AGENT_RADIUS_M = 0.05
FURNITURE_EXCLUDED = {"painting", "rug", "ceiling_light"}


def reachable_rooms(layout: SceneLayout, caster: RayCaster, z: float, step: float = 0.1):
    """Rooms whose free point a breadth-first search over free plan cells reaches from the
    start position, on a grid at height ``z``."""
    width, depth, _ = layout.size
    xs = np.arange(step / 2, width, step)
    ys = np.arange(step / 2, depth, step)
    grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1)
    points = np.concatenate([grid.reshape(-1, 2), np.full((grid.shape[0] * grid.shape[1], 1), z)],
                            axis=1)
    free = (caster.unsigned_distance(points) >= AGENT_RADIUS_M + 0.03).reshape(grid.shape[:2])

    def cell_of(point) -> tuple[int, int]:
        return (int(np.clip(round((point[0] - step / 2) / step), 0, len(xs) - 1)),
                int(np.clip(round((point[1] - step / 2) / step), 0, len(ys) - 1)))

    start = cell_of(layout.start_position)
    assert free[start], "start cell is not free"
    seen = np.zeros_like(free)
    seen[start] = True
    queue = deque([start])
    while queue:
        i, j = queue.popleft()
        for a, b in ((i + 1, j), (i - 1, j), (i, j + 1), (i, j - 1)):
            if 0 <= a < free.shape[0] and 0 <= b < free.shape[1] and free[a, b] and not seen[a, b]:
                seen[a, b] = True
                queue.append((a, b))
    return [index for index, point in enumerate(layout.room_points) if seen[cell_of(point)]]


def assert_doorways_open(layout: SceneLayout, caster: RayCaster) -> None:
    """Every doorway can be walked through at 1 m height, and its lintel closes it above."""
    for door in layout.doorways:
        near, far = door.passage(depth=0.6, z=1.0)
        assert caster.segment_is_free(near, far, clearance=AGENT_RADIUS_M), door
        centre = 0.5 * (near + far)
        up = caster.cast_distance(centre[None], np.array([[0.0, 0.0, 1.0]]))[0]
        assert up == pytest.approx(door.height - 1.0, abs=1e-3)


def assert_rooms_joined(layout: SceneLayout) -> None:
    """Every room is reached from the first through doorways (the room graph is connected)."""
    neighbours: dict[int, set[int]] = {i: set() for i in range(len(layout.rooms))}
    for door in layout.doorways:
        a, b = door.rooms
        assert a != b
        neighbours[a].add(b)
        neighbours[b].add(a)
    seen, stack = {0}, [0]
    while stack:
        for other in neighbours[stack.pop()] - seen:
            seen.add(other)
            stack.append(other)
    assert seen == set(range(len(layout.rooms)))


def assert_furniture_clear(layout: SceneLayout) -> None:
    """Furniture stays inside its room, keeps its gaps and stands in front of no doorway."""
    furniture = [o for o in layout.objects if o.kind not in FURNITURE_EXCLUDED]
    assert furniture, "no furniture placed"
    for index, item in enumerate(furniture):
        room = layout.rooms[item.room]
        assert room.interior.contains(item.footprint), item.kind
        for other in furniture[index + 1:]:
            if other.room != item.room:
                continue  # back to back across a wall is fine
            assert not item.footprint.intersects(other.footprint.inflated(0.399)), (
                item.kind, other.kind)
        for door in layout.doorways:
            near, far = door.passage(depth=0.7, z=0.0)
            lo = np.minimum(near, far)[:2] - 0.05
            hi = np.maximum(near, far)[:2] + 0.05
            if door.along == "x":
                lo[0], hi[0] = door.lo, door.hi
            else:
                lo[1], hi[1] = door.lo, door.hi
            fp = item.footprint
            assert not (fp.x0 < hi[0] and lo[0] < fp.x1 and fp.y0 < hi[1] and lo[1] < fp.y1), (
                f"{item.kind} stands in front of a doorway")
