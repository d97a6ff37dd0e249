"""The egocentric frame of a top-down map crop: the agent at the centre of a ``cells`` x
``cells`` image, its heading (optical axis in the horizontal plane) pointing up the image.
Compiled helpers shared by the kernels that resample a world grid into such a crop."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def heading_axes(pose: np.ndarray) -> tuple[float, float, float, float]:
    """The unit heading ``(fx, fy)`` of a camera-to-world pose (its optical axis in the
    horizontal plane; straight down or up, its image up axis instead) and the image's right
    ``(rx, ry)``: the heading turned clockwise, seen from above."""
    fx, fy = pose[0, 2], pose[1, 2]
    norm = np.sqrt(fx * fx + fy * fy)
    if norm < 1e-6:
        fx, fy = -pose[0, 1], -pose[1, 1]
        norm = np.sqrt(fx * fx + fy * fy)
    fx, fy = fx / norm, fy / norm
    return fx, fy, fy, -fx


@numba.njit(cache=True, nogil=True)
def crop_cell(
    pose: np.ndarray,
    axes: tuple[float, float, float, float],
    origin_x: float,
    origin_y: float,
    cell_m: float,
    cells: int,
    r: int,
    c: int,
) -> tuple[int, int]:
    """The world-grid cell (``origin`` its corner, cells of ``cell_m``) under pixel ``(r, c)``
    of the crop (row 0 ahead of the agent); out of the grid's range where the crop leaves it."""
    fx, fy, rx, ry = axes
    half = cells / 2.0
    ahead = (half - r - 0.5) * cell_m
    right = (c + 0.5 - half) * cell_m
    i = int(np.floor((pose[0, 3] + ahead * fx + right * rx - origin_x) / cell_m))
    j = int(np.floor((pose[1, 3] + ahead * fy + right * ry - origin_y) / cell_m))
    return i, j
