"""Collision checks of straight moves against an SDF volume (the agent is a sphere).

A move is a chain of whole steps (0.1 m in NARUTO). Every step is sampled every
``sample_m`` (2 cm) and a sample is free where the trilinear SDF exceeds the clearance (the
agent's 5 cm radius, plus any safety margin). Free steps are counted from the start side of
the move, so the free prefix can be kept (the released NARUTO code counts from the far end,
which keeps steps that are not reachable).

How safe is this against the true geometry? The SDF is only known on voxel centres. If the
grid holds exact signed distances, the true distance at a point is at least the trilinear
value minus ``sqrt(3) / 2 * voxel_size`` (the SDF is 1-Lipschitz and trilinear weights are a
convex combination of the corners), and between two samples at least the smaller sample
value minus ``sample_m / 2``. So a margin of ``sqrt(3) / 2 * voxel_size + sample_m / 2``
(0.097 m for 0.1 m voxels and 2 cm samples) guarantees the clearance; NARUTO uses no margin,
which is much closer in practice on flat walls (interpolating a linear function is exact) but
can cut convex corners and thin objects by a centimetre or two.
"""

from __future__ import annotations

import math

import numpy as np

from naruto_agent.mapping.sdf_volume import SdfVolume


def guaranteed_margin_m(voxel_size: float, sample_m: float) -> float:
    """Safety margin that makes the sampled trilinear check conservative (see module doc)."""
    return math.sqrt(3.0) / 2.0 * voxel_size + sample_m / 2.0


def samples_per_step(step_m: float, sample_m: float) -> int:
    """How many samples check one step so that samples are at most ``sample_m`` apart."""
    return max(1, math.ceil(step_m / sample_m - 1e-9))


def free_steps_along_direction(
    sdf: SdfVolume,
    start: np.ndarray,
    direction: np.ndarray,
    steps: int,
    step_m: float,
    sample_m: float,
    clearance_m: float,
) -> int:
    """Number of leading free steps of the move ``start + k * step_m * direction``.

    All samples of all ``steps`` steps are checked in one vectorised lookup; the start point
    itself is not checked (it is a node already known to be free).

    Args:
        sdf: signed distance volume, metres.
        start: (3,) start point.
        direction: (3,) unit direction.
        steps: number of whole steps to check (>= 0).
        step_m: step length, metres.
        sample_m: largest distance between two checked samples, metres.
        clearance_m: a sample is free where the SDF exceeds this.

    Returns:
        The count of whole steps, from the start side, whose samples are all free.
    """
    if steps <= 0:
        return 0
    per_step = samples_per_step(step_m, sample_m)
    distances = np.arange(1, steps * per_step + 1, dtype=np.float64) * (step_m / per_step)
    points = start + distances[:, None] * direction
    free = (sdf.sample(points) > clearance_m).reshape(steps, per_step).all(axis=1)
    if free.all():
        return steps
    return int(np.argmin(free))


def free_steps_along_segment(
    sdf: SdfVolume,
    start: np.ndarray,
    end: np.ndarray,
    step_m: float = 0.1,
    sample_m: float = 0.02,
    clearance_m: float = 0.05,
    max_steps: int | None = None,
) -> int:
    """How many whole steps from ``start`` towards ``end`` are free (counted from the start).

    The segment holds ``floor(|end - start| / step_m)`` whole steps (at most ``max_steps``);
    a step is free when all its samples, every ``sample_m``, have SDF > ``clearance_m``.

    Args:
        sdf: signed distance volume (positive in free space), metres.
        start: (3,) start point (assumed free; not checked).
        end: (3,) end point.
        step_m: step length, metres (NARUTO: 0.1).
        sample_m: sample spacing, metres (NARUTO: 0.02).
        clearance_m: required SDF, metres: the agent radius plus any margin (NARUTO: 0.05).
        max_steps: optional cap on the number of steps checked.

    Returns:
        Number of leading free whole steps, 0 when the first step is blocked or the segment
        is shorter than one step.
    """
    if step_m <= 0 or sample_m <= 0:
        raise ValueError(f"step_m and sample_m must be positive, got {step_m} and {sample_m}")
    start = np.asarray(start, dtype=np.float64).reshape(3)
    end = np.asarray(end, dtype=np.float64).reshape(3)
    length = float(np.linalg.norm(end - start))
    steps = int(math.floor(length / step_m + 1e-9))
    if max_steps is not None:
        steps = min(steps, int(max_steps))
    if steps <= 0:
        return 0
    return free_steps_along_direction(
        sdf, start, (end - start) / length, steps, step_m, sample_m, clearance_m
    )


def segment_is_free(
    sdf: SdfVolume,
    start: np.ndarray,
    end: np.ndarray,
    sample_m: float = 0.02,
    clearance_m: float = 0.05,
) -> bool:
    """True when every sample of the segment (ends included, at most ``sample_m`` apart) is free."""
    start = np.asarray(start, dtype=np.float64).reshape(3)
    end = np.asarray(end, dtype=np.float64).reshape(3)
    count = max(1, math.ceil(float(np.linalg.norm(end - start)) / sample_m - 1e-9))
    fractions = np.linspace(0.0, 1.0, count + 1)
    points = start + fractions[:, None] * (end - start)
    return bool(np.all(sdf.sample(points) > clearance_m))
