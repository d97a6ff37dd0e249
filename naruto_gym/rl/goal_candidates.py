"""Candidate goals of the goal actions (:mod:`naruto_gym.rl.goal_actions`), found on the
agent's own egocentric map at every decision and ranked by the planner's path length.

A *target* is a far-scale map cell (``far_factor`` fine cells a side, 0.4 m by default) that
is worth looking at:

* an obstacle at the agent's height that the pinhole camera has not seen (its surface is
  what the coverage reward counts; the panorama finds it, the camera has not looked at it), or
* a free cell beside unknown ones (the edge of the space the panorama has carved: a doorway,
  the end of a corridor). At the far scale the gaps between the panorama's rays are filled,
  so these are real edges, not the spaces between rays.

Targets are grouped in square *clusters* of ``cluster_cells`` far cells (0.8 m by default).
For every cluster with at least ``min_targets`` targets the *viewpoint* is the cell the
planner reaches first (breadth-first over traversable cells, as the planner walks) within
``view_m`` of the cluster's centre with a clear line of sight to it. The clusters with a
viewpoint are ranked by path length to it: candidate 0 is the nearest. Clusters the walker has
already viewed from their viewpoint are marked done for the episode and never offered again
(a cluster the camera cannot mark seen, e.g. beyond its range, would otherwise come back).

The feature table of the observation (:data:`CANDIDATE_FEATURES`, one row per candidate
slot, zeros in invalid slots):

* ``valid``: 1 for a candidate, 0 for an empty slot;
* ``path_m``: path length to the viewpoint, in tens of metres;
* ``distance_m``: straight distance from the agent to the cluster's centre, in tens of metres;
* ``bearing_sin``, ``bearing_cos``: direction of the cluster's centre from the agent's heading
  (positive sine: to the left);
* ``size``: share of the cluster's cells that are targets;
* ``unseen_share``: share of its targets that are unseen obstacles (the rest: free-space
  edges);
* ``out_of_sight``: 1 when an obstacle of the map's slice lies on the straight line from the
  agent to the viewpoint. At walking height the slice's obstacles are mostly walls, so such
  a goal is reached round a wall: through a doorway, out of the room or the part of it the
  agent sees (a choice to leave), 0 for a goal in the open space around the agent.

:data:`INTERVAL_FEATURES`, the table without ``out_of_sight``, is the observation of the
decision every ``K`` steps (the models trained on it).

The map is one slice at the agent's height, so a candidate has no height band of its own.
"""

from __future__ import annotations

import numba
import numpy as np

from naruto_gym.rl.egocentric_map_kernels import FREE, OCCUPIED, SEEN, TRAIL, is_unknown
from naruto_gym.rl.goal_planner import traversable

__all__ = [
    "CANDIDATE_FEATURES",
    "INTERVAL_FEATURES",
    "SURROUNDING_RADII_M",
    "candidate_surroundings",
    "find_candidates",
    "path_lengths",
    "reachable_cells",
    "wander_goal",
]

#: Columns of the candidate feature table.
CANDIDATE_FEATURES = (
    "valid",
    "path_m",
    "distance_m",
    "bearing_sin",
    "bearing_cos",
    "size",
    "unseen_share",
    "out_of_sight",
)
#: The columns of the decision every ``K`` steps' table (module docstring).
INTERVAL_FEATURES = CANDIDATE_FEATURES[:-1]
#: Half sides of the squares :func:`candidate_surroundings` counts in, metres.
SURROUNDING_RADII_M = (1.2, 2.4)
_JIT = {"cache": True, "nogil": True}
_NEIGHBOURS = np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [1, -1], [-1, 1], [-1, -1]])
_DIAGONAL = np.sqrt(2.0)


