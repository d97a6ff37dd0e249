"""Compiled planner of the goal actions (:mod:`naruto_gym.rl.goal_actions`): a breadth-first
search over the agent's own map, and the primitive move that follows its path.

A cell is traversable when the agent's rays crossed it at its height (free) and no obstacle
lies within ``inflate`` cells of it. The search never enters other cells, so a path never
leads into an obstacle or into space the agent has not seen; a forward move is taken only when
the cell it ends in is traversable too.
"""

from __future__ import annotations

import numba
import numpy as np

from naruto_gym.motion.actions import DISCRETE_ACTIONS
from naruto_gym.rl.egocentric_map_kernels import FREE, OCCUPIED

MOVE_FORWARD = DISCRETE_ACTIONS.index("move_forward")
MOVE_BACKWARD = DISCRETE_ACTIONS.index("move_backward")
MOVE_LEFT = DISCRETE_ACTIONS.index("move_left")
MOVE_RIGHT = DISCRETE_ACTIONS.index("move_right")
TURN_LEFT = DISCRETE_ACTIONS.index("turn_left")
TURN_RIGHT = DISCRETE_ACTIONS.index("turn_right")

#: Walk statuses.
WALKING, REPLAN, REACHED = 0, 1, 2
_JIT = {"cache": True, "nogil": True}
_NEIGHBOURS = np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [1, -1], [-1, 1], [-1, -1]])
#: The sideways moves, and every move that translates without turning.
SIDEWAYS = np.array([MOVE_LEFT, MOVE_RIGHT])
TRANSLATIONS = np.array([MOVE_FORWARD, MOVE_BACKWARD, MOVE_LEFT, MOVE_RIGHT])
#: Turns off the carrot up to which a safe forward step is taken instead of a turn.
WALK_ON_TURNS = 0.75
#: Path cells ahead of the nearest one the walker may aim at (when it sees them straight).
LOOKAHEAD = 6
#: Each step's direction, as an angle from the camera's heading.
STEP_TURNS = {
    MOVE_FORWARD: 0.0,
    MOVE_BACKWARD: np.pi,
    MOVE_LEFT: 0.5 * np.pi,
    MOVE_RIGHT: -0.5 * np.pi,
}


def step_direction(pose: np.ndarray, move: int) -> np.ndarray:
    """The unit x-y direction of a step (forward, backward, left or right) from ``pose``."""
    heading = float(np.arctan2(pose[1, 2], pose[0, 2])) + STEP_TURNS[move]
    return np.array([np.cos(heading), np.sin(heading)])


@numba.njit(**_JIT)
def traversable(grid: np.ndarray, i: int, j: int, inflate: int) -> bool:
    """Free and without an obstacle within ``inflate`` cells (the map's border is not)."""
    rows, columns = grid.shape[1], grid.shape[2]
    if i - inflate < 0 or j - inflate < 0 or i + inflate >= rows or j + inflate >= columns:
        return False
    if grid[FREE, i, j] == 0:
        return False
    for a in range(i - inflate, i + inflate + 1):
        for b in range(j - inflate, j + inflate + 1):
            if grid[OCCUPIED, a, b] != 0:
                return False
    return True


@numba.njit(**_JIT)
def plan_path(
    grid: np.ndarray,
    origin: np.ndarray,
    cell_m: float,
    start: np.ndarray,
    goal: np.ndarray,
    radius: int,
    inflate: int,
    path: np.ndarray,
) -> int:
    """Path from the world position ``start`` (x, y) towards ``goal`` (x, y) over traversable
    cells within ``radius`` cells of the start (8-connected, no corner cutting), written as
    cells into ``path`` (L, 2), the start's cell first. It ends at the reachable cell closest
    to the goal (the goal's own cell when reachable). Returns the number of cells written
    (1: no move brings the agent closer; a path longer than L is cut to its first L cells).
    """
    si = int(np.floor((start[0] - origin[0]) / cell_m))
    sj = int(np.floor((start[1] - origin[1]) / cell_m))
    gx = (goal[0] - origin[0]) / cell_m
    gy = (goal[1] - origin[1]) / cell_m
    side = 2 * radius + 1
    parent = np.full(side * side, -1, np.int64)
    queue = np.empty(side * side, np.int64)
    start_index = radius * side + radius
    parent[start_index] = start_index
    queue[0] = start_index
    head, tail = 0, 1
    best = start_index
    best_d = (si + 0.5 - gx) ** 2 + (sj + 0.5 - gy) ** 2
    while head < tail:
        index = queue[head]
        head += 1
        li, lj = index // side, index % side
        i, j = si + li - radius, sj + lj - radius
        d = (i + 0.5 - gx) ** 2 + (j + 0.5 - gy) ** 2
        if d < best_d - 1e-9:
            best, best_d = index, d
        for k in range(8):  # straight neighbours first: straighter paths
            di, dj = _NEIGHBOURS[k, 0], _NEIGHBOURS[k, 1]
            ni, nj = li + di, lj + dj
            if ni < 0 or nj < 0 or ni >= side or nj >= side:
                continue
            neighbour = ni * side + nj
            if parent[neighbour] >= 0:
                continue
            if not traversable(grid, i + di, j + dj, inflate):
                continue
            if (
                di != 0
                and dj != 0
                and not (
                    traversable(grid, i + di, j, inflate) and traversable(grid, i, j + dj, inflate)
                )
            ):
                continue
            parent[neighbour] = index
            queue[tail] = neighbour
            tail += 1
    count = 1
    index = best
    while index != start_index:
        index = parent[index]
        count += 1
    keep = min(count, path.shape[0])
    index = best
    for k in range(count - 1, -1, -1):
        if k < keep:
            path[k, 0] = si + index // side - radius
            path[k, 1] = sj + index % side - radius
        index = parent[index]
    return keep


