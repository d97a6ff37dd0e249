"""Where a pose is updated: the three action modes turned into a bounded pose step (pure).

* ``"pose"``: an absolute target (x, y, z, qx, qy, qz, qw); the camera moves towards it by at
  most the translation and rotation limits.
* ``"delta"``: a normalised ``Box(-1, 1, (6,))`` of camera-frame increments: (tx, ty, tz) times
  ``max_translation_m`` and a rotation vector (rx, ry, rz) times ``max_rotation_deg``; each
  3-vector is clipped to norm 1 first, so a step never exceeds the limits.
* ``"discrete"``: habitat-style moves, see :data:`DISCRETE_ACTIONS`.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from naruto_gym.motion.pose_kernels import (
    delta_target_kernel,
    discrete_target_kernel,
    limit_pose_step_kernel,
    pose_target_kernel,
)

ActionMode = Literal["pose", "delta", "discrete"]
ACTION_MODES: tuple[str, ...] = ("pose", "delta", "discrete")

DISCRETE_ACTIONS: tuple[str, ...] = (
    "move_forward",  # along the camera's heading, in the horizontal plane
    "move_backward",
    "move_left",
    "move_right",
    "move_up",  # along world +z
    "move_down",
    "turn_left",  # yaw about world +z
    "turn_right",
    "look_up",  # pitch about the camera's x axis
    "look_down",
)

# Pitch is kept within this bound in discrete mode so that yaw stays well defined.
MAX_DISCRETE_PITCH_RAD = np.deg2rad(80.0)


def limit_pose_step(
    current: np.ndarray, target: np.ndarray, max_translation_m: float, max_rotation_rad: float
) -> np.ndarray:
    """The pose reached by moving from ``current`` towards ``target`` within the limits.

    Translation is clipped to ``max_translation_m`` along the straight line; rotation follows
    the geodesic (SLERP) for at most ``max_rotation_rad``.
    """
    return limit_pose_step_kernel(
        np.ascontiguousarray(current, dtype=np.float64),
        np.ascontiguousarray(target, dtype=np.float64),
        float(max_translation_m),
        float(max_rotation_rad),
    )


def pose_target_from_action(action: np.ndarray) -> np.ndarray:
    """4x4 target pose from a pose action (x, y, z, qx, qy, qz, qw); the quaternion is
    normalised here (it must not be zero)."""
    action = np.asarray(action, dtype=np.float64)
    if np.linalg.norm(action[3:7]) < 1e-6:
        raise ValueError(
            "pose action quaternion (x, y, z, w) has zero norm; pass a unit quaternion"
        )
    return pose_target_kernel(np.ascontiguousarray(action[:7]))


def delta_target_from_action(
    current: np.ndarray, action: np.ndarray, max_translation_m: float, max_rotation_rad: float
) -> np.ndarray:
    """4x4 target pose for a normalised camera-frame delta action (6,)."""
    return delta_target_kernel(
        np.ascontiguousarray(current, dtype=np.float64),
        np.ascontiguousarray(action, dtype=np.float64),
        float(max_translation_m),
        float(max_rotation_rad),
    )


def discrete_target_from_action(
    current: np.ndarray, action: int, max_translation_m: float, max_rotation_rad: float
) -> np.ndarray:
    """4x4 target pose of a discrete action index (see :data:`DISCRETE_ACTIONS`)."""
    return discrete_target_kernel(
        np.ascontiguousarray(current, dtype=np.float64),
        int(action),
        float(max_translation_m),
        float(max_rotation_rad),
        float(MAX_DISCRETE_PITCH_RAD),
    )
