"""Where coverage is computed: the share of the ground-truth surface seen so far.

The surface is represented by area-uniform samples. A sample counts as seen once it falls in
the pinhole frustum of some frame, within the coverage range, and in front of (or on) the
rendered depth at its pixel, i.e. not occluded.
"""

from __future__ import annotations

from typing import NamedTuple

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


# Side (metres) of the grid cells that group the surface samples: a frame skips every cell
# whose bounding sphere lies outside its view volume (most of them: a 90 degree frustum sees a
# fraction of a room) without touching the cell's samples.
SAMPLE_CELL_M = 0.5


class SampleCells(NamedTuple):
    """Surface samples grouped by grid cell, for culling whole cells against a frame.

    Attributes:
        order: (N,) int64 sample indices, cell after cell.
        starts: (C + 1,) int64: cell ``c`` holds ``order[starts[c]:starts[c + 1]]``.
        centres: (C, 3) float64 centre of each cell's samples' bounding box.
        radii: (C,) float64 distance from the centre to the cell's farthest sample.
    """

    order: np.ndarray
    starts: np.ndarray
    centres: np.ndarray
    radii: np.ndarray


def sample_cells(samples_world: np.ndarray, cell_m: float = SAMPLE_CELL_M) -> SampleCells:
    """Group samples (N, 3) by the grid cell of side ``cell_m`` they fall in (pure function)."""
    samples = np.asarray(samples_world, np.float64)
    if cell_m <= 0:
        raise ValueError(f"cell_m must be positive, got {cell_m}")
    cells = np.floor((samples - samples.min(axis=0)) / cell_m).astype(np.int64)
    size = cells.max(axis=0) + 1
    keys = (cells[:, 0] * size[1] + cells[:, 1]) * size[2] + cells[:, 2]
    order = np.argsort(keys, kind="stable").astype(np.int64)
    ordered = keys[order]
    firsts = np.flatnonzero(np.r_[True, ordered[1:] != ordered[:-1]])
    starts = np.r_[firsts, len(samples)].astype(np.int64)
    points = samples[order]
    centres = (np.minimum.reduceat(points, firsts) + np.maximum.reduceat(points, firsts)) / 2.0
    owner = np.repeat(np.arange(len(firsts)), np.diff(starts))
    radii = np.maximum.reduceat(np.linalg.norm(points - centres[owner], axis=1), firsts)
    return SampleCells(order, starts, centres, radii)


@numba.njit(cache=True, nogil=True, inline="always")
def _sees_sample(
    samples_world, i, r, tx, ty, tz, width, height, fx, fy, cx, cy, depth, max_range_m,
    tolerance, share,
):
    """Whether the frame sees sample ``i`` (in view, in range, not occluded)."""
    dx = samples_world[i, 0] - tx
    dy = samples_world[i, 1] - ty
    dz = samples_world[i, 2] - tz
    z = dx * r[0, 2] + dy * r[1, 2] + dz * r[2, 2]
    if not (z > 1e-3 and z <= max_range_m):
        return False
    x = dx * r[0, 0] + dy * r[1, 0] + dz * r[2, 0]
    y = dx * r[0, 1] + dy * r[1, 1] + dz * r[2, 1]
    u = int(np.floor(fx * x / z + cx + 0.5))
    v = int(np.floor(fy * y / z + cy + 0.5))
    if u < 0 or u >= width or v < 0 or v >= height:
        return False
    rendered = depth[v, u]
    # The depth image is float32: the occlusion bound is summed in float32 like numpy does.
    return rendered > 0 and z <= rendered + tolerance + share * rendered


@numba.njit(cache=True, nogil=True, inline="always")
def _outside_plane(x, z, slope, reach):
    """Whether a ball (centre x, z in the plane's cut, ``reach`` its radius plus a margin)
    lies wholly on the side of the plane x = slope * z through the camera centre where x is
    smaller."""
    return (x - slope * z) / np.sqrt(1.0 + slope * slope) < -reach


