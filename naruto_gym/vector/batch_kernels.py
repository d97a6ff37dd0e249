"""Compiled loops over the agents of a batch: ray buffers, coverage and move sweeps.

Each loop calls the single agent's kernel (the one the single env uses), so a batch of agents
gets bit-identical rays, coverage and moves to the same agents stepped one by one.
"""

from __future__ import annotations

import numba
import numpy as np

from naruto_gym.coverage import mark_visible_in_cells
from naruto_gym.geometry.sweep_kernels import (
    first_blocked_sample,
    fraction_inside_box,
    sweep_step_count,
)
from naruto_gym.sensors.kernels import fill_world_rays


@numba.njit(cache=True, nogil=True)
def fill_pinhole_rays(
    camera_directions: np.ndarray, poses: np.ndarray, rays: np.ndarray, offset: int
) -> None:
    """Write every agent's pinhole rays into ``rays[offset:]`` ((N * P, 6) float32 block).

    Args:
        camera_directions: (P, 3) float32 camera-frame pixel directions (z = 1).
        poses: (N, 4, 4) float32 camera-to-world poses.
        rays: float32 ray buffer, agent ``i`` at ``offset + i * P``.
        offset: first row of the block.
    """
    pixels = camera_directions.shape[0]
    for i in range(poses.shape[0]):
        start = offset + i * pixels
        fill_world_rays(
            camera_directions,
            np.ascontiguousarray(poses[i, :3, :3]),
            np.ascontiguousarray(poses[i, :3, 3]),
            rays[start : start + pixels],
        )


@numba.njit(cache=True, nogil=True)
def mark_visible_batch(
    samples_world: np.ndarray,
    order: np.ndarray,
    starts: np.ndarray,
    centres: np.ndarray,
    radii: np.ndarray,
    seen: np.ndarray,
    unseen_in_cell: np.ndarray,
    agents: np.ndarray,
    poses: np.ndarray,
    intrinsics: np.ndarray,
    depth: np.ndarray,
    max_range_m: float,
    tolerance_m: float,
    added: np.ndarray,
) -> None:
    """:func:`naruto_gym.coverage.mark_visible_in_cells` for the agents ``agents`` of one
    scene, in place in the batch's arrays (no per-agent copies).

    Args:
        samples_world: (M, 3) float64 surface samples of the scene.
        order, starts, centres, radii: the samples' cells (``CoverageTracker.cells``).
        seen: (N, >= M) bool seen flags of all agents (row per agent), updated in place.
        unseen_in_cell: (N, >= C) int64 unseen samples per cell of all agents, likewise.
        agents: (K,) int64 rows of the agents to update.
        poses: (N, 4, 4) float64 poses of all agents.
        intrinsics: (6,) float64 ``(width, height, fx, fy, cx, cy)``.
        depth: (N, H, W) float32 depth frames of all agents.
        max_range_m, tolerance_m: as the single agent's kernel.
        added: (K,) int64 output, samples newly seen by each of ``agents``.
    """
    for k in range(agents.shape[0]):
        agent = agents[k]
        added[k] = mark_visible_in_cells(
            samples_world,
            order,
            starts,
            centres,
            radii,
            seen[agent],
            unseen_in_cell[agent],
            poses[agent],
            intrinsics,
            depth[agent],
            max_range_m,
            tolerance_m,
        )


@numba.njit(cache=True, nogil=True)
def no_hit_counts(distance: np.ndarray, offset: int, per_agent: int, agents: int) -> np.ndarray:
    """Rays without a (positive, finite) hit per agent in ``distance[offset:]``.

    A panorama pixel counts as empty when its ray hits nothing, like a 0 in
    :func:`naruto_gym.sensors.panorama.render_panorama`.
    """
    counts = np.zeros(agents, np.int64)
    for i in range(agents):
        start = offset + i * per_agent
        for k in range(per_agent):
            value = distance[start + k]
            if not (value > 0.0 and value < np.inf):
                counts[i] += 1
    return counts


