"""The scanned space of a mesh: where an agent is still inside what was scanned.

Real scans are open: no ceiling, holes in the floor, walls missing. Judging "inside" by the
share of a whole panorama that hits nothing (the published rule, 50 %) fails on them: without a
ceiling half of every panorama is empty, wherever the agent stands. This module judges a point
from below and by what faces it:

* **supported**: at most ``max_unsupported_share`` (50 %) of the rays of a downward cone
  (``support_half_angle_deg`` = 60 degrees around straight down, uniform in solid angle) hit
  nothing. There is scanned surface under the point: a floor, or furniture, or, within the
  cone's reach, the walls. Over a missing ceiling nothing changes; over a hole in the floor
  the cone still sees the floor around the hole unless the point sinks into the hole; past a
  missing wall or out of a wall hole the floor ends, and so does the support.
* **not behind a surface**: at least ``min_front_facing_share`` (90 %) of the surfaces that a
  probe of rays in all directions hits face the point. Points inside solids, behind a
  single-sided scanned wall or under a scanned floor see the back of the surface.
* **not above the scan**: the point is at most ``top_margin_m`` above the height under which
  ``top_quantile`` (99 %) of the scan's surface area lies. Stray fragments far above a room
  without a ceiling widen its bounds, but carry almost no area, so they do not raise this.

Walls all around are deliberately not required: partial scans lack them, and a scan of a floor
with a few objects (the habitat-sim sample room) has none at all.

Evaluating a point casts about a hundred rays, too many to repeat at every step of a fast env.
:class:`ScannedSpace` therefore evaluates the corners of a voxel lattice (``voxel_m`` = 0.1 m)
once, lazily, the first time a move ends in a cell, and answers later queries by trilinear
interpolation of the unsupported share over the cell's corners that are not behind a surface.
Nothing is precomputed at load (an RL env may draw a new scene at every reset), and after the
first visit of a cell a query casts no ray; :meth:`ScannedSpace.fill` evaluates the whole
lattice at once when a complete map is wanted.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from naruto_gym.sensors.raycaster import RayCaster

_GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))


@dataclass(frozen=True)
class ScannedSpaceConfig:
    """Settings of the scanned-space test (the defaults are the env's).

    Attributes:
        voxel_m: lattice spacing of the cached evaluations.
        support_half_angle_deg: half angle of the downward support cone.
        support_rays: rays in the support cone.
        facing_rays: rays over the whole sphere for the facing test.
        max_unsupported_share: largest share of support rays that may hit nothing.
        min_front_facing_share: smallest share of hit surfaces that must face the point.
        top_quantile: the scan's top is the height under which this share of its area lies.
        top_margin_m: how far above that top a point may still be.
        top_samples: surface samples used to find the top.
    """

    voxel_m: float = 0.1
    support_half_angle_deg: float = 60.0
    support_rays: int = 48
    facing_rays: int = 64
    max_unsupported_share: float = 0.5
    min_front_facing_share: float = 0.9
    top_quantile: float = 0.99
    top_margin_m: float = 0.1
    top_samples: int = 100_000

    def __post_init__(self) -> None:
        if self.voxel_m <= 0:
            raise ValueError(f"voxel_m must be positive, got {self.voxel_m}")
        if not 0 < self.support_half_angle_deg <= 90:
            raise ValueError(
                f"support_half_angle_deg must be in (0, 90], got {self.support_half_angle_deg}"
            )
        if self.support_rays < 1 or self.facing_rays < 1:
            raise ValueError("support_rays and facing_rays must be at least 1")
        if not 0 <= self.max_unsupported_share < 1:
            raise ValueError(
                f"max_unsupported_share must be in [0, 1), got {self.max_unsupported_share}"
            )
        if not 0 <= self.min_front_facing_share <= 1:
            raise ValueError(
                f"min_front_facing_share must be in [0, 1], got {self.min_front_facing_share}"
            )
        if not 0 < self.top_quantile <= 1:
            raise ValueError(f"top_quantile must be in (0, 1], got {self.top_quantile}")


def cap_directions(count: int, half_angle_deg: float, axis: np.ndarray) -> np.ndarray:
    """(count, 3) float32 unit directions spread uniformly (in solid angle) over a spherical cap.

    A Fibonacci spiral: deterministic and even, with no clustering at the cap's centre.
    """
    index = np.arange(count) + 0.5
    cos_limit = np.cos(np.deg2rad(half_angle_deg))
    cos_polar = 1.0 - index / count * (1.0 - cos_limit)
    sin_polar = np.sqrt(np.clip(1.0 - cos_polar**2, 0.0, None))
    azimuth = _GOLDEN_ANGLE * index
    local = np.stack(
        [sin_polar * np.cos(azimuth), sin_polar * np.sin(azimuth), cos_polar], axis=1
    )
    axis = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    return (local[:, :1] * u + local[:, 1:2] * v + local[:, 2:] * axis).astype(np.float32)


def surface_top(
    vertices: np.ndarray, faces: np.ndarray, quantile: float, samples: int = 100_000
) -> float:
    """Height under which ``quantile`` of the mesh's surface area lies (seeded samples)."""
    from naruto_gym.evaluation.metrics import sample_mesh_surface

    points = sample_mesh_surface(vertices, faces, samples, seed=0, what="scene")
    return float(np.quantile(points[:, 2], quantile))


class ScannedSpace:
    """Which points of a mesh lie inside its scanned space (see the module docstring).

    Args:
        raycaster: the scene.
        face_normals: (F, 3) unit triangle normals (orientation tells front from back).
        bounds: (2, 3) scene bounds; the lattice covers them.
        config: the test's settings.
    """

    def __init__(
        self,
        raycaster: RayCaster,
        face_normals: np.ndarray,
        bounds: np.ndarray,
        config: ScannedSpaceConfig | None = None,
    ) -> None:
        self.raycaster = raycaster
        self.face_normals = np.asarray(face_normals, np.float64)
        self.config = config or ScannedSpaceConfig()
        bounds = np.asarray(bounds, np.float64)
        voxel = self.config.voxel_m
        # Corners sit half a voxel off the bounds, so none lies in the plane of an
        # axis-aligned floor or wall at the bounds (a ray from there is ambiguous).
        self.origin = bounds[0] - 0.5 * voxel
        self.shape = tuple(int(n) for n in np.ceil((bounds[1] - self.origin) / voxel) + 1)
        self._unsupported = np.full(self.shape, np.nan, np.float32)
        self._behind = np.zeros(self.shape, bool)
        self.support_directions = cap_directions(
            self.config.support_rays, self.config.support_half_angle_deg, np.array([0, 0, -1.0])
        )
        facing = cap_directions(self.config.facing_rays, 180.0, np.array([0, 0, 1.0]))
        self._directions = np.concatenate([self.support_directions, facing])

    @cached_property
    def top_m(self) -> float:
        """Highest z a point may have: the scan's area quantile plus the margin."""
        top = surface_top(
            self.raycaster.vertices,
            self.raycaster.faces,
            self.config.top_quantile,
            self.config.top_samples,
        )
        return top + self.config.top_margin_m

    # -- exact evaluation ----------------------------------------------------------------
    def probe(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact (unsupported share, behind a surface) of (N, 3) points; casts N x ~112 rays."""
        positions = np.asarray(positions, np.float64).reshape(-1, 3)
        count, rays = len(positions), len(self._directions)
        origins = np.repeat(positions.astype(np.float32), rays, axis=0)
        directions = np.tile(self._directions, (count, 1))
        hits = self.raycaster.cast(origins, directions)
        hit = hits.hit_mask.reshape(count, rays)
        support = self.config.support_rays
        unsupported = 1.0 - hit[:, :support].mean(axis=1)
        normals = self.face_normals[np.where(hits.triangle_ids >= 0, hits.triangle_ids, 0)]
        facing = (np.einsum("ij,ij->i", normals, directions) < 0).reshape(count, rays) & hit
        hit_count = hit.sum(axis=1)
        front_share = facing.sum(axis=1) / np.maximum(hit_count, 1)
        behind = (hit_count > 0) & (front_share < self.config.min_front_facing_share)
        return unsupported, behind

    def evaluate(self, positions: np.ndarray) -> np.ndarray:
        """Exact inside mask of (N, 3) points (casts rays; use :meth:`contains` per step)."""
        positions = np.asarray(positions, np.float64).reshape(-1, 3)
        unsupported, behind = self.probe(positions)
        return (
            ~behind
            & (unsupported <= self.config.max_unsupported_share)
            & (positions[:, 2] <= self.top_m)
        )

    def is_inside(self, position: np.ndarray) -> bool:
        """Exact test of one point (for start poses and viewpoints, drawn rarely)."""
        return bool(self.evaluate(position)[0])

    # -- cached lattice ------------------------------------------------------------------
    def _corner_points(self, index: np.ndarray) -> np.ndarray:
        return self.origin + index * self.config.voxel_m

    def _ensure(self, index: np.ndarray) -> None:
        """Evaluate the lattice corners (K, 3) not evaluated yet."""
        unknown = np.isnan(self._unsupported[tuple(index.T)])
        if unknown.any():
            todo = np.unique(index[unknown], axis=0)
            unsupported, behind = self.probe(self._corner_points(todo))
            self._unsupported[tuple(todo.T)] = unsupported
            self._behind[tuple(todo.T)] = behind

    def fill(self, batch: int = 4096) -> None:
        """Evaluate every lattice corner now (for maps and statistics; the env never needs it)."""
        todo = np.argwhere(np.isnan(self._unsupported))
        for start in range(0, len(todo), batch):
            self._ensure(todo[start : start + batch])

    @property
    def evaluated_share(self) -> float:
        """Share of the lattice corners evaluated so far."""
        return float(np.mean(~np.isnan(self._unsupported)))

    def unsupported_share(self, position: np.ndarray) -> float:
        """Unsupported share at ``position``, interpolated over the usable corners of its cell.

        Corners behind a surface (inside a wall, under a floor) do not count; when all eight
        are, the point itself is evaluated exactly (inf when it is behind a surface too).
        """
        position = np.asarray(position, np.float64)
        scaled = (position - self.origin) / self.config.voxel_m
        low = np.clip(np.floor(scaled).astype(np.int64), 0, np.array(self.shape) - 2)
        t = np.clip(scaled - low, 0.0, 1.0)
        offsets = _CELL_OFFSETS
        corners = low + offsets
        self._ensure(corners)
        key = tuple(corners.T)
        weights = np.prod(np.where(offsets == 1, t, 1.0 - t), axis=1)
        usable = ~self._behind[key]
        total = float(weights[usable].sum())
        if total <= 1e-9:
            unsupported, behind = self.probe(position)
            return float("inf") if behind[0] else float(unsupported[0])
        return float(weights[usable] @ self._unsupported[key][usable] / total)

    def contains(self, position: np.ndarray) -> bool:
        """Whether ``position`` is in the scanned space (lattice lookup; casts rays only in a
        cell visited for the first time)."""
        position = np.asarray(position, np.float64)
        if position[2] > self.top_m:
            return False
        return self.unsupported_share(position) <= self.config.max_unsupported_share

    def contains_many(self, positions: np.ndarray) -> np.ndarray:
        """:meth:`contains` for (N, 3) points."""
        return np.array([self.contains(p) for p in np.asarray(positions).reshape(-1, 3)], bool)


_CELL_OFFSETS = np.array(
    [[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=np.int64
)