@numba.njit(cache=True, nogil=True)
def mark_visible_in_cells(
    samples_world: np.ndarray,
    order: np.ndarray,
    starts: np.ndarray,
    centres: np.ndarray,
    radii: np.ndarray,
    seen: np.ndarray,
    unseen_in_cell: np.ndarray,
    camera_to_world: np.ndarray,
    intrinsics: np.ndarray,
    depth: np.ndarray,
    max_range_m: float,
    tolerance_m: float,
) -> int:
    """Compiled :func:`visible_samples` that only visits unseen samples, and skips the cells
    (:func:`sample_cells`) with none left or whose bounding sphere lies wholly outside the
    frame's view volume: sets ``seen[i]`` for every sample the frame sees and returns how many
    were newly seen.

    Args:
        samples_world: (N, 3) float64 surface samples.
        order, starts, centres, radii: their :class:`SampleCells`.
        seen: (N,) bool, updated in place.
        unseen_in_cell: (C,) int64 samples of each cell not seen yet, updated in place (an
            episode sees most of a room's cells whole, and then skips them).
        camera_to_world: 4x4 float64 pose.
        intrinsics: (6,) float64 ``(width, height, fx, fy, cx, cy)``.
        depth: (H, W) float32 z-depth, 0 where nothing was hit.
        max_range_m: samples farther (in z) than this are not counted.
        tolerance_m: as in :func:`visible_samples`.

    A pixel (u, v) is in the image when ``u = floor(fx * x / z + cx + 0.5)`` lies in
    ``[0, width)``: for z > 0 that is ``lo * z <= x < hi * z`` with ``lo = -(cx + 0.5) / fx``
    and ``hi = (width - 0.5 - cx) / fx``, four planes through the camera centre (likewise in
    y); with the near (z > 1e-3) and far (z <= range) planes they bound the view volume.
    """
    width, height = int(intrinsics[0]), int(intrinsics[1])
    fx, fy, cx, cy = intrinsics[2], intrinsics[3], intrinsics[4], intrinsics[5]
    r = camera_to_world
    tx, ty, tz = r[0, 3], r[1, 3], r[2, 3]
    tolerance, share = np.float32(tolerance_m), np.float32(0.01)
    left, right = -(cx + 0.5) / fx, (width - 0.5 - cx) / fx
    top, bottom = -(cy + 0.5) / fy, (height - 0.5 - cy) / fy
    added = 0
    for cell in range(starts.shape[0] - 1):
        if unseen_in_cell[cell] == 0:
            continue
        dx = centres[cell, 0] - tx
        dy = centres[cell, 1] - ty
        dz = centres[cell, 2] - tz
        z = dx * r[0, 2] + dy * r[1, 2] + dz * r[2, 2]
        x = dx * r[0, 0] + dy * r[1, 0] + dz * r[2, 0]
        y = dx * r[0, 1] + dy * r[1, 1] + dz * r[2, 1]
        # A margin well above rounding keeps the culling conservative.
        reach = radii[cell] * (1.0 + 1e-9) + 1e-6
        if (
            z + reach <= 1e-3
            or z - reach > max_range_m
            or _outside_plane(x, z, left, reach)
            or _outside_plane(-x, z, -right, reach)
            or _outside_plane(y, z, top, reach)
            or _outside_plane(-y, z, -bottom, reach)
        ):
            continue
        for k in range(starts[cell], starts[cell + 1]):
            i = order[k]
            if not seen[i] and _sees_sample(
                samples_world, i, r, tx, ty, tz, width, height, fx, fy, cx, cy, depth,
                max_range_m, tolerance, share,
            ):
                seen[i] = True
                unseen_in_cell[cell] -= 1
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
        self.cells = sample_cells(self.samples_world)
        self.cell_sizes = np.diff(self.cells[1]).astype(np.int64)
        self.unseen_in_cell = self.cell_sizes.copy()
        self._count = 0

    def reset(self) -> None:
        self.seen[:] = False
        self.unseen_in_cell[:] = self.cell_sizes
        self._count = 0

    @property
    def coverage(self) -> float:
        """Share in [0, 1] of the surface samples seen so far."""
        return self._count / len(self.seen)

    def update(self, camera_to_world: np.ndarray, depth: np.ndarray) -> float:
        """Mark what a frame sees and return the coverage gain (share, not percent)."""
        before = self.coverage
        self._count += mark_visible_in_cells(
            self.samples_world, *self.cells, self.seen, self.unseen_in_cell,
            np.ascontiguousarray(camera_to_world, np.float64), self.intrinsics,
            np.ascontiguousarray(depth, np.float32), self.max_range_m, COVERAGE_TOLERANCE_M,
        )
        return self.coverage - before


def camera_intrinsics_vector(camera: PinholeCamera) -> np.ndarray:
    """(6,) float64 ``(width, height, fx, fy, cx, cy)`` as the compiled kernels take them."""
    return np.array(
        [camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy], np.float64
    )
