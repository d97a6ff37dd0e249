"""Equirectangular depth panorama: radial distance all around the agent.

The panorama is aligned with the world, not the camera: column ``u`` looks at azimuth
``-pi + 2 pi (u + 0.5) / W`` (counter-clockwise from world +x), row ``v`` at elevation
``pi / 2 - pi (v + 0.5) / H`` (row 0 looks up). Distances are radial, in metres, 0 where the ray
hits nothing. The share of such pixels tells whether the agent stands inside a closed scene
(the published system refuses moves that see more than 50 % of no-hit pixels).

A camera with ``horizon_deg`` casts only the rows within that elevation of the horizon (a
user that reads only near-horizontal rows, such as a top-down map at the agent's height, pays
for those alone); the other rows read 0, as rays that hit nothing, and the rows it casts are
the full panorama's rows, to the bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from naruto_gym.sensors.raycaster import RayCaster


@dataclass(frozen=True)
class EquirectangularCamera:
    """Size of an equirectangular panorama (the published system used 1024 x 2048), and the
    rows it casts: all, or with ``horizon_deg`` those within that many degrees of elevation of
    the horizon (the others read 0)."""

    height: int = 128
    width: int = 256
    horizon_deg: float | None = None

    def __post_init__(self) -> None:
        if self.height <= 0 or self.width <= 0:
            raise ValueError(f"panorama size must be positive, got {self.height} x {self.width}")
        if self.horizon_deg is not None:
            degrees = self.horizon_deg
            if (
                isinstance(degrees, bool)
                or not isinstance(degrees, (int, float, np.integer, np.floating))
                or not 0.0 < float(degrees) <= 90.0
            ):
                raise ValueError(
                    f"panorama horizon_deg must be a number in (0, 90] (None casts every row), "
                    f"got {degrees!r}"
                )
            if self.cast_rows[0] == self.cast_rows[1]:
                raise ValueError(
                    f"panorama horizon_deg={degrees!r} keeps no row of a {self.height}-row "
                    f"panorama (its rows lie {180.0 / self.height:.2f} degrees apart, the "
                    f"nearest {np.rad2deg(np.abs(self.row_elevations).min()):.2f} degrees from "
                    "the horizon): pass a wider band or more rows"
                )

    @cached_property
    def row_elevations(self) -> np.ndarray:
        """(H,) each row's elevation in radians (row 0 looks up)."""
        return np.pi / 2.0 - np.pi * (np.arange(self.height) + 0.5) / self.height

    @cached_property
    def cast_rows(self) -> tuple[int, int]:
        """``(start, stop)``: the rows cast, every row when ``horizon_deg`` is None, else
        those whose elevation lies within ``horizon_deg`` of the horizon ((k, k) when none
        does)."""
        if self.horizon_deg is None:
            return 0, self.height
        near = np.flatnonzero(np.abs(self.row_elevations) <= np.deg2rad(self.horizon_deg))
        if len(near) == 0:
            middle = self.height // 2
            return middle, middle
        return int(near.min()), int(near.max()) + 1

    @cached_property
    def cast_directions(self) -> np.ndarray:
        """(rows cast * W, 3) float32: the rows of :attr:`ray_directions` that are cast."""
        start, stop = self.cast_rows
        return self.ray_directions[start * self.width : stop * self.width]

    def keep_cast_rows(self, panorama: np.ndarray) -> np.ndarray:
        """``panorama`` (``(..., H, W)``, e.g. a full one) as this camera gives it: a copy with
        the rows it does not cast set to 0. A user trained on the band (a policy) sees the
        same input from an env that casts every row."""
        start, stop = self.cast_rows
        kept = np.zeros_like(np.asarray(panorama))
        kept[..., start:stop, :] = np.asarray(panorama)[..., start:stop, :]
        return kept

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
    """(H, W) float32 radial distance from ``position``, 0 where a ray hits nothing (and on
    the rows the camera does not cast)."""
    distance = raycaster.cast_distance(np.asarray(position, np.float32), camera.cast_directions)
    distance = np.where(np.isfinite(distance), distance, 0.0).astype(np.float32)
    start, stop = camera.cast_rows
    if (start, stop) == (0, camera.height):
        return distance.reshape(camera.height, camera.width)
    panorama = np.zeros((camera.height, camera.width), np.float32)
    panorama[start:stop] = distance.reshape(stop - start, camera.width)
    return panorama


def no_hit_share(panorama: np.ndarray) -> float:
    """Share of panorama pixels whose ray hit nothing (0 = fully enclosed); pass the rows the
    camera casts (``panorama[slice(*camera.cast_rows)]``)."""
    return float(np.mean(panorama <= 0.0))
