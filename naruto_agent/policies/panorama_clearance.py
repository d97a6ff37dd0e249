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