@numba.njit(**_JIT)
def path_lengths(
    grid: np.ndarray, si: int, sj: int, radius: int, inflate: int, out: np.ndarray
) -> None:
    """Breadth-first path lengths (cells; diagonal moves count sqrt 2, no corner cutting, as
    :func:`~naruto_gym.rl.goal_planner.plan_path` walks) from cell ``(si, sj)`` over
    traversable cells within ``radius`` cells, into ``out`` (2 radius + 1 square, -1 where
    unreachable)."""
    side = 2 * radius + 1
    out[:] = -1.0
    queue = np.empty(side * side, np.int64)
    start = radius * side + radius
    out[radius, radius] = 0.0
    queue[0] = start
    head, tail = 0, 1
    while head < tail:
        index = queue[head]
        head += 1
        li, lj = index // side, index % side
        i, j = si + li - radius, sj + lj - radius
        for k in range(8):
            di, dj = _NEIGHBOURS[k, 0], _NEIGHBOURS[k, 1]
            ni, nj = li + di, lj + dj
            if ni < 0 or nj < 0 or ni >= side or nj >= side or out[ni, nj] >= 0:
                continue
            if not traversable(grid, i + di, j + dj, inflate):
                continue
            diagonal = di != 0 and dj != 0
            if diagonal and not (
                traversable(grid, i + di, j, inflate) and traversable(grid, i, j + dj, inflate)
            ):
                continue
            out[ni, nj] = out[li, lj] + (_DIAGONAL if diagonal else 1.0)
            queue[tail] = ni * side + nj
            tail += 1


@numba.njit(**_JIT)
def _clear_line(grid: np.ndarray, x0: float, y0: float, x1: float, y1: float, stop: float) -> bool:
    """No obstacle on the segment (fine cell units) from (x0, y0) towards (x1, y1), up to
    ``stop`` cells short of its end."""
    length = np.sqrt((x1 - x0) ** 2 + (y1 - y0) ** 2)
    if length <= stop:
        return True
    steps = int((length - stop) * 2.0) + 1
    for s in range(1, steps + 1):
        t = s / steps * (length - stop) / length
        i, j = int(np.floor(x0 + t * (x1 - x0))), int(np.floor(y0 + t * (y1 - y0)))
        if i < 0 or j < 0 or i >= grid.shape[1] or j >= grid.shape[2]:
            return False
        if grid[OCCUPIED, i, j] != 0:
            return False
    return True


@numba.njit(**_JIT)
def _viewpoint(
    grid: np.ndarray,
    lengths: np.ndarray,
    si: int,
    sj: int,
    radius: int,
    ti: float,
    tj: float,
    view_cells: float,
    factor: int,
) -> tuple[float, int, int]:
    """The reachable cell nearest by path within ``view_cells`` of (ti, tj) (fine cell
    units) that sees it: (path length, i, j), i = -1 when none."""
    reach = int(np.ceil(view_cells))
    side = 2 * radius + 1
    best, best_i, best_j = np.inf, -1, -1
    for a in range(int(ti) - reach, int(ti) + reach + 1):
        for b in range(int(tj) - reach, int(tj) + reach + 1):
            la, lb = a - si + radius, b - sj + radius
            if la < 0 or lb < 0 or la >= side or lb >= side:
                continue
            length = lengths[la, lb]
            if length < 0 or length >= best:
                continue
            if (a + 0.5 - ti) ** 2 + (b + 0.5 - tj) ** 2 > view_cells * view_cells:
                continue
            if not _clear_line(grid, a + 0.5, b + 0.5, ti, tj, 0.5 * factor):
                continue
            best, best_i, best_j = length, a, b
    return best, best_i, best_j


