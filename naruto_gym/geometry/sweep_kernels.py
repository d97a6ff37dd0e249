"""The geometry of one sphere sweep, compiled once for the single env and the batched env.

A move is clipped to the bounds' box, sampled every quarter of the sphere's clearance, and
stops at the last sample before the first blocked one. The single env
(:class:`~naruto_gym.motion.collision.CollisionChecker`,
:meth:`~naruto_gym.sensors.raycaster.RayCaster.sweep`) calls these functions one move at a
time; the batched env's kernels (:mod:`naruto_gym.vector.batch_kernels`) call them in loops
over all agents, so both make the same numbers.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def fraction_inside_box(
    start: np.ndarray, end: np.ndarray, box_min: np.ndarray, box_max: np.ndarray
) -> float:
    """Largest t in [0, 1] with start + t (end - start) inside the box (start assumed inside)."""
    fraction = 1.0
    for axis in range(3):
        delta = end[axis] - start[axis]
        if delta > 0 and end[axis] > box_max[axis]:
            fraction = min(fraction, (box_max[axis] - start[axis]) / delta)
        elif delta < 0 and end[axis] < box_min[axis]:
            fraction = min(fraction, (box_min[axis] - start[axis]) / delta)
    return min(max(fraction, 0.0), 1.0)


@numba.njit(cache=True, nogil=True)
def sweep_step_count(length: float, clearance: float) -> int:
    """Intervals of a sweep of ``length``: samples every ``clearance / 4``, at least 1 mm
    apart, at least one interval."""
    step = max(clearance / 4.0, 1e-3)
    return max(int(np.ceil(length / step)), 1)


@numba.njit(cache=True, nogil=True)
def first_blocked_sample(
    fractions: np.ndarray,
    length: float,
    surface_distance: np.ndarray,
    wall_distance: float,
    clearance: float,
    threshold: float,
) -> int:
    """Index of a sweep's first blocked sample, -1 when every sample is free.

    A sample is blocked when it lies closer than the clearance to a surface
    (``surface_distance < threshold``, where ``threshold`` is the clearance in the distances'
    own precision, as numpy compares a float32 array with a float) or, for a sweep of
    non-zero length, within the clearance of the ray's first hit along the segment
    (``wall_distance``, ``inf`` for none).
    """
    for k in range(fractions.shape[0]):
        clear = surface_distance[k] >= threshold
        if length > 0:
            clear = clear and fractions[k] * length < wall_distance - clearance
        if not clear:
            return k
    return -1
