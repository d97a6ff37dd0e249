"""Where coverage is computed: the share of the ground-truth surface seen so far.

The surface is represented by area-uniform samples. A sample counts as seen once it falls in
the pinhole frustum of some frame, within the coverage range, and in front of (or on) the
rendered depth at its pixel, i.e. not occluded.
"""

from __future__ import annotations

import numba
import numpy as np

from naruto_gym.sensors.pinhole import PinholeCamera

# How far behind the rendered depth a sample may lie and still count as seen (metres).
COVERAGE_TOLERANCE_M = 0.03


def visible_samples(
    samples_world: np.ndarray,
    camera_to_world: np.ndarray,
    camera: PinholeCamera,
    depth: np.ndarray,
    max_range_m: float,
    tolerance_m: float = 0.03,
) -> np.ndarray:
    """Boolean mask of the samples a frame sees (pure function).

    Args:
        samples_world: (N, 3) surface samples.
        camera_to_world: 4x4 pose of the frame.
        camera: its intrinsics.
        depth: (H, W) z-depth of the frame, 0 where nothing was hit.
        max_range_m: samples farther (in z) than this are not counted.
        tolerance_m: how far behind the rendered depth a sample may lie (grazing surfaces,
            pixel quantisation); grows by 1 % of the depth.
    """
    rotation = camera_to_world[:3, :3]
    points_camera = (samples_world - camera_to_world[:3, 3]) @ rotation
    pixels, z = camera.project(points_camera)
    u = np.floor(pixels[:, 0] + 0.5).astype(np.int64)
    v = np.floor(pixels[:, 1] + 0.5).astype(np.int64)
    in_view = (
        (z > 1e-3) & (z <= max_range_m)
        & (u >= 0) & (u < camera.width) & (v >= 0) & (v < camera.height)
    )
    index = np.flatnonzero(in_view)
    rendered = depth[v[index], u[index]]
    unoccluded = (rendered > 0) & (z[index] <= rendered + tolerance_m + 0.01 * rendered)
    mask = np.zeros(len(samples_world), dtype=bool)
    mask[index[unoccluded]] = True
    return mask


@numba.njit(cache=True, nogil=True)
def mark_visible_samples(
    samples_world: np.ndarray,
    seen: np.ndarray,
    camera_to_world: np.ndarray,
    intrinsics: np.ndarray,
    depth: np.ndarray,
    max_range_m: float,
    tolerance_m: float,
) -> int:
    """Compiled :func:`visible_samples` that only visits unseen samples: sets ``seen[i]`` for
    every sample the frame sees and returns how many were newly seen.

    Args:
        samples_world: (N, 3) float64 surface samples.
        seen: (N,) bool, updated in place.
        camera_to_world: 4x4 float64 pose.
        intrinsics: (6,) float64 ``(width, height, fx, fy, cx, cy)``.
        depth: (H, W) float32 z-depth, 0 where nothing was hit.
        max_range_m: samples farther (in z) than this are not counted.
        tolerance_m: as in :func:`visible_samples`.
    """
    width, height = int(intrinsics[0]), int(intrinsics[1])
    fx, fy, cx, cy = intrinsics[2], intrinsics[3], intrinsics[4], intrinsics[5]
    tx, ty, tz = camera_to_world[0, 3], camera_to_world[1, 3], camera_to_world[2, 3]
    r = camera_to_world
    tolerance = np.float32(tolerance_m)
    share = np.float32(0.01)
    added = 0
    for i in range(samples_world.shape[0]):
        if seen[i]:
            continue
        dx = samples_world[i, 0] - tx
        dy = samples_world[i, 1] - ty
        dz = samples_world[i, 2] - tz
        z = dx * r[0, 2] + dy * r[1, 2] + dz * r[2, 2]
        if not (z > 1e-3 and z <= max_range_m):
            continue
        x = dx * r[0, 0] + dy * r[1, 0] + dz * r[2, 0]
        y = dx * r[0, 1] + dy * r[1, 1] + dz * r[2, 1]
        u = int(np.floor(fx * x / z + cx + 0.5))
        v = int(np.floor(fy * y / z + cy + 0.5))
        if u < 0 or u >= width or v < 0 or v >= height:
            continue
        rendered = depth[v, u]
        # The depth image is float32: the occlusion bound is summed in float32 like numpy does.
        if rendered > 0 and z <= rendered + tolerance + share * rendered:
            seen[i] = True
            added += 1
    return added


class CoverageTracker:
    """Accumulates which ground-truth surface samples have been seen in an episode."""

    def __init__(self, samples_world: np.ndarray, camera: PinholeCamera, max_range_m: float):
        if len(samples_world) == 0:
            raise ValueError("coverage needs at least one surface sample")
        self.samples_world = np.ascontiguousarray(samples_world, np.float64)
        self.camera = camera
        self.max_range_m = float(max_range_m)
        self.seen = np.zeros(len(samples_world), dtype=bool)
        self.intrinsics = camera_intrinsics_vector(camera)
        self._count = 0

    def reset(self) -> None:
        self.seen[:] = False
        self._count = 0

    @property
    def coverage(self) -> float:
        """Share in [0, 1] of the surface samples seen so far."""
        return self._count / len(self.seen)

    def update(self, camera_to_world: np.ndarray, depth: np.ndarray) -> float:
        """Mark what a frame sees and return the coverage gain (share, not percent)."""
        before = self.coverage
        self._count += mark_visible_samples(
            self.samples_world, self.seen, np.ascontiguousarray(camera_to_world, np.float64),
            self.intrinsics, np.ascontiguousarray(depth, np.float32), self.max_range_m,
            COVERAGE_TOLERANCE_M,
        )
        return self.coverage - before


def camera_intrinsics_vector(camera: PinholeCamera) -> np.ndarray:
    """(6,) float64 ``(width, height, fx, fy, cx, cy)`` as the compiled kernels take them."""
    return np.array(
        [camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy], np.float64
    )
