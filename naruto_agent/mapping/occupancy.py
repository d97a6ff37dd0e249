"""A voxel occupancy map built from depth frames, with frontiers and grid path planning.

Each voxel holds a log-odds of being occupied. A depth frame is integrated by casting a
subsample of its pixels (every ``pixel_stride``-th pixel in both directions): the voxel of each
hit is made more occupied; voxels that rays pass through (sampled every half voxel, stopping
one voxel short of the hit) are made more free. Pixels with no hit within ``max_range_m`` mark
their whole ray up to that range as free. The rays are walked by a compiled kernel
(:func:`_trace_rays`) that visits every sample once and updates each touched voxel once per
frame, without the (rays x samples) arrays a vectorised walk needs.

States: *unknown* (never touched by a ray), *free* (log-odds below ``free_threshold``),
*occupied* (above ``occupied_threshold``). A *frontier* voxel is a free voxel with an unknown
face neighbour (Yamauchi, 1997). Paths run through *traversable* voxels: free, inside a height
band, and at least ``inflation_voxels`` away from any occupied voxel, found by a
minimum-cost-path search (``skimage.graph.MCP_Geometric``, 26-connected).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from scipy import ndimage
from skimage.graph import MCP_Geometric

from naruto_agent.mapping.grid_memory import check_grid_memory
from naruto_agent.mapping.occupancy_kernels import empty_sectors_below
from naruto_gym.motion.scanned_space import ScannedSpaceConfig, support_directions
from naruto_gym.sensors.pinhole import PinholeCamera

_FACE_NEIGHBOURS = ndimage.generate_binary_structure(3, 1)


@numba.njit(cache=True, nogil=True)
def _trace_rays(
    origin: np.ndarray, directions: np.ndarray, ranges: np.ndarray, max_range: float,
    grid_origin: np.ndarray, voxel: float, shape: np.ndarray, log_odds: np.ndarray,
    observed: np.ndarray, marks: np.ndarray, frame: int, miss: np.float32, hit: np.float32,
    low: np.float32, high: np.float32,
) -> None:
    """Walk every ray (samples every half voxel up to one voxel short of its hit, or to
    ``max_range`` without a hit) and update each touched voxel once: a hit voxel by ``hit``,
    a voxel only passed through by ``miss`` (clamped to [low, high]). ``marks`` (flat, int64)
    remembers which voxels this ``frame`` touched: 2 * frame + 1 hit, 2 * frame + 2 passed."""
    nx, ny, nz = shape[0], shape[1], shape[2]
    hit_mark = 2 * frame + 1
    free_mark = 2 * frame + 2
    count = ranges.shape[0]
    for r in range(count):  # the hits first: a voxel hit in this frame is not also cleared
        value = ranges[r]
        if not (np.isfinite(value) and value > 0.0 and value <= max_range):
            continue
        i = int(np.floor((origin[0] + directions[r, 0] * value - grid_origin[0]) / voxel))
        j = int(np.floor((origin[1] + directions[r, 1] * value - grid_origin[1]) / voxel))
        k = int(np.floor((origin[2] + directions[r, 2] * value - grid_origin[2]) / voxel))
        if 0 <= i < nx and 0 <= j < ny and 0 <= k < nz:
            flat = (i * ny + j) * nz + k
            if marks[flat] != hit_mark:
                marks[flat] = hit_mark
                log_odds[flat] = min(log_odds[flat] + hit, high)
                observed[flat] = True
    spacing = voxel / 2.0
    steps = int(np.ceil(max_range / spacing))
    for r in range(count):
        value = ranges[r]
        if value == 0.0:
            length = max_range
        elif np.isfinite(value) and value > 0.0:
            length = value - voxel if value <= max_range else max_range
        else:
            continue
        for step in range(1, steps + 1):
            distance = step * spacing
            if distance > length:
                break
            i = int(np.floor((origin[0] + directions[r, 0] * distance - grid_origin[0]) / voxel))
            j = int(np.floor((origin[1] + directions[r, 1] * distance - grid_origin[1]) / voxel))
            k = int(np.floor((origin[2] + directions[r, 2] * distance - grid_origin[2]) / voxel))
            if 0 <= i < nx and 0 <= j < ny and 0 <= k < nz:
                flat = (i * ny + j) * nz + k
                if marks[flat] != hit_mark and marks[flat] != free_mark:
                    marks[flat] = free_mark
                    log_odds[flat] = max(log_odds[flat] + miss, low)
                    observed[flat] = True


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
        hit_log_odds: log-odds increment of a hit.
        miss_log_odds: log-odds increment of a pass-through.
        clamp: log-odds are kept within (-clamp[0], clamp[1]).
        occupied_threshold: log-odds above which a voxel is occupied.
        free_threshold: log-odds below which a voxel is free.
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
        check_grid_memory(self.shape, 5, self.voxel_size_m, "occupancy map")
        self.max_range_m = float(max_range_m)
        self._pixel_stride = int(pixel_stride)
        self.hit_log_odds = float(hit_log_odds)
        self.miss_log_odds = float(miss_log_odds)
        self.clamp = (-float(clamp[0]), float(clamp[1]))
        self.occupied_threshold = float(occupied_threshold)
        self.free_threshold = float(free_threshold)
        self.log_odds = np.zeros(self.shape, np.float32)
        self.observed = np.zeros(self.shape, bool)
        self._ray_cache: tuple[PinholeCamera, np.ndarray] | None = None
        self._marks: np.ndarray | None = None  # per-voxel stamp of the frame that touched it
        self._frame = 0

    @property
    def pixel_stride(self) -> int:
        """Every n-th pixel of a depth frame, in each image direction, is integrated."""
        return self._pixel_stride

    @pixel_stride.setter
    def pixel_stride(self, stride: int) -> None:
        # The cached camera rays are those of the old stride's pixels.
        stride = int(stride)
        if stride < 1:
            raise ValueError(f"pixel_stride must be at least 1, got {stride}")
        if stride != self._pixel_stride:
            self._pixel_stride = stride
            self._ray_cache = None

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

    def frontier(self, unknown_below_z: float | None = None) -> np.ndarray:
        """Free voxels with at least one unknown face neighbour; with ``unknown_below_z``,
        only unknown voxels whose centres lie below that height count (above the top of an
        open scan, the unknown is sky that no view can resolve)."""
        unknown = self.unknown
        if unknown_below_z is not None:
            unknown = unknown & self.levels_within((-np.inf, unknown_below_z))[None, None, :]
        unknown_near = ndimage.binary_dilation(unknown, _FACE_NEIGHBOURS)
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
            result &= self.levels_within(z_band)[None, None, :]
        return result

    def levels_within(self, z_band: tuple[float, float]) -> np.ndarray:
        """(nz,) bool: the voxel levels whose centres lie within ``z_band`` (min, max) metres."""
        z = self.origin[2] + (np.arange(self.shape[2]) + 0.5) * self.voxel_size_m
        return (z >= z_band[0]) & (z <= z_band[1])

    def supported_below(self, below_m: float, reach_m: float) -> np.ndarray:
        """(nx, ny, nz) bool: voxels with an occupied voxel below them, at most ``below_m``
        down and ``reach_m`` sideways (a coarse version of the env's cone test: a floor seen
        only around a table still supports the space above the table)."""
        voxel = self.voxel_size_m
        occupied = self.occupied
        reach = int(round(reach_m / voxel))
        if reach:
            occupied = ndimage.maximum_filter(occupied, size=(2 * reach + 1,) * 2 + (1,))
        depth = max(1, math.ceil(below_m / voxel - 1e-9))
        # below[z] = occupied voxels in z - depth .. z - 1 of the (widened) column.
        total = np.cumsum(occupied, axis=2, dtype=np.int32)
        total = np.concatenate([np.zeros(total.shape[:2] + (1,), np.int32), total], axis=2)
        upper = total[:, :, :-1]
        lower = total[:, :, np.maximum(np.arange(total.shape[2] - 1) - depth, 0)]
        return upper - lower > 0

    def occupied_top_z(self, quantile: float) -> float:
        """Height (world z of voxel tops) under which ``quantile`` of the occupied voxels
        lie; +inf before anything was measured occupied. A scan without a ceiling ends at its
        wall tops; a few stray fragments above barely move the quantile."""
        levels = np.nonzero(self.occupied)[2]
        if len(levels) == 0:
            return float("inf")
        level = np.quantile(levels, quantile, method="higher")
        return float(self.origin[2] + (level + 1) * self.voxel_size_m)

    def sectors_seen_below(self, points: np.ndarray, max_length_m: float = 5.0) -> np.ndarray:
        """(N,) bool: every azimuth sector of the env's downward support cone
        (:func:`naruto_gym.motion.scanned_space.support_directions`: 8 sectors of a cone of 60
        degrees around straight down) meets an occupied voxel of this grid from the point.

        The env's scanned-space rule asks that of the scan itself; asked of what a policy has
        measured, it tells a point inside a room (floor and walls below all around) from one
        in a wall's opening, past a missing wall or over the edge of a floor hole.
        """
        points = np.ascontiguousarray(np.asarray(points, np.float64).reshape(-1, 3))
        if len(points) == 0:
            return np.zeros(0, bool)
        directions, sectors = support_directions(ScannedSpaceConfig())
        empty = empty_sectors_below(
            points, directions.astype(np.float64), sectors, int(sectors.max()) + 1,
            self.occupied, np.asarray(self.origin, np.float64), self.voxel_size_m,
            float(max_length_m),
        )
        return empty == 0

    def move_leaves_support(self, start: np.ndarray, end: np.ndarray, probe_m: float) -> bool:
        """A move from a point that passes :meth:`sectors_seen_below` towards one ``probe_m``
        beyond its end (horizontally) that fails it: the move heads over the edge of the
        measured floor. The probe lies past the end because a 0.1 m grid blurs that edge by up
        to a voxel, and the env keeps the agent's clearance from it."""
        start, end = np.asarray(start, np.float64), np.asarray(end, np.float64)
        across = np.array([end[0] - start[0], end[1] - start[1], 0.0])
        length = float(np.linalg.norm(across))
        if length < 1e-9:
            return False
        probe = end + probe_m * across / length
        held = self.sectors_seen_below(np.stack([start, probe]))
        return bool(held[0] and not held[1])

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
        directions = np.ascontiguousarray(directions, np.float64).reshape(-1, 3)
        ranges = np.ascontiguousarray(ranges, np.float64).reshape(-1)
        if len(ranges) != len(directions):
            raise ValueError(f"{len(directions)} directions but {len(ranges)} ranges")
        if self._marks is None or self._marks.size != self.log_odds.size:
            self._marks = np.zeros(self.log_odds.size, np.int64)
            self._frame = 0
        self._frame += 1
        _trace_rays(
            origin, directions, ranges, float(self.max_range_m),
            np.asarray(self.origin, np.float64), float(self.voxel_size_m),
            np.asarray(self.shape, np.int64), self.log_odds.reshape(-1),
            self.observed.reshape(-1), self._marks, self._frame,
            np.float32(self.miss_log_odds), np.float32(self.hit_log_odds),
            np.float32(self.clamp[0]), np.float32(self.clamp[1]),
        )

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
