"""Compiled pose arithmetic of one step: action -> target pose -> bounded pose step.

The same numba functions serve the single env (one agent per call) and the batched vector env
(a compiled loop over agents), so both produce bit-identical poses. They replace SciPy's
``Rotation`` / ``Slerp`` on the step path, whose object construction cost more than the rest
of a 64 x 64 step. Compiled without ``fastmath`` so that no reassociation makes the two
callers differ.

Rotations are 3x3 matrices; the SLERP of :func:`limit_rotation` goes through unit
quaternions (x, y, z, w), as SciPy's ``Slerp`` does.
"""

from __future__ import annotations

import numba
import numpy as np

# Discrete action indices (see naruto_gym.motion.actions.DISCRETE_ACTIONS).
MOVE_FORWARD, MOVE_BACKWARD, MOVE_LEFT, MOVE_RIGHT, MOVE_UP, MOVE_DOWN = range(6)
TURN_LEFT, TURN_RIGHT, LOOK_UP, LOOK_DOWN = range(6, 10)

_JIT = {"cache": True, "nogil": True}


@numba.njit(**_JIT)
def rotation_from_rotvec(rx: float, ry: float, rz: float) -> np.ndarray:
    """3x3 rotation of a rotation vector (axis times angle, radians), Rodrigues' formula."""
    angle = np.sqrt(rx * rx + ry * ry + rz * rz)
    out = np.eye(3)
    if angle < 1e-12:
        return out
    x, y, z = rx / angle, ry / angle, rz / angle
    c = np.cos(angle)
    s = np.sin(angle)
    t = 1.0 - c
    out[0, 0] = c + x * x * t
    out[0, 1] = x * y * t - z * s
    out[0, 2] = x * z * t + y * s
    out[1, 0] = y * x * t + z * s
    out[1, 1] = c + y * y * t
    out[1, 2] = y * z * t - x * s
    out[2, 0] = z * x * t - y * s
    out[2, 1] = z * y * t + x * s
    out[2, 2] = c + z * z * t
    return out