@numba.njit(**_JIT)
def find_candidates(
    grid: np.ndarray,
    coarse: np.ndarray,
    factor: int,
    origin: np.ndarray,
    cell_m: float,
    pose: np.ndarray,
    radius: int,
    inflate: int,
    cluster_cells: int,
    min_targets: int,
    view_m: float,
    frontier_m: float,
    done: np.ndarray,
    lengths: np.ndarray,
    table: np.ndarray,
    viewpoints: np.ndarray,
    centres: np.ndarray,
    clusters: np.ndarray,
) -> int:
    """The candidates of one agent (module docstring), nearest by path first.

    Args:
        grid: the agent's fine world grid.
        coarse: its far grid.
        factor: far cell side in fine cells.
        origin: world (x, y) of the fine grid's corner.
        cell_m: fine cell side.
        pose: (4, 4) camera-to-world.
        radius: search radius around the agent, fine cells.
        inflate: cells around an obstacle the planner keeps out of.
        cluster_cells: cluster side in far cells.
        min_targets: fewest targets a cluster needs.
        view_m: farthest a viewpoint may be from its cluster's centre.
        frontier_m: the same for a cluster of free-space edges only (when it has one).
        done: (clusters a side, clusters a side) bool: clusters already viewed.
        lengths: (2 radius + 1)^2 float scratch (path lengths).
        table: (N, len(CANDIDATE_FEATURES)) float32 output (or fewer columns: the first
            ones).
        viewpoints: (N, 2) world (x, y) output: each candidate's viewpoint.
        centres: (N, 2) world (x, y) output: each candidate's cluster centre.
        clusters: (N, 2) int64 output: each candidate's cluster index.

    Returns:
        The number of candidates (the first rows of the outputs; the rest are zero).
    """
    table[:] = 0.0
    viewpoints[:] = 0.0
    centres[:] = 0.0
    clusters[:] = -1
    px, py = pose[0, 3], pose[1, 3]
    si = int(np.floor((px - origin[0]) / cell_m))
    sj = int(np.floor((py - origin[1]) / cell_m))
    path_lengths(grid, si, sj, radius, inflate, lengths)
    fx, fy = pose[0, 2], pose[1, 2]
    if fx * fx + fy * fy < 1e-12:
        fx, fy = -pose[0, 1], -pose[1, 1]
    heading = np.arctan2(fy, fx)
    # Clusters within the search window (far cells), in the world frame of the grid.
    low_i = max((si - radius) // factor, 0)
    low_j = max((sj - radius) // factor, 0)
    high_i = min((si + radius) // factor + 1, coarse.shape[1])
    high_j = min((sj + radius) // factor + 1, coarse.shape[2])
    c_low_i, c_low_j = low_i // cluster_cells, low_j // cluster_cells
    c_high_i = (high_i - 1) // cluster_cells + 1
    c_high_j = (high_j - 1) // cluster_cells + 1
    ni, nj = c_high_i - c_low_i, c_high_j - c_low_j
    counts = np.zeros((ni, nj), np.int64)
    unseen = np.zeros((ni, nj), np.int64)
    sum_i = np.zeros((ni, nj))
    sum_j = np.zeros((ni, nj))
    for a in range(low_i, high_i):
        for b in range(low_j, high_j):
            occupied = coarse[OCCUPIED, a, b] != 0
            target = False
            if occupied:
                if coarse[SEEN, a, b] == 0:
                    target = True
            elif coarse[FREE, a, b] != 0:
                target = (
                    is_unknown(coarse, a - 1, b)
                    or is_unknown(coarse, a + 1, b)
                    or is_unknown(coarse, a, b - 1)
                    or is_unknown(coarse, a, b + 1)
                )
            if not target:
                continue
            ci, cj = a // cluster_cells - c_low_i, b // cluster_cells - c_low_j
            counts[ci, cj] += 1
            unseen[ci, cj] += 1 if occupied else 0
            sum_i[ci, cj] += a + 0.5
            sum_j[ci, cj] += b + 0.5
    capacity = table.shape[0]
    found = 0
    # Candidates kept sorted by path length (insertion into the first ``capacity`` rows).
    best_lengths = np.full(capacity, np.inf)
    view_cells = view_m / cell_m
    for ci in range(ni):
        for cj in range(nj):
            if counts[ci, cj] < min_targets:
                continue
            gi, gj = ci + c_low_i, cj + c_low_j
            if gi < done.shape[0] and gj < done.shape[1] and done[gi, gj]:
                continue
            # Centre of the cluster's targets, fine cell units.
            ti = sum_i[ci, cj] / counts[ci, cj] * factor
            tj = sum_j[ci, cj] / counts[ci, cj] * factor
            # A free-space edge is walked up to (seeing past a doorway needs standing in
            # it); an unseen obstacle is viewed from up to ``view_m`` away.
            near = frontier_m / cell_m if unseen[ci, cj] == 0 else view_cells
            best, best_i, best_j = _viewpoint(grid, lengths, si, sj, radius, ti, tj, near, factor)
            if best_i < 0 and near < view_cells:
                best, best_i, best_j = _viewpoint(
                    grid, lengths, si, sj, radius, ti, tj, view_cells, factor
                )
            if best_i < 0:
                continue
            # Insert into the sorted rows.
            row = min(found, capacity)
            while row > 0 and best_lengths[row - 1] > best:
                row -= 1
            if row >= capacity:
                continue
            last = min(found, capacity - 1)
            for k in range(last, row, -1):
                best_lengths[k] = best_lengths[k - 1]
                table[k] = table[k - 1]
                viewpoints[k] = viewpoints[k - 1]
                centres[k] = centres[k - 1]
                clusters[k] = clusters[k - 1]
            best_lengths[row] = best
            cx = origin[0] + ti * cell_m
            cy = origin[1] + tj * cell_m
            bearing = np.arctan2(cy - py, cx - px) - heading
            table[row, 0] = 1.0
            table[row, 1] = best * cell_m / 10.0
            table[row, 2] = np.sqrt((cx - px) ** 2 + (cy - py) ** 2) / 10.0
            table[row, 3] = np.sin(bearing)
            table[row, 4] = np.cos(bearing)
            table[row, 5] = counts[ci, cj] / (cluster_cells * cluster_cells)
            table[row, 6] = unseen[ci, cj] / counts[ci, cj]
            if table.shape[1] > 7:
                agent_i, agent_j = (px - origin[0]) / cell_m, (py - origin[1]) / cell_m
                seen = _clear_line(grid, agent_i, agent_j, best_i + 0.5, best_j + 0.5, 0.0)
                table[row, 7] = 0.0 if seen else 1.0
            viewpoints[row, 0] = origin[0] + (best_i + 0.5) * cell_m
            viewpoints[row, 1] = origin[1] + (best_j + 0.5) * cell_m
            centres[row, 0] = cx
            centres[row, 1] = cy
            clusters[row, 0] = gi
            clusters[row, 1] = gj
            found = min(found + 1, capacity)
    return found


@numba.njit(**_JIT)
def wander_goal(
    grid: np.ndarray,
    coarse: np.ndarray,
    factor: int,
    lengths: np.ndarray,
    si: int,
    sj: int,
    radius: int,
    stride: int,
) -> tuple[int, int]:
    """The reachable cell (``lengths`` from :func:`path_lengths` around ``(si, sj)``) farthest
    from every cell the agent stood in (its trail), every ``stride``-th cell looked at: where
    an agent with no candidate left sees the rooms from a new place. Only cells whose far
    cell holds surface the camera saw (a floor under it: inside an open scan's scanned
    space, not past its edge) qualify. (-1, -1) when none."""
    side = 2 * radius + 1
    trail_i = np.empty(side * side, np.int64)
    trail_j = np.empty(side * side, np.int64)
    count = 0
    for a in range(0, side, 2):
        for b in range(0, side, 2):
            i, j = si + a - radius, sj + b - radius
            if 0 <= i < grid.shape[1] and 0 <= j < grid.shape[2] and grid[TRAIL, i, j] != 0:
                trail_i[count], trail_j[count] = i, j
                count += 1
    best, best_i, best_j = -1.0, -1, -1
    for a in range(0, side, stride):
        for b in range(0, side, stride):
            if lengths[a, b] <= 0:
                continue
            i, j = si + a - radius, sj + b - radius
            if coarse[SEEN, i // factor, j // factor] == 0:
                continue
            nearest = 1e18
            for k in range(count):
                d = (trail_i[k] - i) ** 2 + (trail_j[k] - j) ** 2
                if d < nearest:
                    nearest = d
            if nearest > best:
                best, best_i, best_j = nearest, i, j
    return best_i, best_j


def reachable_cells(
    lengths: np.ndarray, coarse: np.ndarray, factor: int, si: int, sj: int, radius: int
) -> tuple[np.ndarray, np.ndarray]:
    """The cells ``lengths`` (from :func:`path_lengths` around ``(si, sj)``) reaches whose far
    cell holds surface the camera saw (a floor under it: inside an open scan's scanned
    space), ``(n, 2)`` grid indices, and their path lengths (cells)."""
    a, b = np.nonzero(lengths > 0)
    cells = np.stack([si + a - radius, sj + b - radius], axis=1)
    seen = coarse[SEEN, cells[:, 0] // factor, cells[:, 1] // factor] != 0
    return cells[seen], lengths[a, b][seen]


def candidate_surroundings(
    coarse: np.ndarray,
    origin: np.ndarray,
    far_cell_m: float,
    centres: np.ndarray,
    radii_m: tuple[float, ...] = SURROUNDING_RADII_M,
) -> np.ndarray:
    """What lies around each candidate's cluster on the far map: per radius, the share of the
    square of that half side around the cluster's centre that is *targets* (unseen obstacles
    and free cells beside unknown ones, as :func:`find_candidates` counts them) and the
    share that is unknown (neither free nor occupied; outside the map counts as unknown).
    The table's ``size`` describes the cluster alone (0.8 m); these say how much is left to
    see beyond it.

    Args:
        coarse: one agent's far grid ``(layers, rows, columns)``.
        origin: world (x, y) of the grid's corner.
        far_cell_m: side of a far cell.
        centres: ``(n, 2)`` world (x, y) of the candidates' cluster centres.
        radii_m: half sides of the squares, metres.

    Returns:
        ``(n, 2 * len(radii_m))`` float32: per radius, the targets' share, then the unknown
        share.
    """
    occupied = coarse[OCCUPIED] != 0
    free = (coarse[FREE] != 0) & ~occupied
    unknown = ~occupied & (coarse[FREE] == 0)
    padded = np.pad(unknown, 1, constant_values=True)
    beside_unknown = padded[:-2, 1:-1] | padded[2:, 1:-1] | padded[1:-1, :-2] | padded[1:-1, 2:]
    targets = (occupied & (coarse[SEEN] == 0)) | (free & beside_unknown)
    rows, columns = unknown.shape
    out = np.zeros((len(centres), 2 * len(radii_m)), np.float32)
    sums = []
    for layer in (targets, unknown):
        integral = np.zeros((rows + 1, columns + 1), np.int64)
        integral[1:, 1:] = layer.cumsum(0).cumsum(1)
        sums.append(integral)
    cells = np.floor((np.asarray(centres, np.float64) - origin[:2]) / far_cell_m).astype(np.int64)
    for k, radius_m in enumerate(radii_m):
        half = max(int(round(radius_m / far_cell_m)), 1)
        area = (2 * half + 1) ** 2
        for n, (i, j) in enumerate(cells):
            i0, i1 = max(i - half, 0), min(i + half + 1, rows)
            j0, j1 = max(j - half, 0), min(j + half + 1, columns)
            inside = max(i1 - i0, 0) * max(j1 - j0, 0)
            for column, integral in enumerate(sums):
                count = 0
                if inside:
                    count = (
                        integral[i1, j1] - integral[i0, j1] - integral[i1, j0] + integral[i0, j0]
                    )
                if column == 1:  # cells of the square outside the map are unknown
                    count += area - inside
                out[n, 2 * k + column] = count / area
    return out
