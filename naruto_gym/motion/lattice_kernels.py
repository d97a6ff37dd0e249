"""Compiled lookups of the scanned space's lattice for many points at once
(:meth:`naruto_gym.motion.scanned_space.ScannedSpace.contains_many`).

A batched env asks for all its agents every step; in NumPy the lookup was some twenty array
operations per call, most of the call's time for a few dozen points. The arithmetic is the
same as :meth:`~naruto_gym.motion.scanned_space.ScannedSpace.contains`, term by term, so both
answer alike to the last bit.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, inline="always")
def _cell_low(value: float, origin: float, voxel: float, size: int) -> int:
    return min(max(int(np.floor((value - origin) / voxel)), 0), size - 2)


@numba.njit(cache=True, nogil=True)
def usable_corners(
    positions: np.ndarray,
    clearances: np.ndarray,
    top_m: float,
    origin: np.ndarray,
    voxel: float,
    shape: np.ndarray,
    empty: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lattice corners each point's answer rests on.

    Args:
        positions: (N, 3) float64 points; clearances: (N,) float64 their surface distances.
        top_m: the highest z inside the scanned space.
        origin: (3,) float64 lattice origin; voxel: its spacing; shape: (3,) int64 its size.
        empty: the lattice's empty-sector counts (-1: not evaluated yet).

    Returns:
        ``usable`` ((N, 8) bool: the corners of the point's cell closer to it than its
        clearance, in ``_CELL_STEPS`` order), ``exact`` ((N,) bool: points below the top with
        no usable corner, which need an exact evaluation) and ``unknown`` ((K, 3) int64: the
        distinct usable corners not evaluated yet, in lattice (flat index) order).
    """
    count = positions.shape[0]
    usable = np.zeros((count, 8), np.bool_)
    exact = np.zeros(count, np.bool_)
    flat = np.empty(count * 8, np.int64)  # flat lattice indices of the unknown corners
    found = 0
    for point in range(count):
        x, y, z = positions[point, 0], positions[point, 1], positions[point, 2]
        if not z <= top_m:
            continue
        limit = clearances[point] * clearances[point]
        i0 = _cell_low(x, origin[0], voxel, shape[0])
        j0 = _cell_low(y, origin[1], voxel, shape[1])
        k0 = _cell_low(z, origin[2], voxel, shape[2])
        any_usable = False
        step = 0
        for di in range(2):
            for dj in range(2):
                for dk in range(2):
                    i, j, k = i0 + di, j0 + dj, k0 + dk
                    dx = origin[0] + i * voxel - x
                    dy = origin[1] + j * voxel - y
                    dz = origin[2] + k * voxel - z
                    if dx * dx + dy * dy + dz * dz < limit:
                        usable[point, step] = True
                        any_usable = True
                        if empty[i, j, k] < 0:
                            flat[found] = (i * shape[1] + j) * shape[2] + k
                            found += 1
                    step += 1
        exact[point] = not any_usable
    # Neighbouring points share corners: each is evaluated once.
    flat = np.sort(flat[:found])
    unknown = np.empty((found, 3), np.int64)
    distinct = 0
    for entry in range(found):
        if entry and flat[entry] == flat[entry - 1]:
            continue
        index = flat[entry]
        unknown[distinct, 2] = index % shape[2]
        unknown[distinct, 1] = (index // shape[2]) % shape[1]
        unknown[distinct, 0] = index // (shape[1] * shape[2])
        distinct += 1
    return usable, exact, unknown[:distinct]


@numba.njit(cache=True, nogil=True)
def corners_supported(
    positions: np.ndarray,
    usable: np.ndarray,
    origin: np.ndarray,
    voxel: float,
    shape: np.ndarray,
    empty: np.ndarray,
    max_empty_sectors: int,
) -> np.ndarray:
    """(N,) bool: every usable corner of each point's cell (:func:`usable_corners`, all
    evaluated by now) has at most ``max_empty_sectors`` empty support sectors."""
    count = positions.shape[0]
    supported = np.ones(count, np.bool_)
    for point in range(count):
        i0 = _cell_low(positions[point, 0], origin[0], voxel, shape[0])
        j0 = _cell_low(positions[point, 1], origin[1], voxel, shape[1])
        k0 = _cell_low(positions[point, 2], origin[2], voxel, shape[2])
        step = 0
        for di in range(2):
            for dj in range(2):
                for dk in range(2):
                    if usable[point, step] and empty[i0 + di, j0 + dj, k0 + dk] > max_empty_sectors:
                        supported[point] = False
                    step += 1
    return supported