@numba.njit(**_JIT)
def _wrap(angle: float) -> float:
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


@numba.njit(**_JIT)
def _heading(pose: np.ndarray) -> float:
    fx, fy = pose[0, 2], pose[1, 2]
    if fx * fx + fy * fy < 1e-12:
        fx, fy = -pose[0, 1], -pose[1, 1]
    return np.arctan2(fy, fx)


@numba.njit(**_JIT)
def _cell_of(grid_origin: np.ndarray, cell_m: float, x: float, y: float) -> tuple[int, int]:
    return (
        int(np.floor((x - grid_origin[0]) / cell_m)),
        int(np.floor((y - grid_origin[1]) / cell_m)),
    )


@numba.njit(**_JIT)
def _move_direction(pose: np.ndarray, action: int) -> tuple[float, float]:
    """The unit horizontal direction of a move (forward, backward, left, right) from
    ``pose``; (0, 0) for any other action."""
    yaw = _heading(pose)
    fx, fy = np.cos(yaw), np.sin(yaw)
    if action == MOVE_FORWARD:
        return fx, fy
    if action == MOVE_BACKWARD:
        return -fx, -fy
    if action == MOVE_LEFT:
        return -fy, fx
    if action == MOVE_RIGHT:
        return fy, -fx
    return 0.0, 0.0


@numba.njit(**_JIT)
def move_is_safe(
    grid: np.ndarray,
    origin: np.ndarray,
    cell_m: float,
    pose: np.ndarray,
    action: int,
    step_m: float,
    inflate: int,
) -> bool:
    """Whether a horizontal move (forward, backward, left, right) of ``step_m`` ends in the
    agent's own cell or in a traversable one; other actions are always safe here."""
    if action not in (MOVE_FORWARD, MOVE_BACKWARD, MOVE_LEFT, MOVE_RIGHT):
        return True
    mx, my = _move_direction(pose, action)
    here = _cell_of(origin, cell_m, pose[0, 3], pose[1, 3])
    there = _cell_of(origin, cell_m, pose[0, 3] + step_m * mx, pose[1, 3] + step_m * my)
    return there == here or traversable(grid, there[0], there[1], inflate)


@numba.njit(**_JIT)
def _straight(grid: np.ndarray, x0: float, y0: float, x1: float, y1: float, inflate: int) -> bool:
    """Whether every cell the segment (cell units) crosses, but the first, is traversable."""
    length = np.sqrt((x1 - x0) ** 2 + (y1 - y0) ** 2)
    steps = int(length * 3.0) + 1
    start_i, start_j = int(np.floor(x0)), int(np.floor(y0))
    for s in range(1, steps + 1):
        t = s / steps
        i, j = int(np.floor(x0 + t * (x1 - x0))), int(np.floor(y0 + t * (y1 - y0)))
        if (i != start_i or j != start_j) and not traversable(grid, i, j, inflate):
            return False
    return True


