"""Where coverage is computed: the share of the ground-truth surface seen so far.

The surface is represented by area-uniform samples. A sample counts as seen once it falls in
the pinhole frustum of some frame, within the coverage range, and in front of (or on) the
rendered depth at its pixel, i.e. not occluded.
"""

from __future__ import annotations

import numpy as np

from naruto_gym.sensors.pinhole import PinholeCamera


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


class CoverageTracker:
    """Accumulates which ground-truth surface samples have been seen in an episode."""

    def __init__(self, samples_world: np.ndarray, camera: PinholeCamera, max_range_m: float):
        if len(samples_world) == 0:
            raise ValueError("coverage needs at least one surface sample")
        self.samples_world = np.asarray(samples_world, np.float64)
        self.camera = camera
        self.max_range_m = float(max_range_m)
        self.seen = np.zeros(len(samples_world), dtype=bool)

    def reset(self) -> None:
        self.seen[:] = False

    @property
    def coverage(self) -> float:
        """Share in [0, 1] of the surface samples seen so far."""
        return float(self.seen.mean())

    def update(self, camera_to_world: np.ndarray, depth: np.ndarray) -> float:
        """Mark what a frame sees and return the coverage gain (share, not percent)."""
        before = self.coverage
        self.seen |= visible_samples(
            self.samples_world, camera_to_world, self.camera, depth, self.max_range_m
        )
        return self.coverage - before
