"""What the agent has measured of space, and the uncertainty of what it has not.

A map built from depth knows only the surfaces it has seen. NARUTO's uncertainty has a
meaning beyond them: what no frame has measured is maximally uncertain. The neural field
expresses that by extrapolating a surface into unexplored space whose variance is still the
grid's initial one; a TSDF (or a neural field that extrapolates free space) has nothing
there, so an agent planning on it polishes what it has and never heads into new rooms.

:class:`ObservedSpace` keeps a coarse occupancy grid (log-odds, 0.1 m) of every frame's rays
(and of the depth panorama, when the agent has one): voxels are *unknown* (no ray has passed
them), *free* or *occupied*. Its *frontier* is the free space next to unknown space
(Yamauchi, 1997), in clusters of at least ``min_cluster_voxels`` (smaller ones are sensor
noise: a grazing ray, a pixel between two objects).

:func:`add_unknown_space_uncertainty` turns the frontier into targets of the goal search: a
frontier voxel gets the mapper's *initial* variance, the largest any voxel can have, so
unexplored space outranks every surface already seen, and surfaces win again once the
frontier is exhausted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from naruto_agent.planning.sdf_volume import SdfVolume
from naruto_agent.policies.occupancy import OccupancyGrid
from naruto_gym.sensors.pinhole import PinholeCamera

_ALL_NEIGHBOURS = np.ones((3, 3, 3), bool)


@dataclass(frozen=True)
class ObservedSpaceConfig:
    """Settings of :class:`ObservedSpace`.

    Attributes:
        voxel_size_m: voxel of the occupancy grid (0.1 m, the planner's grid).
        max_range_m: rays are integrated up to this range (5 m, the mapping range).
        rays_per_frame: about this many rays of each depth frame or panorama are
            integrated (a regular subsample; 2048 resolve 0.1 m voxels out to several metres
            and cost a few milliseconds).
        min_cluster_voxels: frontier clusters (26-connected) smaller than this are ignored.
    """

    voxel_size_m: float = 0.1
    max_range_m: float = 5.0
    rays_per_frame: int = 2048
    min_cluster_voxels: int = 8

    def __post_init__(self) -> None:
        if not (self.voxel_size_m > 0 and self.max_range_m > 0):
            raise ValueError("voxel_size_m and max_range_m must be positive")
        if self.rays_per_frame < 1 or self.min_cluster_voxels < 1:
            raise ValueError("rays_per_frame and min_cluster_voxels must be at least 1")


class ObservedSpace:
    """Unknown / free / occupied voxels from depth frames and panoramas, with a frontier.

    Args:
        bounds: (2, 3) world box of the scene.
        config: settings.
    """

    def __init__(self, bounds: np.ndarray, config: ObservedSpaceConfig | None = None) -> None:
        self.config = config or ObservedSpaceConfig()
        self.bounds = np.asarray(bounds, np.float64)
        self.grid = OccupancyGrid(self.bounds, self.config.voxel_size_m, self.config.max_range_m)
        self._frontier: np.ndarray | None = None

    def _stride(self, camera: PinholeCamera) -> int:
        pixels = camera.width * camera.height
        return max(1, int(round(math.sqrt(pixels / self.config.rays_per_frame))))

    def integrate_depth(
        self, depth: np.ndarray, camera_to_world: np.ndarray, camera: PinholeCamera
    ) -> None:
        """Integrate a pinhole z-depth frame (0 = no hit) seen from ``camera_to_world``."""
        stride = self._stride(camera)
        if stride != self.grid.pixel_stride:
            self.grid.pixel_stride = stride
            self.grid._ray_cache = None
        self.grid.integrate(depth, camera_to_world, camera)
        self._frontier = None

    def integrate_panorama(self, panorama: np.ndarray, position: np.ndarray) -> None:
        """Integrate an equirectangular radial-distance panorama (0 = no hit) taken at
        ``position`` (rows from straight up to straight down, columns from azimuth -pi;
        see :mod:`naruto_gym.sensors.panorama`)."""
        from naruto_gym.sensors.panorama import EquirectangularCamera

        panorama = np.asarray(panorama, np.float32)
        if panorama.ndim != 2:
            raise ValueError(f"panorama must be an (h, w) distance image, got {panorama.shape}")
        directions = EquirectangularCamera(*panorama.shape).ray_directions
        step = max(1, int(round(math.sqrt(panorama.size / self.config.rays_per_frame))))
        rows = np.arange(step // 2, panorama.shape[0], step)
        columns = np.arange(step // 2, panorama.shape[1], step)
        flat = (rows[:, None] * panorama.shape[1] + columns[None, :]).reshape(-1)
        self.grid.integrate_rays(position, directions[flat], panorama.reshape(-1)[flat])
        self._frontier = None

    def mark_occupied(self, points: np.ndarray) -> None:
        """Mark the voxels of world points as occupied (e.g. where a move was refused)."""
        self.grid.mark_occupied(points)
        self._frontier = None

    @property
    def observed_fraction(self) -> float:
        """Share of the grid's voxels that some ray has reached (a measure of progress)."""
        return float(self.grid.observed.mean())

    def frontier(self) -> np.ndarray:
        """(nx, ny, nz) bool: free voxels next to unknown ones, in clusters big enough."""
        if self._frontier is None:
            frontier = self.grid.frontier()
            labels, count = ndimage.label(frontier, _ALL_NEIGHBOURS)
            if count:
                sizes = np.bincount(labels.reshape(-1), minlength=count + 1)
                big = sizes >= self.config.min_cluster_voxels
                big[0] = False
                frontier = big[labels]
            self._frontier = frontier
        return self._frontier

    def cells_of(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) grid cells of world points, clipped into the grid, and (N,) inside flags."""
        cells = self.grid.world_to_cell(np.asarray(points, np.float64).reshape(-1, 3))
        inside = self.grid.in_grid(cells)
        return np.clip(cells, 0, np.array(self.grid.shape) - 1), inside

    def sample(self, grid: np.ndarray, points: np.ndarray) -> np.ndarray:
        """(N,) values of a per-voxel array of this grid at world points (False/0 outside)."""
        cells, inside = self.cells_of(points)
        values = grid[cells[:, 0], cells[:, 1], cells[:, 2]]
        return np.where(inside, values, np.zeros((), values.dtype))

    def state_dict(self) -> dict[str, np.ndarray]:
        return {"log_odds": self.grid.log_odds.copy(), "observed": self.grid.observed.copy()}

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        if np.shape(state["log_odds"]) != self.grid.shape:
            raise ValueError("saved observed-space grid does not match these bounds/voxel size")
        self.grid.log_odds = np.asarray(state["log_odds"], np.float32).copy()
        self.grid.observed = np.asarray(state["observed"], bool).copy()
        self._frontier = None


def add_unknown_space_uncertainty(
    uncertainty: SdfVolume, observed: ObservedSpace, initial_variance: float
) -> SdfVolume:
    """The planner's uncertainty volume with frontier voxels at the initial variance.

    Args:
        uncertainty: the mapper's uncertainty volume (0 except on seen surfaces).
        observed: what the frames have measured.
        initial_variance: the variance of a voxel nothing has measured (the mapper's
            maximum).

    Returns:
        A new volume on the same grid: the larger of the surface uncertainty and, on voxels
        whose centre lies in a frontier cell, ``initial_variance``.
    """
    on_frontier = observed.sample(observed.frontier(), uncertainty.grid_points()).reshape(
        uncertainty.shape
    )
    values = np.where(on_frontier, np.maximum(uncertainty.values, initial_variance),
                      uncertainty.values)
    return SdfVolume(values, uncertainty.origin, uncertainty.voxel_size)