@numba.njit(**_JIT)
def quaternion_from_rotation(matrix: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of a rotation matrix (Shepperd's method, robust near pi)."""
    q = np.empty(4)
    trace = matrix[0, 0] + matrix[1, 1] + matrix[2, 2]
    if trace >= matrix[0, 0] and trace >= matrix[1, 1] and trace >= matrix[2, 2]:
        s = np.sqrt(1.0 + trace) * 2.0
        q[3] = 0.25 * s
        q[0] = (matrix[2, 1] - matrix[1, 2]) / s
        q[1] = (matrix[0, 2] - matrix[2, 0]) / s
        q[2] = (matrix[1, 0] - matrix[0, 1]) / s
    elif matrix[0, 0] >= matrix[1, 1] and matrix[0, 0] >= matrix[2, 2]:
        s = np.sqrt(1.0 + matrix[0, 0] - matrix[1, 1] - matrix[2, 2]) * 2.0
        q[3] = (matrix[2, 1] - matrix[1, 2]) / s
        q[0] = 0.25 * s
        q[1] = (matrix[0, 1] + matrix[1, 0]) / s
        q[2] = (matrix[0, 2] + matrix[2, 0]) / s
    elif matrix[1, 1] >= matrix[2, 2]:
        s = np.sqrt(1.0 + matrix[1, 1] - matrix[0, 0] - matrix[2, 2]) * 2.0
        q[3] = (matrix[0, 2] - matrix[2, 0]) / s
        q[0] = (matrix[0, 1] + matrix[1, 0]) / s
        q[1] = 0.25 * s
        q[2] = (matrix[1, 2] + matrix[2, 1]) / s
    else:
        s = np.sqrt(1.0 + matrix[2, 2] - matrix[0, 0] - matrix[1, 1]) * 2.0
        q[3] = (matrix[1, 0] - matrix[0, 1]) / s
        q[0] = (matrix[0, 2] + matrix[2, 0]) / s
        q[1] = (matrix[1, 2] + matrix[2, 1]) / s
        q[2] = 0.25 * s
    norm = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return q / norm


@numba.njit(**_JIT)
def rotation_from_quaternion(q: np.ndarray) -> np.ndarray:
    """3x3 rotation of a quaternion (x, y, z, w); normalised here (must not be zero)."""
    norm = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    x, y, z, w = q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm
    out = np.empty((3, 3))
    out[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    out[0, 1] = 2.0 * (x * y - z * w)
    out[0, 2] = 2.0 * (x * z + y * w)
    out[1, 0] = 2.0 * (x * y + z * w)
    out[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    out[1, 2] = 2.0 * (y * z - x * w)
    out[2, 0] = 2.0 * (x * z - y * w)
    out[2, 1] = 2.0 * (y * z + x * w)
    out[2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return out


@numba.njit(**_JIT)
def relative_rotation_angle(current: np.ndarray, target: np.ndarray) -> float:
    """Geodesic angle (radians) of ``current.T @ target``."""
    relative = current.T @ target
    q = quaternion_from_rotation(relative)
    vector = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2])
    return 2.0 * np.arctan2(vector, abs(q[3]))


@numba.njit(**_JIT)
def limit_rotation(current: np.ndarray, target: np.ndarray, max_angle: float) -> np.ndarray:
    """``target`` if it lies within ``max_angle`` of ``current``, else the rotation
    ``max_angle`` along the geodesic from ``current`` towards it (SLERP)."""
    relative = current.T @ target
    q = quaternion_from_rotation(relative)
    if q[3] < 0.0:
        q = -q
    vector = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2])
    angle = 2.0 * np.arctan2(vector, q[3])
    if not (angle > max_angle and angle > 0.0):
        return target.copy()
    scale = max_angle / vector
    return current @ rotation_from_rotvec(q[0] * scale, q[1] * scale, q[2] * scale)


@numba.njit(**_JIT)
def limit_pose_step_kernel(
    current: np.ndarray, target: np.ndarray, max_translation: float, max_rotation: float
) -> np.ndarray:
    """4x4 pose reached from ``current`` towards ``target`` within the step limits."""
    out = np.eye(4)
    dx = target[0, 3] - current[0, 3]
    dy = target[1, 3] - current[1, 3]
    dz = target[2, 3] - current[2, 3]
    distance = np.sqrt(dx * dx + dy * dy + dz * dz)
    if distance > max_translation:
        scale = max_translation / distance
        dx *= scale
        dy *= scale
        dz *= scale
    out[:3, :3] = limit_rotation(
        np.ascontiguousarray(current[:3, :3]), np.ascontiguousarray(target[:3, :3]), max_rotation
    )
    out[0, 3] = current[0, 3] + dx
    out[1, 3] = current[1, 3] + dy
    out[2, 3] = current[2, 3] + dz
    return out


@numba.njit(**_JIT)
def discrete_target_kernel(
    current: np.ndarray, action: int, max_translation: float, max_rotation: float,
    max_pitch: float,
) -> np.ndarray:
    """4x4 target pose of a discrete action (habitat-style moves, see ``DISCRETE_ACTIONS``)."""
    out = current.copy()
    rotation = np.ascontiguousarray(current[:3, :3])
    if action <= MOVE_DOWN:
        # Heading: the optical axis in the horizontal plane (its up vector when looking
        # straight up or down).
        fx, fy = rotation[0, 2], rotation[1, 2]
        if np.sqrt(fx * fx + fy * fy) < 1e-6:
            fx, fy = -rotation[0, 1], -rotation[1, 1]
        norm = np.sqrt(fx * fx + fy * fy)
        fx, fy = fx / norm, fy / norm
        # left = up x forward
        mx, my, mz = 0.0, 0.0, 0.0
        if action == MOVE_FORWARD:
            mx, my = fx, fy
        elif action == MOVE_BACKWARD:
            mx, my = -fx, -fy
        elif action == MOVE_LEFT:
            mx, my = -fy, fx
        elif action == MOVE_RIGHT:
            mx, my = fy, -fx
        elif action == MOVE_UP:
            mz = 1.0
        else:
            mz = -1.0
        out[0, 3] = current[0, 3] + mx * max_translation
        out[1, 3] = current[1, 3] + my * max_translation
        out[2, 3] = current[2, 3] + mz * max_translation
        return out
    if action == TURN_LEFT or action == TURN_RIGHT:
        sign = 1.0 if action == TURN_LEFT else -1.0
        out[:3, :3] = rotation_from_rotvec(0.0, 0.0, sign * max_rotation) @ rotation
        return out
    # Pitch about the camera x axis; "look up" turns the optical axis towards +z.
    pitch = np.arcsin(min(max(rotation[2, 2], -1.0), 1.0))
    wanted = pitch + (max_rotation if action == LOOK_UP else -max_rotation)
    wanted = min(max(wanted, -max_pitch), max_pitch)
    out[:3, :3] = rotation @ rotation_from_rotvec(wanted - pitch, 0.0, 0.0)
    return out


@numba.njit(**_JIT)
def _clip_norm(x: float, y: float, z: float) -> tuple[float, float, float]:
    norm = np.sqrt(x * x + y * y + z * z)
    if norm > 1.0:
        return x / norm, y / norm, z / norm
    return x, y, z


@numba.njit(**_JIT)
def delta_target_kernel(
    current: np.ndarray, action: np.ndarray, max_translation: float, max_rotation: float
) -> np.ndarray:
    """4x4 target pose of a normalised camera-frame delta action (6,)."""
    out = np.eye(4)
    rotation = np.ascontiguousarray(current[:3, :3])
    tx, ty, tz = _clip_norm(action[0], action[1], action[2])
    rx, ry, rz = _clip_norm(action[3], action[4], action[5])
    local = np.array([tx * max_translation, ty * max_translation, tz * max_translation])
    translation = rotation @ local
    out[:3, :3] = rotation @ rotation_from_rotvec(
        rx * max_rotation, ry * max_rotation, rz * max_rotation
    )
    out[:3, 3] = current[:3, 3] + translation
    return out


@numba.njit(**_JIT)
def pose_target_kernel(action: np.ndarray) -> np.ndarray:
    """4x4 target pose of a pose action (x, y, z, qx, qy, qz, qw); the quaternion must not be
    zero (checked by the caller)."""
    out = np.eye(4)
    out[:3, :3] = rotation_from_quaternion(action[3:7].copy())
    out[0, 3] = action[0]
    out[1, 3] = action[1]
    out[2, 3] = action[2]
    return out


MODE_POSE, MODE_DELTA, MODE_DISCRETE = 0, 1, 2


@numba.njit(**_JIT)
def step_pose_kernel(
    current: np.ndarray, mode: int, discrete_action: int, continuous_action: np.ndarray,
    max_translation: float, max_rotation: float, max_pitch: float,
) -> np.ndarray:
    """The bounded pose one action leads to (before collision checking)."""
    if mode == MODE_DISCRETE:
        target = discrete_target_kernel(
            current, discrete_action, max_translation, max_rotation, max_pitch
        )
    elif mode == MODE_DELTA:
        target = delta_target_kernel(current, continuous_action, max_translation, max_rotation)
    else:
        target = pose_target_kernel(continuous_action)
    return limit_pose_step_kernel(current, target, max_translation, max_rotation)


@numba.njit(**_JIT)
def step_poses_kernel(
    poses: np.ndarray, mode: int, discrete_actions: np.ndarray, continuous_actions: np.ndarray,
    max_translation: float, max_rotation: float, max_pitch: float, out: np.ndarray,
) -> None:
    """:func:`step_pose_kernel` for N agents: ``poses`` (N, 4, 4) -> ``out`` (N, 4, 4)."""
    for i in range(poses.shape[0]):
        out[i] = step_pose_kernel(
            poses[i], mode, discrete_actions[i], continuous_actions[i], max_translation,
            max_rotation, max_pitch,
        )
