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
from scipy.spatial.transform import Rotation, Slerp

from naruto_gym.geometry.transforms import WORLD_UP, make_pose

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
    delta = target[:3, 3] - current[:3, 3]
    distance = float(np.linalg.norm(delta))
    if distance > max_translation_m:
        delta *= max_translation_m / distance
    rotations = Rotation.from_matrix(np.stack([current[:3, :3], target[:3, :3]]))
    angle = float((rotations[0].inv() * rotations[1]).magnitude())
    if angle > max_rotation_rad and angle > 0.0:
        rotation = Slerp([0.0, 1.0], rotations)([max_rotation_rad / angle])[0].as_matrix()
    else:
        rotation = target[:3, :3]
    return make_pose(rotation, current[:3, 3] + delta)


def pose_target_from_action(action: np.ndarray) -> np.ndarray:
    """4x4 target pose from a pose action (x, y, z, qx, qy, qz, qw); the quaternion is
    normalised here (it must not be zero)."""
    quaternion = np.asarray(action[3:7], dtype=np.float64)
    norm = np.linalg.norm(quaternion)
    if norm < 1e-6:
        raise ValueError(
            "pose action quaternion (x, y, z, w) has zero norm; pass a unit quaternion"
        )
    return make_pose(Rotation.from_quat(quaternion / norm).as_matrix(), action[:3])


def _clip_norm(vector: np.ndarray) -> np.ndarray:
    norm = float(np.linalg.norm(vector))
    return vector / norm if norm > 1.0 else vector


def delta_target_from_action(
    current: np.ndarray, action: np.ndarray, max_translation_m: float, max_rotation_rad: float
) -> np.ndarray:
    """4x4 target pose for a normalised camera-frame delta action (6,)."""
    rotation = current[:3, :3]
    translation = rotation @ (_clip_norm(np.asarray(action[:3], np.float64)) * max_translation_m)
    turn = Rotation.from_rotvec(_clip_norm(np.asarray(action[3:6], np.float64)) * max_rotation_rad)
    return make_pose(rotation @ turn.as_matrix(), current[:3, 3] + translation)


def _heading(rotation: np.ndarray) -> np.ndarray:
    """Unit horizontal direction of the camera's optical axis (falls back to its up vector)."""
    forward = rotation[:, 2].copy()
    forward[2] = 0.0
    if np.linalg.norm(forward) < 1e-6:
        forward = -rotation[:, 1].copy()
        forward[2] = 0.0
    return forward / np.linalg.norm(forward)


def discrete_target_from_action(
    current: np.ndarray, action: int, max_translation_m: float, max_rotation_rad: float
) -> np.ndarray:
    """4x4 target pose of a discrete action index (see :data:`DISCRETE_ACTIONS`)."""
    name = DISCRETE_ACTIONS[int(action)]
    rotation = current[:3, :3]
    position = current[:3, 3].copy()
    forward = _heading(rotation)
    left = np.cross(WORLD_UP, forward)
    moves = {
        "move_forward": forward,
        "move_backward": -forward,
        "move_left": left,
        "move_right": -left,
        "move_up": WORLD_UP,
        "move_down": -WORLD_UP,
    }
    if name in moves:
        return make_pose(rotation, position + moves[name] * max_translation_m)
    if name in ("turn_left", "turn_right"):
        sign = 1.0 if name == "turn_left" else -1.0
        yaw = Rotation.from_rotvec(WORLD_UP * sign * max_rotation_rad).as_matrix()
        return make_pose(yaw @ rotation, position)
    # Pitch about the camera x axis; "look up" turns the optical axis towards +z.
    pitch = float(np.arcsin(np.clip(rotation[2, 2], -1.0, 1.0)))
    wanted = pitch + (max_rotation_rad if name == "look_up" else -max_rotation_rad)
    wanted = float(np.clip(wanted, -MAX_DISCRETE_PITCH_RAD, MAX_DISCRETE_PITCH_RAD))
    # Rotating about camera x by +angle tilts the optical axis towards camera -y (image up).
    turn = Rotation.from_rotvec(np.array([wanted - pitch, 0.0, 0.0])).as_matrix()
    return make_pose(rotation @ turn, position)
