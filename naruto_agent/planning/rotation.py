"""Rotation planning: look at targets, order the views, turn in bounded SLERP steps.

NARUTO turns the camera in place towards each target view it wants, never by more than
``max_rotation_deg`` (10 degrees) per frame. The number of steps between two rotations is
``ceil(angle / limit)``, so no step exceeds the limit (the released code divides by
``floor``, which allows steps of up to twice the limit).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from naruto_gym.geometry.transforms import look_at_rotation, rotation_angle_between

__all__ = [
    "RotationPlan",
    "look_at_rotation",
    "order_views_greedily",
    "image_view_test",
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
        order: (T',) indices of the visited targets, in visiting order.
        arrivals: (T',) index into ``rotations`` where each visited view (in ``order``) is
            reached, exactly.
        skipped: indices of the targets not turned to because they were already in view.
    """

    rotations: np.ndarray
    order: np.ndarray
    arrivals: np.ndarray
    skipped: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))


#: ``in_view(eye (3,), rotations (K, 3, 3), targets (T, 3)) -> (K, T) bool``: which targets
#: a camera at ``eye`` has in its image at each rotation.
InViewTest = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def image_view_test(
    width: int, height: int, fx: float, fy: float, cx: float, cy: float,
    margin: float = 0.1,
) -> InViewTest:
    """An :data:`InViewTest` for a pinhole camera: a target is in view when it lies in front
    of the camera and projects inside the image shrunk by ``margin`` of its size per side."""
    low_u, high_u = margin * width - 0.5, (1.0 - margin) * width - 0.5
    low_v, high_v = margin * height - 0.5, (1.0 - margin) * height - 0.5

    def in_view(eye: np.ndarray, rotations: np.ndarray, targets: np.ndarray) -> np.ndarray:
        offsets = np.asarray(targets, np.float64).reshape(-1, 3) - np.asarray(eye).reshape(3)
        # Camera-frame coordinates R^T (t - eye) for every rotation and target.
        local = np.einsum("kji,tj->kti", np.asarray(rotations, np.float64), offsets)
        z = local[..., 2]
        safe = np.where(z > 1e-6, z, 1.0)
        u = fx * local[..., 0] / safe + cx
        v = fy * local[..., 1] / safe + cy
        return (z > 1e-6) & (u >= low_u) & (u <= high_u) & (v >= low_v) & (v <= high_v)

    return in_view


def plan_rotations(
    current_rotation: np.ndarray,
    eye: np.ndarray,
    targets: np.ndarray,
    max_step_deg: float = 10.0,
    greedy: bool = True,
    in_view: InViewTest | None = None,
) -> RotationPlan:
    """Turn in place at ``eye`` to look at every target, in bounded SLERP steps.

    Args:
        current_rotation: 3x3 camera-to-world rotation now (OpenCV camera axes).
        eye: (3,) camera position, world metres (z up).
        targets: (T, 3) points to look at.
        max_step_deg: largest turn per step, degrees (NARUTO: 10).
        greedy: order views by the smallest next turn (NARUTO); else keep the given order.
        in_view: None (published) turns to every target. Given, a target that the current
            rotation or any rotation already turned through has in its image is not turned
            to (the camera has seen it; with a 90-degree field of view the 10 views of a
            goal often share a few images).

    Returns:
        A :class:`RotationPlan` whose last rotation is exactly the look-at rotation of the
        last visited target (empty when every target was already in view).
    """
    current = _rotation(current_rotation, "current_rotation")
    eye = np.asarray(eye, dtype=np.float64).reshape(3)
    targets = np.asarray(targets, dtype=np.float64).reshape(-1, 3)
    empty = RotationPlan(np.zeros((0, 3, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64))
    if len(targets) == 0:
        return empty
    views = np.stack([look_at_rotation(eye, target) for target in targets])
    if in_view is None:
        order = order_views_greedily(current, views) if greedy else np.arange(len(views))
        skipped: list[int] = []
    else:
        order, skipped = [], []
    chunks = []
    arrivals = []
    count = 0
    remaining = list(range(len(views)))
    seen_by = current[None]
    while remaining:
        if in_view is not None:
            # Drop the targets some rotation so far has in view, then take the nearest turn.
            visible = in_view(eye, seen_by, targets[remaining]).any(axis=0)
            skipped += [index for index, hit in zip(remaining, visible, strict=True) if hit]
            remaining = [index for index, hit in zip(remaining, visible, strict=True)
                         if not hit]
            if not remaining:
                break
            traces = np.einsum("ij,tij->t", current, views[remaining])
            index = remaining.pop(int(np.argmax(traces)) if greedy else 0)
            order.append(index)
        else:
            index = order[len(chunks)]
            remaining.pop()
        steps = slerp_rotations(current, views[index], max_step_deg)
        chunks.append(steps)
        count += len(steps)
        arrivals.append(count - 1)
        current = views[index]
        seen_by = steps
    if not chunks:
        return RotationPlan(empty.rotations, empty.order, empty.arrivals,
                            np.asarray(skipped, dtype=np.int64))
    return RotationPlan(np.concatenate(chunks), np.asarray(order, dtype=np.int64),
                        np.asarray(arrivals, dtype=np.int64),
                        np.asarray(skipped, dtype=np.int64))
