"""Collision handling of the agent, a sphere carrying the camera.

A move is checked along its whole segment against the ground-truth mesh (never against a
map), clipped to the scene bounds, and refused when the new position would see mostly
nothing around it (an agent slipping out of a scan with holes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from naruto_gym.sensors.panorama import EquirectangularCamera, no_hit_share, render_panorama
from naruto_gym.sensors.raycaster import RayCaster


@dataclass(frozen=True)
class MoveResult:
    """Where a move ended and why it stopped short."""

    position: np.ndarray
    collided: bool
    reason: str  # "", "surface", "bounds" or "escape"


def segment_fraction_inside_box(
    start: np.ndarray, end: np.ndarray, box_min: np.ndarray, box_max: np.ndarray
) -> float:
    """Largest t in [0, 1] with start + t (end - start) inside the box (start assumed inside)."""
    delta = end - start
    fraction = 1.0
    for axis in range(3):
        if delta[axis] > 0 and end[axis] > box_max[axis]:
            fraction = min(fraction, (box_max[axis] - start[axis]) / delta[axis])
        elif delta[axis] < 0 and end[axis] < box_min[axis]:
            fraction = min(fraction, (box_min[axis] - start[axis]) / delta[axis])
    return float(np.clip(fraction, 0.0, 1.0))


class CollisionChecker:
    """Moves a sphere of ``radius_m`` through a scene without touching its surfaces.

    Args:
        raycaster: the ground-truth scene.
        bounds: (2, 3) scene bounds; the sphere's centre stays ``radius_m`` inside them.
        radius_m: agent radius (0.05 m in the published system).
        escape_no_hit_threshold: refuse a move whose end sees more than this share of
            no-hit panorama pixels (0.5 in the published system); None switches it off.
        escape_panorama: the (small) panorama used for that check.
    """

    def __init__(
        self,
        raycaster: RayCaster,
        bounds: np.ndarray,
        radius_m: float = 0.05,
        escape_no_hit_threshold: float | None = 0.5,
        escape_panorama: EquirectangularCamera | None = None,
    ) -> None:
        if radius_m <= 0:
            raise ValueError(f"agent radius must be positive, got {radius_m}")
        self.raycaster = raycaster
        self.radius_m = float(radius_m)
        self.box_min = np.asarray(bounds[0], np.float64) + radius_m
        self.box_max = np.asarray(bounds[1], np.float64) - radius_m
        self.escape_no_hit_threshold = escape_no_hit_threshold
        self.escape_panorama = escape_panorama or EquirectangularCamera(32, 64)

    def clearance(self, position: np.ndarray) -> float:
        """Distance from ``position`` to the nearest surface, metres."""
        return float(self.raycaster.unsigned_distance(np.asarray(position)[None])[0])

    def inside_bounds(self, position: np.ndarray) -> bool:
        return bool(np.all(position >= self.box_min) and np.all(position <= self.box_max))

    def sees_escape(self, position: np.ndarray) -> bool:
        """True when ``position`` sees more no-hit pixels than the escape threshold allows."""
        if self.escape_no_hit_threshold is None:
            return False
        panorama = render_panorama(self.raycaster, self.escape_panorama, position)
        return no_hit_share(panorama) > self.escape_no_hit_threshold

    def move(self, start: np.ndarray, target: np.ndarray) -> MoveResult:
        """Move from ``start`` towards ``target`` as far as the sphere fits."""
        start = np.asarray(start, np.float64)
        target = np.asarray(target, np.float64)
        if np.allclose(start, target):
            return MoveResult(start.copy(), False, "")
        box_fraction = segment_fraction_inside_box(start, target, self.box_min, self.box_max)
        end = start + box_fraction * (target - start)
        # From a start already closer than the radius (an exact start pose), the sphere may
        # move on as long as it gets no closer than it already is.
        clearance = min(self.radius_m, self.clearance(start) - 1e-4)
        surface_fraction = self.raycaster.free_fraction_of_segment(start, end, max(clearance, 0))
        position = start + surface_fraction * (end - start)
        if surface_fraction < 1.0:
            reason = "surface"
        elif box_fraction < 1.0:
            reason = "bounds"
        else:
            reason = ""
        if not np.allclose(position, start) and self.sees_escape(position):
            return MoveResult(start.copy(), True, "escape")
        return MoveResult(position, reason != "", reason)
