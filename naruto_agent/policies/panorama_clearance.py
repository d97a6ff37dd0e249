"""Free distance in a world direction, read from the env's equirectangular depth panorama.

The panorama observation is world-aligned (see ``naruto_gym.sensors.panorama``): it is what a
360-degree depth sensor on the agent reports, so reading obstacles from it is fair for a
policy. Scripted and reactive policies use it to check the way ahead before they move.
"""

from __future__ import annotations

import numpy as np

from naruto_gym.sensors.panorama import EquirectangularCamera


class PanoramaClearance:
    """Clearance queries on panoramas of one size.

    Args:
        cone_half_angle_deg: a direction's clearance is the nearest hit within this angle of
            it (the agent's body sweeps a cone-shaped neighbourhood of its heading).
    """

    def __init__(self, cone_half_angle_deg: float = 25.0) -> None:
        self.cos_half_angle = float(np.cos(np.deg2rad(cone_half_angle_deg)))
        self._shape: tuple[int, int] | None = None
        self._directions = np.zeros((0, 3), np.float32)

    def _directions_for(self, panorama: np.ndarray) -> np.ndarray:
        shape = tuple(panorama.shape)
        if shape != self._shape:
            if len(shape) != 2:
                raise ValueError(f"panorama must be (H, W), got shape {shape}")
            self._directions = EquirectangularCamera(*shape).ray_directions
            self._shape = shape
        return self._directions

    def clearance(self, panorama: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Nearest hit distance within the cone around each direction (inf when none).

        Args:
            panorama: (H, W) radial distances, 0 where nothing was hit.
            directions: (K, 3) or (3,) world directions (need not be unit).

        Returns:
            (K,) clearances in metres.
        """
        directions = np.atleast_2d(np.asarray(directions, np.float64))
        norms = np.linalg.norm(directions, axis=1, keepdims=True)
        directions = directions / np.maximum(norms, 1e-12)
        rays = self._directions_for(panorama)
        distance = np.asarray(panorama, np.float64).reshape(-1)
        distance = np.where(distance > 0.0, distance, np.inf)
        inside = directions @ rays.T.astype(np.float64) >= self.cos_half_angle
        return np.where(inside, distance[None, :], np.inf).min(axis=1)


def horizontal_profile(
    panorama: np.ndarray, max_height_offset_m: float = 0.3, max_elevation_deg: float = 20.0
) -> np.ndarray:
    """Horizontal free distance per panorama column (azimuth) around the agent's height.

    Pixels within ``max_elevation_deg`` of the horizon whose hit lies within
    ``max_height_offset_m`` of the agent's height count; the result is, per column, the
    smallest horizontal distance of those (inf when none). Column ``u`` looks at azimuth
    ``-pi + 2 pi (u + 0.5) / W``.
    """
    panorama = np.asarray(panorama, np.float64)
    height, width = panorama.shape
    elevation = np.pi / 2.0 - np.pi * (np.arange(height) + 0.5) / height
    rows = np.abs(elevation) <= np.deg2rad(max_elevation_deg)
    distance = np.where(panorama[rows] > 0.0, panorama[rows], np.inf)
    horizontal = distance * np.cos(elevation[rows])[:, None]
    offset = np.abs(distance * np.sin(elevation[rows])[:, None])
    horizontal = np.where(offset <= max_height_offset_m, horizontal, np.inf)
    return horizontal.min(axis=0)


def profile_clearance(profile: np.ndarray, yaw: float, half_width_rad: float) -> float:
    """Smallest profile distance within ``half_width_rad`` of azimuth ``yaw``."""
    width = len(profile)
    azimuth = -np.pi + 2.0 * np.pi * (np.arange(width) + 0.5) / width
    difference = np.angle(np.exp(1j * (azimuth - yaw)))
    inside = np.abs(difference) <= half_width_rad
    return float(profile[inside].min()) if inside.any() else float("inf")
