"""Rotation planning: look at targets, order the views, turn in bounded SLERP steps.

NARUTO turns the camera in place towards each target view it wants, never by more than
``max_rotation_deg`` (10 degrees) per frame. The number of steps between two rotations is
``ceil(angle / limit)``, so no step exceeds the limit (the released code divides by
``floor``, which allows steps of up to twice the limit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from naruto_gym.geometry.transforms import look_at_rotation, rotation_angle_between

__all__ = [
    "RotationPlan",
    "look_at_rotation",
    "order_views_greedily",
    "plan_rotations",
    "slerp_rotations",
]


def _rotation(matrix: np.ndarray, what: str) -> np.ndarray:
    matrix = np.asarray(matrix, dtype=np.float64)
    if matrix.shape != (3, 3) or not np.all(np.isfinite(matrix)):
        raise ValueError(f"{what} must be a finite 3x3 rotation matrix, got shape {matrix.shape}")
    if not np.allclose(matrix.T @ matrix, np.eye(3), atol=1e-4) or np.linalg.det(matrix) < 0:
        raise ValueError(f"{what} is not a proper rotation (orthonormal with determinant +1)")
    return matrix


def slerp_rotations(
    start: np.ndarray, end: np.ndarray, max_step_deg: float = 10.0
) -> np.ndarray:
    """Rotations that turn from ``start`` to ``end`` in equal steps of at most ``max_step_deg``.

    Args:
        start: 3x3 rotation to turn from (not included in the output).
        end: 3x3 rotation to reach; the last output is exactly ``end``.
        max_step_deg: largest angle of one step, degrees.

    Returns:
        (K, 3, 3) rotations, ``K = max(1, ceil(angle / max_step_deg))``: at least one step,
        so even a zero turn yields ``end`` once (one frame spent at the view).
    """
    if not max_step_deg > 0:
        raise ValueError(f"max_step_deg must be positive degrees, got {max_step_deg}")
    start = _rotation(start, "start rotation")
    end = _rotation(end, "end rotation")
    angle = rotation_angle_between(start, end)
    # The small tolerance keeps an exact multiple of the limit from costing one more step.
    steps = max(1, math.ceil(math.degrees(angle) / max_step_deg - 1e-9))
    if steps == 1:
        return end[None].copy()
    slerp = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([start, end])))
    rotations = slerp(np.arange(1, steps + 1) / steps).as_matrix()
    rotations[-1] = end
    return rotations


def order_views_greedily(current_rotation: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """Visiting order of views: each next view is the one nearest (in angle) to the last.

    Args:
        current_rotation: 3x3 rotation to start from.
        rotations: (T, 3, 3) view rotations.

    Returns:
        (T,) int64 permutation of ``range(T)``; ties go to the lower index.
    """
    current = _rotation(current_rotation, "current_rotation")
    rotations = np.asarray(rotations, dtype=np.float64).reshape(-1, 3, 3)
    remaining = list(range(len(rotations)))
    order: list[int] = []
    while remaining:
        # cos(angle) is monotone in trace(R_a^T R_b): the largest trace is the smallest turn.
        traces = np.einsum("ij,tij->t", current, rotations[remaining])
        chosen = remaining.pop(int(np.argmax(traces)))
        order.append(chosen)
        current = rotations[chosen]
    return np.asarray(order, dtype=np.int64)


@dataclass
class RotationPlan:
    """Rotations that visit a set of target views in place.

    Attributes:
        rotations: (K, 3, 3) camera-to-world rotations, one per frame.
        order: (T,) target indices in visiting order.
        arrivals: (T,) index into ``rotations`` where each visited view (in ``order``) is
            reached, exactly.
    """

    rotations: np.ndarray
    order: np.ndarray
    arrivals: np.ndarray


def plan_rotations(
    current_rotation: np.ndarray,
    eye: np.ndarray,
    targets: np.ndarray,
    max_step_deg: float = 10.0,
    greedy: bool = True,
) -> RotationPlan:
    """Turn in place at ``eye`` to look at every target, in bounded SLERP steps.

    Args:
        current_rotation: 3x3 camera-to-world rotation now (OpenCV camera axes).
        eye: (3,) camera position, world metres (z up).
        targets: (T, 3) points to look at.
        max_step_deg: largest turn per step, degrees (NARUTO: 10).
        greedy: order views by the smallest next turn (NARUTO); else keep the given order.

    Returns:
        A :class:`RotationPlan` whose last rotation is exactly the look-at rotation of the
        last visited target.
    """
    current = _rotation(current_rotation, "current_rotation")
    eye = np.asarray(eye, dtype=np.float64).reshape(3)
    targets = np.asarray(targets, dtype=np.float64).reshape(-1, 3)
    if len(targets) == 0:
        return RotationPlan(np.zeros((0, 3, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64))
    views = np.stack([look_at_rotation(eye, target) for target in targets])
    order = order_views_greedily(current, views) if greedy else np.arange(len(views))
    chunks = []
    arrivals = []
    count = 0
    for index in order:
        steps = slerp_rotations(current, views[index], max_step_deg)
        chunks.append(steps)
        count += len(steps)
        arrivals.append(count - 1)
        current = views[index]
    return RotationPlan(np.concatenate(chunks), order, np.asarray(arrivals, dtype=np.int64))