@numba.njit(**_JIT)
def path_carrot(
    grid: np.ndarray,
    origin: np.ndarray,
    cell_m: float,
    pose: np.ndarray,
    path: np.ndarray,
    length: int,
    cursor: np.ndarray,
    inflate: int,
) -> tuple[int, int]:
    """The index of the cell of ``path`` (its first ``length`` cells) to aim at from
    ``pose`` (the farthest of the next ``LOOKAHEAD`` in a straight safe line), and a status:
    ``WALKING``, ``REPLAN`` (the path ahead is no longer safe on the updated map) or
    ``REACHED`` (the index is then -1). ``cursor[0]`` is the path index reached so far
    (updated)."""
    x, y = pose[0, 3], pose[1, 3]
    ax, ay = (x - origin[0]) / cell_m, (y - origin[1]) / cell_m
    if length <= 1:
        return -1, REACHED
    best, best_d = cursor[0], 1e18
    for k in range(cursor[0], min(cursor[0] + 8, length)):
        d = (path[k, 0] + 0.5 - ax) ** 2 + (path[k, 1] + 0.5 - ay) ** 2
        if d < best_d:
            best, best_d = k, d
    cursor[0] = best
    if best == length - 1 and best_d < 1.0:
        return -1, REACHED
    for k in range(best + 1, min(best + 6, length)):
        if not traversable(grid, path[k, 0], path[k, 1], inflate):
            return -1, REPLAN
    carrot = best + 1 if best + 1 < length else best
    for k in range(min(best + LOOKAHEAD, length - 1), best + 1, -1):
        if _straight(grid, ax, ay, path[k, 0] + 0.5, path[k, 1] + 0.5, inflate):
            carrot = k
            break
    return carrot, WALKING


@numba.njit(**_JIT)
def follow_path(
    grid: np.ndarray,
    origin: np.ndarray,
    cell_m: float,
    pose: np.ndarray,
    path: np.ndarray,
    length: int,
    cursor: np.ndarray,
    step_m: float,
    turn_rad: float,
    inflate: int,
) -> tuple[int, int]:
    """The primitive action that follows ``path`` (its first ``length`` cells) from ``pose``,
    and a status: ``WALKING``, ``REPLAN`` (the path or the next move is no longer safe on the
    updated map; the action is then a turn in place) or ``REACHED`` (a turn in place).
    ``cursor[0]`` is the path index reached so far (updated)."""
    carrot, status = path_carrot(grid, origin, cell_m, pose, path, length, cursor, inflate)
    if status != WALKING:
        return TURN_LEFT, status
    x, y = pose[0, 3], pose[1, 3]
    best = cursor[0]
    cx = origin[0] + (path[carrot, 0] + 0.5) * cell_m
    cy = origin[1] + (path[carrot, 1] + 0.5) * cell_m
    error = _wrap(np.arctan2(cy - y, cx - x) - _heading(pose))
    forward = move_is_safe(grid, origin, cell_m, pose, MOVE_FORWARD, step_m, inflate)
    # Headings come a whole turn apart: a carrot a little over half a turn off is walked
    # towards while that is safe (the step still brings it nearer); turning would put it
    # as far off on the other side, and the next steps would turn back (a zigzag).
    if abs(error) > (WALK_ON_TURNS if forward else 0.5) * turn_rad + 1e-6:
        return (TURN_LEFT if error > 0 else TURN_RIGHT), WALKING
    if forward:
        return MOVE_FORWARD, WALKING
    # Facing the carrot within half a turn, the step may still end in a cell beside the path
    # that is not traversable (where the path turns by a corner): a sideways step that is
    # safe and brings the path's next cell nearer follows the path instead. Turning and
    # re-planning there would face the same carrot from the same spot again.
    following = best + 1 if best + 1 < length else best
    nx = origin[0] + (path[following, 0] + 0.5) * cell_m
    ny = origin[1] + (path[following, 1] + 0.5) * cell_m
    side = step_towards(grid, origin, cell_m, pose, nx, ny, step_m, inflate, SIDEWAYS)
    if side >= 0:
        return side, WALKING
    return TURN_LEFT, REPLAN


@numba.njit(**_JIT)
def step_towards(
    grid: np.ndarray,
    origin: np.ndarray,
    cell_m: float,
    pose: np.ndarray,
    cx: float,
    cy: float,
    step_m: float,
    inflate: int,
    moves: np.ndarray,
) -> int:
    """The safe move among ``moves`` (forward, backward, left, right) that brings the agent
    nearest to world ``(cx, cy)`` without turning, if it brings it nearer at all; else -1."""
    x, y = pose[0, 3], pose[1, 3]
    best, best_d = -1, (cx - x) ** 2 + (cy - y) ** 2
    for move in moves:
        mx, my = _move_direction(pose, move)
        d = (cx - x - step_m * mx) ** 2 + (cy - y - step_m * my) ** 2
        if d < best_d - 1e-12 and move_is_safe(grid, origin, cell_m, pose, move, step_m, inflate):
            best, best_d = move, d
    return best
