"""Pose and rotation helpers (pure functions).

Poses are camera-to-world 4x4 matrices with OpenCV camera axes (x right, y down, z forward),
world z-up, metres. Quaternions are (x, y, z, w), scalar last, as scipy's ``Rotation``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

WORLD_UP = np.array([0.0, 0.0, 1.0])


def make_pose(rotation: np.ndarray, position: np.ndarray) -> np.ndarray:
    """4x4 camera-to-world matrix from a 3x3 rotation and a position."""
    pose = np.eye(4)
    pose[:3, :3] = rotation
    pose[:3, 3] = position
    return pose


def pose_from_position_quaternion(position: np.ndarray, quaternion_xyzw: np.ndarray) -> np.ndarray:
    """4x4 pose from a position and a unit quaternion (x, y, z, w)."""
    return make_pose(Rotation.from_quat(quaternion_xyzw).as_matrix(), position)


def quaternion_from_pose(pose: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of a pose's rotation, with w >= 0."""
    quaternion = Rotation.from_matrix(pose[:3, :3]).as_quat()
    return quaternion if quaternion[3] >= 0 else -quaternion


def look_at_rotation(eye: np.ndarray, target: np.ndarray, up: np.ndarray = WORLD_UP) -> np.ndarray:
    """Camera-to-world rotation of an OpenCV camera at ``eye`` looking at ``target``.

    The camera's z axis points at the target and its y axis (image down) points as far
    towards world-down as possible. When looking straight up or down the x axis is kept
    along world +x.
    """
    forward = np.asarray(target, dtype=np.float64) - np.asarray(eye, dtype=np.float64)
    norm = np.linalg.norm(forward)
    if norm < 1e-12:
        raise ValueError("look_at_rotation: eye and target coincide")
    forward /= norm
    # OpenCV axes: right = down x forward with down ~ -up, i.e. forward x up.
    right = np.cross(forward, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(right) < 1e-9:
        right = np.array([1.0, 0.0, 0.0]) - forward * forward[0]
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return np.stack([right, down, forward], axis=1)


def rotation_angle_between(rotation_a: np.ndarray, rotation_b: np.ndarray) -> float:
    """Geodesic angle in radians between two rotation matrices."""
    relative = rotation_a.T @ rotation_b
    cosine = (np.trace(relative) - 1.0) / 2.0
    return float(np.arccos(np.clip(cosine, -1.0, 1.0)))


def is_rotation_matrix(matrix: np.ndarray, tolerance: float = 1e-4) -> bool:
    matrix = np.asarray(matrix, dtype=np.float64)
    return (
        matrix.shape == (3, 3)
        and np.allclose(matrix.T @ matrix, np.eye(3), atol=tolerance)
        and abs(np.linalg.det(matrix) - 1.0) < tolerance
    )


def validate_pose(pose: np.ndarray, what: str = "pose") -> np.ndarray:
    """Return ``pose`` as a float64 4x4 rigid transform or raise a ValueError saying why."""
    try:
        pose = np.asarray(pose, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(
            f"{what} must be a 4x4 camera-to-world matrix of numbers, got {pose!r}"
        ) from None
    if pose.shape != (4, 4):
        raise ValueError(f"{what} must be a 4x4 camera-to-world matrix, got shape {pose.shape}")
    if not np.all(np.isfinite(pose)):
        raise ValueError(f"{what} contains NaN or inf")
    if not np.allclose(pose[3], [0.0, 0.0, 0.0, 1.0], atol=1e-6):
        raise ValueError(f"{what} last row must be [0, 0, 0, 1], got {pose[3].tolist()}")
    if not is_rotation_matrix(pose[:3, :3]):
        raise ValueError(f"{what} rotation block is not a proper rotation (orthonormal, det +1)")
    return pose
