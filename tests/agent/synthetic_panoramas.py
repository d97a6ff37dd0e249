"""Depth panoramas of simple synthetic scenes, for tests of what policies read from them."""

from __future__ import annotations

import numpy as np

from naruto_gym.sensors.panorama import EquirectangularCamera

SHAPE = (64, 128)


def _rays(shape: tuple[int, int]) -> np.ndarray:
    return EquirectangularCamera(*shape).ray_directions.astype(np.float64)


def floor_panorama(
    height_m: float = 1.0,
    edge_x_m: float = np.inf,
    hole_radius_m: float = 0.0,
    shape: tuple[int, int] = SHAPE,
) -> np.ndarray:
    """A floor ``height_m`` below the agent and nothing else; the floor ends ``edge_x_m``
    ahead along +x and has a hole of ``hole_radius_m`` straight below the agent."""
    rays = _rays(shape)
    down = rays[:, 2] < -1e-6
    distance = np.where(down, height_m / np.maximum(-rays[:, 2], 1e-6), 0.0)
    landing_x = distance * rays[:, 0]
    landing_r = distance * np.hypot(rays[:, 0], rays[:, 1])
    floor = down & (landing_x < edge_x_m) & (landing_r > hole_radius_m)
    return np.where(floor, distance, 0.0).reshape(shape).astype(np.float32)


def wall_panorama(
    wall_y_m: float, max_range_m: float = 10.0, shape: tuple[int, int] = SHAPE
) -> np.ndarray:
    """A plane wall at y = ``wall_y_m`` (< 0) relative to the agent, seen up to
    ``max_range_m``, and nothing else."""
    rays = _rays(shape)
    towards = rays[:, 1] < -1e-6
    distance = np.zeros(len(rays))
    distance[towards] = wall_y_m / rays[towards, 1]
    distance[distance > max_range_m] = 0.0
    return distance.reshape(shape).astype(np.float32)
