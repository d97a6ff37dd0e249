"""Compiled loops over the agents of a batch: ray buffers and coverage.

Each loop calls the single agent's kernel (the one the single env uses), so a batch of agents
gets bit-identical rays and coverage to the same agents stepped one by one.
"""

from __future__ import annotations

import numba
import numpy as np

from naruto_gym.coverage import mark_visible_samples
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
            rays[start:start + pixels],
        )


@numba.njit(cache=True, nogil=True)
def fill_panorama_rays(
    directions: np.ndarray, positions: np.ndarray, rays: np.ndarray, offset: int
) -> None:
    """Write world-aligned panorama rays of every position into ``rays[offset:]``.

    Args:
        directions: (P, 3) float32 unit world directions.
        positions: (N, 3) float32 ray origins.
        rays: float32 ray buffer, position ``i`` at ``offset + i * P``.
        offset: first row of the block.
    """
    count = directions.shape[0]
    for i in range(positions.shape[0]):
        start = offset + i * count
        for k in range(count):
            rays[start + k, 0] = positions[i, 0]
            rays[start + k, 1] = positions[i, 1]
            rays[start + k, 2] = positions[i, 2]
            rays[start + k, 3] = directions[k, 0]
            rays[start + k, 4] = directions[k, 1]
            rays[start + k, 5] = directions[k, 2]


@numba.njit(cache=True, nogil=True)
def mark_visible_batch(
    samples_world: np.ndarray,
    seen: np.ndarray,
    poses: np.ndarray,
    intrinsics: np.ndarray,
    depth: np.ndarray,
    max_range_m: float,
    tolerance_m: float,
    added: np.ndarray,
) -> None:
    """:func:`naruto_gym.coverage.mark_visible_samples` for N agents in one scene.

    Args:
        samples_world: (M, 3) float64 surface samples of the scene.
        seen: (N, M) bool per-agent seen flags, updated in place.
        poses: (N, 4, 4) float64 poses.
        intrinsics: (6,) float64 ``(width, height, fx, fy, cx, cy)``.
        depth: (N, H, W) float32 depth frames.
        max_range_m, tolerance_m: as the single agent's kernel.
        added: (N,) int64 output, samples newly seen by each agent.
    """
    for i in range(poses.shape[0]):
        added[i] = mark_visible_samples(
            samples_world, seen[i], poses[i], intrinsics, depth[i], max_range_m, tolerance_m
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