@numba.njit(cache=True, nogil=True)
def plan_sweeps(
    starts: np.ndarray,
    targets: np.ndarray,
    box_min: np.ndarray,
    box_max: np.ndarray,
    start_clearances: np.ndarray,
    radius_m: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The box clip and sweep samples of N moves, as the single env's checker makes them
    (:func:`~naruto_gym.geometry.sweep_kernels.fraction_inside_box`, then the samples of
    :func:`~naruto_gym.sensors.raycaster.segment_samples` with the clearance the checker
    gives a start closer than its radius), the same numbers for every move.

    Returns:
        ``box`` (N,) fraction inside the box, ``ends`` (N, 3), ``clearances`` (N,),
        ``lengths`` (N,), ``offsets`` (N + 1,) (move ``i``'s samples are
        ``offsets[i]:offsets[i + 1]``), ``fractions`` and ``points`` (S,) / (S, 3).
    """
    count = starts.shape[0]
    box = np.ones(count)
    ends = np.empty((count, 3))
    clearances = np.empty(count)
    lengths = np.empty(count)
    offsets = np.zeros(count + 1, np.int64)
    steps = np.empty(count, np.int64)
    for i in range(count):
        box[i] = fraction_inside_box(starts[i], targets[i], box_min, box_max)
        squared = 0.0
        for axis in range(3):
            ends[i, axis] = starts[i, axis] + box[i] * (targets[i, axis] - starts[i, axis])
            delta = ends[i, axis] - starts[i, axis]
            squared += delta * delta
        lengths[i] = np.sqrt(squared)
        clearances[i] = max(min(radius_m, start_clearances[i] - 1e-4), 0.0)
        steps[i] = sweep_step_count(lengths[i], clearances[i])
        offsets[i + 1] = offsets[i] + steps[i] + 1
    fractions = np.empty(offsets[count])
    points = np.empty((offsets[count], 3))
    for i in range(count):
        # np.linspace(0, 1, steps + 1): k * (1 / steps), the last exactly 1.
        spacing = 1.0 / steps[i]
        for k in range(steps[i] + 1):
            sample = offsets[i] + k
            fractions[sample] = 1.0 if k == steps[i] else k * spacing
            for axis in range(3):
                points[sample, axis] = starts[i, axis] + fractions[sample] * (
                    ends[i, axis] - starts[i, axis]
                )
    return box, ends, clearances, lengths, offsets, fractions, points


# Slack (metres) on the distance bound below: far above the float32 rounding of the queried
# distances and coordinates (about 1e-6 m across a room).
PROVABLY_CLEAR_SLACK_M = 1e-4


@numba.njit(cache=True, nogil=True)
def sweep_distance_queries(
    start_clearances: np.ndarray,
    offsets: np.ndarray,
    fractions: np.ndarray,
    lengths: np.ndarray,
    clearances: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Which sweep samples (:func:`plan_sweeps`) need a distance query, and the distances
    known without one.

    A sample's distance to the surface is at least its start's less how far it lies from the
    start (a distance field changes no faster than the point moves), so a sample whose bound
    clears the sweep's clearance by ``PROVABLY_CLEAR_SLACK_M`` is free whatever its exact
    distance: it gets ``inf``, which :func:`sweep_stops` finds free alike. The first sample
    is the start, whose distance is known; the last is always queried, as where a sweep stops
    its exact distance is wanted (:func:`sweep_stops` returns it).

    Returns:
        ``needed`` (S,) bool and ``distances`` (S,) float32 (meaningful where not needed).
    """
    needed = np.zeros(fractions.shape[0], np.bool_)
    distances = np.full(fractions.shape[0], np.inf, np.float32)
    for i in range(lengths.shape[0]):
        begin, end = offsets[i], offsets[i + 1]
        distances[begin] = start_clearances[i]
        for sample in range(begin + 1, end):
            bound = np.float64(start_clearances[i]) - fractions[sample] * lengths[i]
            needed[sample] = sample == end - 1 or not (
                bound >= clearances[i] + PROVABLY_CLEAR_SLACK_M
            )
    return needed, distances


@numba.njit(cache=True, nogil=True)
def sweep_stops(
    fractions: np.ndarray,
    offsets: np.ndarray,
    lengths: np.ndarray,
    distances: np.ndarray,
    walls: np.ndarray,
    clearances: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Where each of N sweeps (:func:`plan_sweeps`) stops and the surface distance there:
    :func:`~naruto_gym.sensors.raycaster.sweep_stop_from_distances` move by move, with the
    same :func:`~naruto_gym.geometry.sweep_kernels.first_blocked_sample` (the last free
    sample's fraction, 1 when all are free; nan as the clearance of a stop at 0)."""
    count = lengths.shape[0]
    stops = np.empty(count)
    stop_clearances = np.empty(count)
    for i in range(count):
        begin, end = offsets[i], offsets[i + 1]
        # The distances are float32, and numpy compares them with a float in float32.
        first_blocked = first_blocked_sample(
            fractions[begin:end],
            lengths[i],
            distances[begin:end],
            walls[i],
            clearances[i],
            np.float32(clearances[i]),
        )
        last_free = offsets[i + 1] - 1 if first_blocked == -1 else offsets[i] + first_blocked - 1
        stops[i] = 0.0 if first_blocked == 0 else fractions[last_free]
        # A sweep that cannot leave its start (stop 0) has no stop clearance.
        stop_clearances[i] = distances[last_free] if stops[i] > 0.0 else np.nan
    return stops, stop_clearances
