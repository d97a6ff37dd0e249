"""A voxel occupancy map built from depth frames, with frontiers and grid path planning.

Each voxel holds a log-odds of being occupied. A depth frame is integrated by casting a
subsample of its pixels (every ``pixel_stride``-th pixel in both directions): the voxel of each
hit is made more occupied; voxels that rays pass through (sampled every half voxel, stopping
one voxel short of the hit) are made more free. Pixels with no hit within ``max_range_m`` mark
their whole ray up to that range as free. Everything is vectorised numpy, with a fixed number
of samples per ray and a mask.

States: *unknown* (never touched by a ray), *free* (log-odds below ``free_threshold``),
*occupied* (above ``occupied_threshold``). A *frontier* voxel is a free voxel with an unknown
face neighbour (Yamauchi, 1997). Paths run through *traversable* voxels: free, inside a height
band, and at least ``inflation_voxels`` away from any occupied voxel, found by a
minimum-cost-path search (``skimage.graph.MCP_Geometric``, 26-connected).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from skimage.graph import MCP_Geometric

from naruto_gym.sensors.pinhole import PinholeCamera

_FACE_NEIGHBOURS = ndimage.generate_binary_structure(3, 1)


@dataclass
class PathPlan:
    """Result of a search from one start cell: cumulative costs (metres; inf = unreachable)
    and the MCP object to trace paths back."""

    costs: np.ndarray
    mcp: MCP_Geometric
    start: tuple[int, int, int]


class OccupancyGrid:
    """Log-odds occupancy voxels over an axis-aligned box.

    Args:
        bounds: (2, 3) box (min, max) the map covers, metres.
        voxel_size_m: voxel edge (0.1 m).
        max_range_m: depth beyond this is not integrated (5 m, the mapping range).
        pixel_stride: integrate every n-th pixel in each image direction.
        hit_log_odds, miss_log_odds: log-odds increments of a hit and a pass-through.
        clamp: log-odds are kept within (-clamp[0], clamp[1]).
        occupied_threshold, free_threshold: log-odds thresholds of the two states.
    """

    def __init__(
        self,
        bounds: np.ndarray,
        voxel_size_m: float = 0.1,
        max_range_m: float = 5.0,
        pixel_stride: int = 4,
        hit_log_odds: float = 0.85,
        miss_log_odds: float = -0.4,
        clamp: tuple[float, float] = (2.0, 3.5),
        occupied_threshold: float = 0.4,
        free_threshold: float = -0.2,
    ) -> None:
        bounds = np.asarray(bounds, np.float64)
        if bounds.shape != (2, 3) or np.any(bounds[1] <= bounds[0]):
            raise ValueError(f"bounds must be (2, 3) with max > min, got {bounds.tolist()}")
        if voxel_size_m <= 0 or max_range_m <= 0 or pixel_stride < 1:
            raise ValueError("voxel_size_m and max_range_m must be positive, pixel_stride >= 1")
        self.origin = bounds[0].copy()
        self.voxel_size_m = float(voxel_size_m)
        self.shape = tuple(int(n) for n in np.ceil((bounds[1] - bounds[0]) / voxel_size_m))
        self.max_range_m = float(max_range_m)
        self.pixel_stride = int(pixel_stride)
        self.hit_log_odds = float(hit_log_odds)
        self.miss_log_odds = float(miss_log_odds)
        self.clamp = (-float(clamp[0]), float(clamp[1]))
        self.occupied_threshold = float(occupied_threshold)
        self.free_threshold = float(free_threshold)
        self.log_odds = np.zeros(self.shape, np.float32)
        self.observed = np.zeros(self.shape, bool)
        self._ray_cache: tuple[PinholeCamera, np.ndarray] | None = None

    # -- coordinates ---------------------------------------------------------------------
    def world_to_cell(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) integer cell indices of world points (may lie outside the grid)."""
        return np.floor((np.asarray(points) - self.origin) / self.voxel_size_m).astype(np.int64)

    def cell_to_world(self, cells: np.ndarray) -> np.ndarray:
        """(N, 3) world centres of cells."""
        return self.origin + (np.asarray(cells, np.float64) + 0.5) * self.voxel_size_m

    def in_grid(self, cells: np.ndarray) -> np.ndarray:
        cells = np.atleast_2d(cells)
        return np.all((cells >= 0) & (cells < np.array(self.shape)), axis=1)

    def _flat(self, cells: np.ndarray) -> np.ndarray:
        return np.ravel_multi_index(cells.T, self.shape)

    # -- states --------------------------------------------------------------------------
    @property
    def occupied(self) -> np.ndarray:
        return self.observed & (self.log_odds > self.occupied_threshold)

    @property
    def free(self) -> np.ndarray:
        return self.observed & (self.log_odds < self.free_threshold)

    @property
    def unknown(self) -> np.ndarray:
        return ~self.observed

    def frontier(self) -> np.ndarray:
        """Free voxels with at least one unknown face neighbour."""
        unknown_near = ndimage.binary_dilation(self.unknown, _FACE_NEIGHBOURS)
        return self.free & unknown_near

    def traversable(
        self, inflation_voxels: int = 1, z_band: tuple[float, float] | None = None
    ) -> np.ndarray:
        """Free voxels at least ``inflation_voxels`` (26-neighbourhood rings) from occupied
        ones, optionally only with centres within ``z_band`` (min, max) metres."""
        blocked = self.occupied
        if inflation_voxels > 0:
            blocked = ndimage.binary_dilation(
                blocked, ndimage.generate_binary_structure(3, 3), iterations=inflation_voxels
            )
        result = self.free & ~blocked
        if z_band is not None:
            z = self.origin[2] + (np.arange(self.shape[2]) + 0.5) * self.voxel_size_m
            result &= ((z >= z_band[0]) & (z <= z_band[1]))[None, None, :]
        return result

    def mark_occupied(self, points: np.ndarray) -> None:
        """Mark the voxels of world points occupied (e.g. where a move bumped into something)."""
        cells = self.world_to_cell(np.atleast_2d(points))
        cells = cells[self.in_grid(cells)]
        if len(cells):
            index = tuple(cells.T)
            self.log_odds[index] = self.clamp[1]
            self.observed[index] = True

    # -- integration ---------------------------------------------------------------------
    def _camera_rays(self, camera: PinholeCamera) -> np.ndarray:
        """(R, 3) camera-frame directions (z = 1) of the subsampled pixels."""
        if self._ray_cache is None or self._ray_cache[0] != camera:
            start = self.pixel_stride // 2
            v, u = np.meshgrid(
                np.arange(start, camera.height, self.pixel_stride),
                np.arange(start, camera.width, self.pixel_stride),
                indexing="ij",
            )
            rays = np.stack(
                [(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones(u.shape)],
                axis=-1,
            ).reshape(-1, 3)
            self._ray_cache = (camera, rays)
        return self._ray_cache[1]

    def integrate(
        self, depth: np.ndarray, camera_to_world: np.ndarray, camera: PinholeCamera
    ) -> None:
        """Integrate one depth frame (z-depth metres, 0 = no hit) seen from a pose."""
        depth = np.asarray(depth, np.float32)
        if depth.shape != (camera.height, camera.width):
            raise ValueError(
                f"depth shape {depth.shape} does not match the camera ({camera.height}, "
                f"{camera.width})"
            )
        start = self.pixel_stride // 2
        sampled = depth[start :: self.pixel_stride, start :: self.pixel_stride].reshape(-1)
        rays_camera = self._camera_rays(camera)
        norms = np.linalg.norm(rays_camera, axis=1)
        rotation = np.asarray(camera_to_world, np.float64)[:3, :3]
        directions = (rays_camera / norms[:, None]) @ rotation.T
        # z-depth -> distance along the ray; 0 (no hit) stays 0.
        self.integrate_rays(np.asarray(camera_to_world, np.float64)[:3, 3], directions,
                            sampled * norms)

    def integrate_rays(
        self, origin: np.ndarray, directions: np.ndarray, ranges: np.ndarray
    ) -> None:
        """Integrate rays from one origin: unit world ``directions`` (R, 3) and the distance
        to their hit ``ranges`` (R,), 0 where a ray hit nothing (e.g. a depth panorama).

        A ray with no hit within ``max_range_m`` clears its whole length up to that range;
        a ray with a non-finite or negative range is ignored.
        """
        origin = np.asarray(origin, np.float64).reshape(3)
        directions = np.asarray(directions, np.float64).reshape(-1, 3)
        ranges = np.asarray(ranges, np.float64).reshape(-1)
        if len(ranges) != len(directions):
            raise ValueError(f"{len(directions)} directions but {len(ranges)} ranges")
        valid = np.isfinite(ranges) & (ranges > 0.0)
        hit = valid & (ranges <= self.max_range_m)
        free_length = np.where(hit, ranges - self.voxel_size_m, self.max_range_m)
        free_length = np.where(valid | (ranges == 0.0), free_length, 0.0)

        spacing = self.voxel_size_m / 2.0
        steps = np.arange(1, int(np.ceil(self.max_range_m / spacing)) + 1) * spacing
        keep = steps[None, :] <= free_length[:, None]
        ray_index, step_index = np.nonzero(keep)
        points = origin + directions[ray_index] * steps[step_index, None]
        free_cells = self.world_to_cell(points)
        free_cells = free_cells[self.in_grid(free_cells)]
        free_flat = np.unique(self._flat(free_cells)) if len(free_cells) else np.zeros(0, np.int64)

        hit_points = origin + directions[hit] * ranges[hit, None]
        hit_cells = self.world_to_cell(hit_points)
        hit_cells = hit_cells[self.in_grid(hit_cells)]
        hit_flat = np.unique(self._flat(hit_cells)) if len(hit_cells) else np.zeros(0, np.int64)
        # A voxel hit in this frame is not also cleared by rays that graze it.
        free_flat = np.setdiff1d(free_flat, hit_flat, assume_unique=True)

        log_odds = self.log_odds.reshape(-1)
        observed = self.observed.reshape(-1)
        log_odds[free_flat] = np.maximum(log_odds[free_flat] + self.miss_log_odds, self.clamp[0])
        log_odds[hit_flat] = np.minimum(log_odds[hit_flat] + self.hit_log_odds, self.clamp[1])
        observed[free_flat] = True
        observed[hit_flat] = True

    # -- planning ------------------------------------------------------------------------
    def plan_from(self, start_cell: np.ndarray, traversable: np.ndarray) -> PathPlan:
        """Path costs (metres) from ``start_cell`` through ``traversable`` voxels."""
        costs = np.where(traversable, 1.0, np.inf)
        start = tuple(int(c) for c in start_cell)
        costs[start] = 1.0  # the start itself is always usable
        mcp = MCP_Geometric(costs, fully_connected=True)
        cumulative, _ = mcp.find_costs([start])
        return PathPlan(cumulative * self.voxel_size_m, mcp, start)

    @staticmethod
    def trace_path(plan: PathPlan, goal_cell: np.ndarray) -> np.ndarray:
        """(K, 3) cells from the start to ``goal_cell`` (must be reachable)."""
        return np.array(plan.mcp.traceback(tuple(int(c) for c in goal_cell)), dtype=np.int64)

    def segment_is_traversable(
        self, start: np.ndarray, end: np.ndarray, traversable: np.ndarray
    ) -> bool:
        """True when every half-voxel sample of the world segment lies in a traversable voxel
        (the start voxel excepted)."""
        length = float(np.linalg.norm(end - start))
        count = max(int(np.ceil(length / (self.voxel_size_m / 2.0))), 1)
        points = start + (end - start) * (np.arange(1, count + 1) / count)[:, None]
        cells = self.world_to_cell(points)
        if not np.all(self.in_grid(cells)):
            return False
        start_cell = self.world_to_cell(start[None])[0]
        own = np.all(cells == start_cell, axis=1)
        return bool(np.all(traversable[tuple(cells[~own].T)]))
