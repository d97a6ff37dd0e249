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

Not all of the frontier can be resolved: much of what stays unknown in a furnished room is the
inside of furniture and the space under and behind it. A frontier voxel that frames have
looked at with a clear line of sight (it lies in front of the measured depth, within
``look_range_m``) and that is still frontier hides what is next to it. Like a surface's
uncertainty, which falls with every observation, its variance falls with every such *look*:
``initial / (1 + look_weight * looks)``. Fresh frontier then outranks the hidden pockets the
agent has already looked into.

Real scans are open (no ceiling, a missing wall, holes): rays that pass over a wall top or
through a gap mark free space *outside* the scanned room, whose frontier would pull the agent
out of the scan, where the env refuses its moves. The frontier therefore counts only where it
is *supported*: measured surface (a floor, furniture, a wall) lies below it, within
``support_below_m`` and ``support_reach_m`` sideways, as under every place a robot can stand
or fly over inside a scan. :meth:`ObservedSpace.scan_top_z` gives the height under which the
measured surfaces lie (a room without a ceiling ends at its wall tops), which the agent uses
to keep its goals inside.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage

from naruto_agent.mapping.occupancy import OccupancyGrid
from naruto_agent.mapping.sdf_volume import SdfVolume
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.utils.checks import check_integer, check_number

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
        support_below_m: a frontier voxel counts only with measured surface at most this far
            below it (None: every frontier voxel counts, the behaviour on closed scenes).
        support_reach_m: ... in its own column or one at most this far sideways (a floor
            seen next to a table, a doorway's threshold seen at a slant).
        top_quantile: :meth:`ObservedSpace.scan_top_z` is the height under which this share
            of the occupied voxels lies.
        look_weight: how fast a frontier voxel's variance falls with the frames that looked
            at it without resolving it (0: it stays at the initial variance until resolved).
        look_range_m: a frame looks at a voxel up to this distance (the goal search's 2 m).
        look_behind_surface_m: a frame also looks at a voxel whose centre lies up to this far
            behind the surface its pixel measured (0.15 m: the voxel's own cell reaches
            0.09 m from its centre). Most unresolvable frontier lies under and behind
            surfaces: free cells the rays grazed, next to the unknown inside furniture. The
            goal search sees them (its line of sight stops a voxel short of the target), so
            unless the surface over them counts as a look they keep the initial variance
            and hold the agent in place. -0.1 (a voxel in front of the surface): the line
            of sight must be clear.
    """

    voxel_size_m: float = 0.1
    max_range_m: float = 5.0
    rays_per_frame: int = 2048
    min_cluster_voxels: int = 8
    support_below_m: float | None = 3.0
    support_reach_m: float = 0.3
    top_quantile: float = 0.99
    look_weight: float = 0.25
    look_range_m: float = 2.0
    look_behind_surface_m: float = 0.15

    def __post_init__(self) -> None:
        check_number("voxel_size_m", self.voxel_size_m, low=0.0)
        check_number("max_range_m", self.max_range_m, low=0.0)
        check_integer("rays_per_frame", self.rays_per_frame, low=1)
        check_integer("min_cluster_voxels", self.min_cluster_voxels, low=1)
        if self.support_below_m is not None:
            check_number("support_below_m (or None)", self.support_below_m, low=0.0)
        check_number("support_reach_m", self.support_reach_m, low=0.0, low_open=False)
        check_number("top_quantile", self.top_quantile, low=0.0, high=1.0)
        check_number("look_weight", self.look_weight, low=0.0, low_open=False)
        check_number("look_range_m", self.look_range_m, low=0.0)
        check_number("look_behind_surface_m", self.look_behind_surface_m)


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
        self.looks = np.zeros(self.grid.shape, np.float32)
        self._frontier: np.ndarray | None = None
        self._supported: np.ndarray | None = None

    def configure(self, **changes: object) -> None:
        """Change settings (fields of :class:`ObservedSpaceConfig`) of a live grid."""
        self.config = replace(self.config, **changes)
        self._changed()

    def _changed(self) -> None:
        self._frontier = None
        self._supported = None

    def _stride(self, camera: PinholeCamera) -> int:
        pixels = camera.width * camera.height
        return max(1, int(round(math.sqrt(pixels / self.config.rays_per_frame))))

    def integrate_depth(
        self, depth: np.ndarray, camera_to_world: np.ndarray, camera: PinholeCamera
    ) -> None:
        """Integrate a pinhole z-depth frame (0 = no hit) seen from ``camera_to_world``."""
        self.grid.pixel_stride = self._stride(camera)  # drops the grid's rays if it changed
        self.grid.integrate(depth, camera_to_world, camera)
        if self.config.look_weight > 0:
            self._count_looks(depth, np.asarray(camera_to_world, np.float64), camera)
        self._changed()

    def _count_looks(self, depth: np.ndarray, pose: np.ndarray, camera: PinholeCamera) -> None:
        """Add a look to every voxel the frame sees: in the image, within ``look_range_m``,
        in front of the measured depth or at most ``look_behind_surface_m`` behind it (or
        where nothing was hit)."""
        reach = self.config.look_range_m
        voxel = self.config.voxel_size_m
        low = self.grid.world_to_cell(pose[:3, 3][None] - reach)[0]
        high = self.grid.world_to_cell(pose[:3, 3][None] + reach)[0] + 1
        shape = np.asarray(self.grid.shape)
        low, high = np.clip(low, 0, shape), np.clip(high, 0, shape)
        if np.any(high <= low):
            return
        axes = [np.arange(a, b) for a, b in zip(low, high, strict=True)]
        cells = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        points = (self.grid.cell_to_world(cells) - pose[:3, 3]) @ pose[:3, :3]
        pixels, z = camera.project(points)
        u = np.floor(pixels[:, 0] + 0.5).astype(np.int64)
        v = np.floor(pixels[:, 1] + 0.5).astype(np.int64)
        near = (z > voxel) & (np.linalg.norm(points, axis=1) <= reach)
        near &= (u >= 0) & (u < camera.width) & (v >= 0) & (v < camera.height)
        index = np.flatnonzero(near)
        measured = depth[v[index], u[index]]
        clear = (measured <= 0) | (z[index] < measured + self.config.look_behind_surface_m)
        seen = cells[index[clear]]
        self.looks[seen[:, 0], seen[:, 1], seen[:, 2]] += 1.0

    def add_looks(self, points: np.ndarray, looks: float) -> None:
        """Count ``looks`` more looks at the voxels of world points (e.g. targets an agent went
        to see that are still unresolved after its visit)."""
        cells, inside = self.cells_of(points)
        cells = cells[inside]
        np.add.at(self.looks, (cells[:, 0], cells[:, 1], cells[:, 2]), np.float32(looks))

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
        self._changed()

    def mark_occupied(self, points: np.ndarray) -> None:
        """Mark the voxels of world points as occupied (e.g. where a move was refused)."""
        self.grid.mark_occupied(points)
        self._changed()

    @property
    def observed_fraction(self) -> float:
        """Share of the grid's voxels that some ray has reached (a measure of progress)."""
        return float(self.grid.observed.mean())

    def supported(self) -> np.ndarray:
        """(nx, ny, nz) bool: voxels with an occupied voxel below them, at most
        ``support_below_m`` down and ``support_reach_m`` sideways (all True when
        ``support_below_m`` is None)."""
        if self._supported is None:
            if self.config.support_below_m is None:
                self._supported = np.ones(self.grid.shape, bool)
                return self._supported
            self._supported = self.grid.supported_below(
                self.config.support_below_m, self.config.support_reach_m
            )
        return self._supported

    def sectors_seen_below(self, points: np.ndarray, max_length_m: float = 5.0) -> np.ndarray:
        """(N,) bool: every sector of the env's downward support cone meets measured surface
        from the point (:meth:`OccupancyGrid.sectors_seen_below`). Stricter than
        :meth:`supported`, which accepts a point in a wall's opening or over the edge of a
        floor hole when measured surface lies within ``support_reach_m`` sideways below."""
        return self.grid.sectors_seen_below(points, max_length_m)

    def scan_top_z(self) -> float:
        """Height (world z of voxel tops) under which ``top_quantile`` of the occupied
        voxels lie; +inf before anything was measured occupied."""
        return self.grid.occupied_top_z(self.config.top_quantile)

    def frontier(self) -> np.ndarray:
        """(nx, ny, nz) bool: free voxels next to unknown ones, in clusters big enough,
        supported by measured surface below (see :class:`ObservedSpaceConfig`)."""
        if self._frontier is None:
            frontier = self.grid.frontier() & self.supported()
            labels, count = ndimage.label(frontier, _ALL_NEIGHBOURS)
            if count:
                sizes = np.bincount(labels.reshape(-1), minlength=count + 1)
                big = sizes >= self.config.min_cluster_voxels
                big[0] = False
                frontier = big[labels]
            self._frontier = frontier
        return self._frontier

    def frontier_variance(self, initial_variance: float) -> np.ndarray:
        """(nx, ny, nz) variance of unexplored space: on the frontier ``initial_variance``
        lowered by the looks that did not resolve it, 0 elsewhere."""
        falling = initial_variance / (1.0 + self.config.look_weight * self.looks)
        return np.where(self.frontier(), falling, 0.0)

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
        return {
            "log_odds": self.grid.log_odds.copy(),
            "observed": self.grid.observed.copy(),
            "looks": self.looks.copy(),
        }

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        if np.shape(state["log_odds"]) != self.grid.shape:
            raise ValueError("saved observed-space grid does not match these bounds/voxel size")
        self.grid.log_odds = np.asarray(state["log_odds"], np.float32).copy()
        self.grid.observed = np.asarray(state["observed"], bool).copy()
        self.looks = np.asarray(state.get("looks", np.zeros(self.grid.shape)), np.float32).copy()
        self._changed()


def add_unknown_space_uncertainty(
    uncertainty: SdfVolume, observed: ObservedSpace, initial_variance: float
) -> SdfVolume:
    """The planner's uncertainty volume with the frontier's variance added.

    Args:
        uncertainty: the mapper's uncertainty volume (0 except on seen surfaces).
        observed: what the frames have measured.
        initial_variance: the variance of a voxel nothing has measured (the mapper's
            maximum).

    Returns:
        A new volume on the same grid: the larger of the surface uncertainty and, on voxels
        whose centre lies in a frontier cell, the frontier's variance
        (:meth:`ObservedSpace.frontier_variance`: ``initial_variance`` until frames look at
        it without resolving it).
    """
    frontier = observed.sample(
        observed.frontier_variance(initial_variance), uncertainty.grid_points()
    ).reshape(uncertainty.shape)
    values = np.maximum(uncertainty.values, frontier)
    return SdfVolume(values, uncertainty.origin, uncertainty.voxel_size)
