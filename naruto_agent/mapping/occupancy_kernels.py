"""Numba kernel of :meth:`OccupancyGrid.sectors_seen_below` (a policy's mirror of the env's
scanned-space support test, on its own occupancy grid)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def empty_sectors_below(
    points: np.ndarray,
    directions: np.ndarray,
    sectors: np.ndarray,
    sector_count: int,
    occupied: np.ndarray,
    origin: np.ndarray,
    voxel: float,
    max_length: float,
) -> np.ndarray:
    """(N,) number of sectors none of whose rays meets an occupied voxel within
    ``max_length`` (rays marched every half voxel from each point; outside the grid a ray
    meets nothing)."""
    out = np.zeros(points.shape[0], np.int64)
    nx, ny, nz = occupied.shape
    step = 0.5 * voxel
    count = int(math.ceil(max_length / step))
    for i in range(points.shape[0]):
        seen = np.zeros(sector_count, np.bool_)
        for r in range(directions.shape[0]):
            sector = sectors[r]
            if seen[sector]:
                continue
            for k in range(1, count + 1):
                x = points[i, 0] + k * step * directions[r, 0]
                y = points[i, 1] + k * step * directions[r, 1]
                z = points[i, 2] + k * step * directions[r, 2]
                cx = int(math.floor((x - origin[0]) / voxel))
                cy = int(math.floor((y - origin[1]) / voxel))
                cz = int(math.floor((z - origin[2]) / voxel))
                if cx < 0 or cy < 0 or cz < 0 or cx >= nx or cy >= ny or cz >= nz:
                    break
                if occupied[cx, cy, cz]:
                    seen[sector] = True
                    break
        empty = 0
        for s in range(sector_count):
            if not seen[s]:
                empty += 1
        out[i] = empty
    return out
