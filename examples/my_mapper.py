"""A mapper of one's own for the NARUTO agent: a projective TSDF on a dense NumPy voxel grid."""

from __future__ import annotations

import numpy as np
import trimesh
from skimage.measure import marching_cubes

from naruto_agent.mapping import (
    ObservedSpace,
    SdfVolume,
    add_unknown_space_uncertainty,
    check_bounds,
    check_frame,
)
from naruto_gym.sensors.pinhole import PinholeCamera

#: The variance of a surface no frame has seen; a surface seen n times has 1 / (1 + n) of it.
INITIAL_VARIANCE = 1.0


class VoxelTsdfMapper:
    """Truncated signed distances averaged over the frames, one value per voxel.

    Args:
        bounds: (2, 3) world box of the scene, metres.
        camera: intrinsics of the frames.
        voxel_size_m: edge of a voxel.
        truncation_m: distances are kept up to this far from a measured surface; space no
            frame has measured reads as this far from any surface.
        max_depth_m: depths beyond this are not fused.
        map_every: ``integrate`` reports a changed map every n-th frame.
    """

    def __init__(
        self,
        bounds: np.ndarray,
        camera: PinholeCamera,
        voxel_size_m: float = 0.05,
        truncation_m: float = 0.15,
        max_depth_m: float = 5.0,
        map_every: int = 5,
    ) -> None:
        if truncation_m < 2 * voxel_size_m:
            raise ValueError("truncation_m must span at least two voxels")
        self.bounds = check_bounds(bounds)
        self.camera = camera
        self.truncation_m = truncation_m
        self.max_depth_m = max_depth_m
        self.map_every = map_every
        grid = SdfVolume.from_function(lambda p: np.zeros(len(p)), self.bounds, voxel_size_m)
        self.distances = SdfVolume(np.full(grid.shape, truncation_m), grid.origin, voxel_size_m)
        self.weights = np.zeros(grid.shape, np.float32)
        # The agent reads the explored space from here; this mapper feeds it every frame.
        self.observed_space = ObservedSpace(self.bounds)

    def integrate(
        self, rgb: np.ndarray, depth: np.ndarray, camera_to_world: np.ndarray, frame_index: int
    ) -> bool:
        """Fuse one frame; True every ``map_every``-th frame (the agent then re-plans)."""
        rgb, depth, pose = check_frame(rgb, depth, camera_to_world)
        cells = self._cells_near_surface(depth, pose)
        points = self.distances.voxel_to_world(cells)
        pixels, z = self.camera.project((points - pose[:3, 3]) @ pose[:3, :3])
        u, v = np.round(pixels).astype(np.int64).T
        seen = (z > 0) & (u >= 0) & (u < self.camera.width) & (v >= 0) & (v < self.camera.height)
        cells, u, v, z = cells[seen], u[seen], v[seen], z[seen]
        measured = depth[v, u]
        distance = measured - z  # projective distance, along the camera axis
        keep = (measured > 0) & (measured <= self.max_depth_m) & (distance >= -self.truncation_m)
        cells, distance = cells[keep], np.minimum(distance[keep], self.truncation_m)
        index = np.ravel_multi_index(tuple(cells.T), self.weights.shape)
        values, weights = self.distances.values.reshape(-1), self.weights.reshape(-1)
        values[index] = (values[index] * weights[index] + distance) / (weights[index] + 1)
        weights[index] += 1
        self.observed_space.integrate_depth(depth, pose, self.camera)
        return frame_index % self.map_every == 0

    def _cells_near_surface(self, depth: np.ndarray, pose: np.ndarray) -> np.ndarray:
        """(N, 3) distinct voxels within a truncation of the frame's measured surfaces (only
        these change: the voxels in front read as a truncation away already)."""
        rows, cols = np.nonzero((depth > 0) & (depth <= self.max_depth_m))
        z = depth[rows, cols].astype(np.float64)
        rays = np.stack(
            [
                (cols - self.camera.cx) / self.camera.fx,
                (rows - self.camera.cy) / self.camera.fy,
                np.ones_like(z),
            ],
            axis=1,
        )
        step = self.distances.voxel_size
        offsets = np.arange(-self.truncation_m, self.truncation_m + step / 2, step)
        along = (z[:, None] + offsets[None, :]).reshape(-1, 1)
        in_camera = np.repeat(rays, len(offsets), axis=0) * along
        world = in_camera @ pose[:3, :3].T + pose[:3, 3]
        cells = np.rint(self.distances.world_to_voxel(world)).astype(np.int64)
        shape = self.weights.shape
        cells = cells[np.all((cells >= 0) & (cells < np.asarray(shape)), axis=1)]
        flat = np.unique(np.ravel_multi_index(tuple(cells.T), shape))
        return np.stack(np.unravel_index(flat, shape), axis=1)

    def integrate_panorama(self, panorama: np.ndarray, position: np.ndarray) -> None:
        """Add the panorama's rays to the explored space."""
        self.observed_space.integrate_panorama(panorama, position)

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """(N,) signed distance in metres at (N, 3) world points, positive in free space."""
        points = np.asarray(points, np.float64).reshape(-1, 3)
        return self.distances.sample(points, outside_value=self.truncation_m).astype(np.float64)

    def planner_view(self, voxel_size: float = 0.1) -> tuple[SdfVolume, SdfVolume]:
        """(SDF, uncertainty) on one grid: a surface voxel's variance falls with every frame
        that saw it, and the frontier of unexplored space gets the initial variance."""
        sdf = SdfVolume.from_function(self.sdf, self.bounds, voxel_size)
        looks = SdfVolume(self.weights, self.distances.origin, self.distances.voxel_size)
        seen = looks.sample(sdf.grid_points(), outside_value=0.0).reshape(sdf.shape)
        surface = (sdf.values >= 0) & (sdf.values <= 0.5 * voxel_size)
        variance = np.where(surface, INITIAL_VARIANCE / (1.0 + seen), 0.0)
        uncertainty = SdfVolume(variance, sdf.origin, voxel_size)
        return sdf, add_unknown_space_uncertainty(
            uncertainty, self.observed_space, INITIAL_VARIANCE
        )

    def extract_mesh(self, voxel_size: float = 0.02) -> trimesh.Trimesh:
        """The zero level set over voxels a frame has measured, at this mapper's own
        resolution (``voxel_size`` is what the caller would like; the grid decides)."""
        values, observed = self.distances.values, self.weights > 0
        corners = [
            observed[
                i : i + observed.shape[0] - 1,
                j : j + observed.shape[1] - 1,
                k : k + observed.shape[2] - 1,
            ]
            for i in (0, 1)
            for j in (0, 1)
            for k in (0, 1)
        ]
        cubes = np.zeros_like(observed)
        cubes[:-1, :-1, :-1] = np.logical_and.reduce(corners)
        if not (cubes.any() and values[observed].min() < 0 < values[observed].max()):
            return trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
        step = self.distances.voxel_size
        vertices, faces, _, _ = marching_cubes(values, 0.0, spacing=(step,) * 3, mask=cubes)
        return trimesh.Trimesh(vertices + self.distances.origin, faces, process=False)
