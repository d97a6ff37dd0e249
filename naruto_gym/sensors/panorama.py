"""Equirectangular depth panorama: radial distance all around the agent.

The panorama is aligned with the world, not the camera: column ``u`` looks at azimuth
``-pi + 2 pi (u + 0.5) / W`` (counter-clockwise from world +x), row ``v`` at elevation
``pi / 2 - pi (v + 0.5) / H`` (row 0 looks up). Distances are radial, in metres, 0 where the ray
hits nothing. The share of such pixels tells whether the agent stands inside a closed scene
(the published system refuses moves that see more than 50 % of no-hit pixels).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from naruto_gym.sensors.raycaster import RayCaster


@dataclass(frozen=True)
class EquirectangularCamera:
    """Size of an equirectangular panorama (the published system used 1024 x 2048)."""

    height: int = 128
    width: int = 256

    def __post_init__(self) -> None:
        if self.height <= 0 or self.width <= 0:
            raise ValueError(f"panorama size must be positive, got {self.height} x {self.width}")

    @cached_property
    def ray_directions(self) -> np.ndarray:
        """(H * W, 3) float32 unit world directions, row-major over (v, u)."""
        azimuth = -np.pi + 2.0 * np.pi * (np.arange(self.width) + 0.5) / self.width
        elevation = np.pi / 2.0 - np.pi * (np.arange(self.height) + 0.5) / self.height
        azimuth, elevation = np.meshgrid(azimuth, elevation)
        directions = np.stack(
            [
                np.cos(elevation) * np.cos(azimuth),
                np.cos(elevation) * np.sin(azimuth),
                np.sin(elevation),
            ],
            axis=-1,
        )
        return directions.reshape(-1, 3).astype(np.float32)


def render_panorama(
    raycaster: RayCaster, camera: EquirectangularCamera, position: np.ndarray
) -> np.ndarray:
    """(H, W) float32 radial distance from ``position``, 0 where a ray hits nothing."""
    distance = raycaster.cast_distance(np.asarray(position, np.float32), camera.ray_directions)
    distance = np.where(np.isfinite(distance), distance, 0.0).astype(np.float32)
    return distance.reshape(camera.height, camera.width)


def no_hit_share(panorama: np.ndarray) -> float:
    """Share of panorama pixels whose ray hit nothing (0 = fully enclosed)."""
    return float(np.mean(panorama <= 0.0))
