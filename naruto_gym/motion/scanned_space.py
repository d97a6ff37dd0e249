"""The scanned space of a mesh: where an agent is still inside what was scanned.

Real scans are open: no ceiling, holes in the floor, walls missing. Judging "inside" by the
share of a whole panorama that hits nothing (the published rule, 50 %) fails on them: without a
ceiling half of every panorama is empty, wherever the agent stands. This module judges a point
from below:

* **supported**: every azimuth sector (``support_sectors`` = 8, of 45 degrees) of a downward
  cone (``support_half_angle_deg`` = 60 degrees around straight down) sees scanned surface:
  floor, furniture or walls. Over a missing ceiling nothing changes. Over a hole in the floor
  the cone's outer rays still find the floor all around, unless the point sinks into the
  hole (lower than about 0.6 x the hole's half width). Past the edge of the scanned floor (a
  missing wall, a wall hole, a partial scan) the sectors that look away from the floor see
  nothing, however high the point is: the test flips at the edge itself, to within the
  steepest ring of rays (2 degrees, 5 cm at 1.5 m). Under a single-sided scanned floor
  nothing is below either.
* **not above the scan**: the point is at most ``top_margin_m`` above the height under which
  ``top_quantile`` (99 %) of the scan's surface area lies. Stray fragments far above a room
  without a ceiling widen its bounds, but carry almost no area, so they do not raise this.

Walls all around are deliberately not required: partial scans lack them, and a scan of a floor
with a few objects (the habitat-sim sample room) has none at all. Neither test reads triangle
orientation, so meshes with flipped normals (common in CAD-made scenes) are judged like any
other. Start poses and viewpoints, drawn once, also reject points inside solids by the
published free-space test's facing criterion (:meth:`ScannedSpace.is_inside`).

Evaluating a point casts up to 112 rays (8, one per sector of the steepest ring, where those
already see surface all around, as above any floor), too many to repeat at every step of a
fast env.
:class:`ScannedSpace` therefore evaluates the corners of a lattice (``voxel_m`` = 5 cm) once,
lazily, the first time a query needs them, and answers a query from the corners of its cell
that lie within its clearance (the ball around it that no surface enters, so no wall
separates them from it): all must be supported. The agent keeps at least its radius (5 cm)
from every surface, which is more than half a cell's diagonal (4.3 cm), so some corner always
qualifies. Nothing is precomputed at load (an RL env may draw a new scene at every reset),
and once the corners around a place are known a query casts no ray;
:meth:`ScannedSpace.fill` evaluates the whole lattice when a complete map is wanted.
The lattice is dense (a byte per corner), so a scene too large for it at 5 cm (more than
``MAX_LATTICE_CORNERS`` corners, about 40 x 40 x 10 m) gets a coarser one, and there a move
close to a surface may find no corner within its clearance and be refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from naruto_gym.motion.lattice_kernels import corners_supported, usable_corners
from naruto_gym.scenes.mesh_scene import sample_mesh_surface
from naruto_gym.sensors.kernels import fill_panorama_rays
from naruto_gym.sensors.raycaster import RayCaster, RayHits

_GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))


@dataclass(frozen=True)
class ScannedSpaceConfig:
    """Settings of the scanned-space test (the defaults are the env's).

    Attributes:
        voxel_m: lattice spacing of the cached evaluations.
        support_half_angle_deg: half angle of the downward support cone.
        support_sectors: azimuth sectors of the cone that must each see surface.
        support_rings: rings of rays in the cone, from 2 degrees off straight down to the
            half angle, denser near the axis (where they place the floor's edge).
        rays_per_sector: rays of each ring in each sector.
        max_empty_sectors: sectors that may see nothing (0: all must see surface).
        facing_rays: rays over the whole sphere for the facing test.
        min_front_facing_share: smallest share of hit surfaces that must face the point.
        top_quantile: the scan's top is the height under which this share of its area lies.
        top_margin_m: how far above that top a point may still be.
        top_samples: surface samples used to find the top.
    """

    voxel_m: float = 0.05
    support_half_angle_deg: float = 60.0
    support_sectors: int = 8
    support_rings: int = 7
    rays_per_sector: int = 2
    max_empty_sectors: int = 0
    facing_rays: int = 64
    min_front_facing_share: float = 0.9
    top_quantile: float = 0.99
    top_margin_m: float = 0.1
    top_samples: int = 100_000

    def __post_init__(self) -> None:
        if self.voxel_m <= 0:
            raise ValueError(f"voxel_m must be positive, got {self.voxel_m}")
        if not 2 < self.support_half_angle_deg <= 90:
            raise ValueError(
                f"support_half_angle_deg must be in (2, 90], got {self.support_half_angle_deg}"
            )
        if min(self.support_sectors, self.support_rings, self.rays_per_sector,
               self.facing_rays) < 1:
            raise ValueError(
                "support_sectors, support_rings, rays_per_sector and facing_rays must be >= 1"
            )
        if not 0 <= self.max_empty_sectors < self.support_sectors:
            raise ValueError(
                f"max_empty_sectors must be in [0, support_sectors), got {self.max_empty_sectors}"
            )
        if not 0 <= self.min_front_facing_share <= 1:
            raise ValueError(
                f"min_front_facing_share must be in [0, 1], got {self.min_front_facing_share}"
            )
        if not 0 < self.top_quantile <= 1:
            raise ValueError(f"top_quantile must be in (0, 1], got {self.top_quantile}")


_STEEPEST_RING_DEG = 2.0

#: The most lattice corners (one byte each) a scene's lattice holds; a larger scene gets a
#: coarser lattice, so that its memory stays bounded (64 MiB) whatever the scene's size.
MAX_LATTICE_CORNERS = 64 * 2**20


def lattice_spacing(bounds: np.ndarray, voxel_m: float) -> float:
    """``voxel_m``, or the smallest coarser spacing at which the lattice over ``bounds`` has
    at most ``MAX_LATTICE_CORNERS`` corners."""
    extents = np.maximum(np.asarray(bounds[1], float) - np.asarray(bounds[0], float), 0.0)

    def corners(spacing: float) -> float:
        return float(np.prod(np.ceil(extents / spacing + 0.5) + 1.0))

    spacing = voxel_m
    while corners(spacing) > MAX_LATTICE_CORNERS:
        spacing *= 1.25
    return spacing


def support_directions(config: ScannedSpaceConfig) -> tuple[np.ndarray, np.ndarray]:
    """The downward cone's rays: (R, 3) float32 unit directions and (R,) sector indices.

    Rings from 2 degrees off straight down to the half angle, spaced as the 1.5th power
    (denser near the axis); in every ring ``rays_per_sector`` rays per azimuth sector, spread
    evenly inside it. Deterministic.
    """
    rings = config.support_rings
    steps = np.linspace(0.0, 1.0, rings) if rings > 1 else np.ones(1)
    polar = np.deg2rad(
        _STEEPEST_RING_DEG + (config.support_half_angle_deg - _STEEPEST_RING_DEG) * steps**1.5
    )
    per_ring = config.support_sectors * config.rays_per_sector
    azimuth = 2.0 * np.pi * (np.arange(per_ring) + 0.5) / per_ring
    polar, azimuth = np.meshgrid(polar, azimuth, indexing="ij")
    directions = np.stack(
        [np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), -np.cos(polar)],
        axis=-1,
    ).reshape(-1, 3)
    sectors = np.tile(np.arange(per_ring) // config.rays_per_sector, rings)
    return directions.astype(np.float32), sectors


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
    heights = sample_mesh_surface(vertices, faces, samples, seed=0, what="scene", axes=[2])
    return float(np.quantile(heights[:, 0], quantile))


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
        spacing = lattice_spacing(bounds, self.config.voxel_m)
        if spacing != self.config.voxel_m:  # a very large scene: a coarser lattice
            self.config = replace(self.config, voxel_m=spacing)
        voxel = self.config.voxel_m
        # Corners sit half a voxel off the bounds, so none lies in the plane of an
        # axis-aligned floor or wall at the bounds (a ray from there is ambiguous).
        self.origin = tuple(float(value) for value in bounds[0] - 0.5 * voxel)
        self.shape = tuple(
            int(n) for n in np.ceil((bounds[1] - np.array(self.origin)) / voxel) + 1
        )
        # Per corner: -1 not evaluated yet, else the number of empty support sectors.
        self._empty = np.full(self.shape, -1, np.int8)
        self._lattice_origin = np.array(self.origin)  # for the compiled lookups
        self._lattice_shape = np.array(self.shape, np.int64)
        self.support_directions, sectors = support_directions(self.config)
        # The staged probe of empty_sectors: first one ray per sector of the steepest ring,
        # then every other ray, sector after sector.
        per_ring = self.config.support_sectors * self.config.rays_per_sector
        leading = np.arange(0, per_ring, self.config.rays_per_sector)
        others = np.setdiff1d(np.arange(len(sectors)), leading)
        others = others[np.argsort(sectors[others], kind="stable")]
        self._leading_directions = np.ascontiguousarray(self.support_directions[leading])
        self._other_directions = np.ascontiguousarray(self.support_directions[others])
        self.facing_directions = cap_directions(
            self.config.facing_rays, 180.0, np.array([0, 0, 1.0])
        )

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
        """Support below (N, 3) points, casting N x ``support rays`` rays in one call.

        Returns:
            empty support sectors (N,) int, and how far the scan is below: (N, 2) float,
            the share of support rays that hit nothing and the distance of their nearest hit
            (inf for none).
        """
        positions = np.asarray(positions, np.float64).reshape(-1, 3)
        hits = self._cast_from(positions, self.support_directions)
        hit = hits.hit_mask.reshape(len(positions), -1)
        empty = self.config.support_sectors - self._seen_sectors(hit).sum(axis=1)
        missed = 1.0 - hit.mean(axis=1)
        nearest = hits.distance.reshape(hit.shape).min(axis=1)
        return empty, np.stack([missed, nearest], axis=1)

    def _cast_from(self, positions: np.ndarray, directions: np.ndarray) -> RayHits:
        """One cast of ``directions`` from every point of (N, 3) ``positions``, point-major."""
        return self.raycaster.cast_packed(self._rays_from(positions, directions))

    def _hits_from(self, positions: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Whether each of those rays hits anything: (N * R,) bool, a cheaper query."""
        return self.raycaster.hits_any_packed(self._rays_from(positions, directions))

    @staticmethod
    def _rays_from(positions: np.ndarray, directions: np.ndarray) -> np.ndarray:
        rays = np.empty((len(positions) * len(directions), 6), np.float32)
        fill_panorama_rays(np.ascontiguousarray(directions, np.float32),
                           np.ascontiguousarray(positions, np.float32), rays, 0)
        return rays

    def _seen_sectors(self, hit: np.ndarray) -> np.ndarray:
        """(N, sectors) bool: which sectors some ray of ``hit`` found surface in; ``hit``
        is (N, R) over whole rings of :func:`support_directions` (sector after sector in
        each ring, ``rays_per_sector`` rays each)."""
        config = self.config
        return hit.reshape(len(hit), -1, config.support_sectors, config.rays_per_sector).any(
            axis=(1, 3)
        )

    def empty_sectors(self, positions: np.ndarray) -> np.ndarray:
        """Empty support sectors below (N, 3) points: :meth:`probe`'s first answer, casting
        fewer rays.

        One ray per sector of the steepest ring goes first: above a floor each finds
        surface, and then no other ray can change the answer (a sector is seen when any of
        its rays hits). Only points it leaves undecided (over a hole, past an edge) cast the
        other rays.
        """
        positions = np.asarray(positions, np.float64).reshape(-1, 3)
        sectors = self.config.support_sectors
        seen = self._hits_from(positions, self._leading_directions).reshape(
            len(positions), sectors
        )
        undecided = np.flatnonzero(~seen.all(axis=1))
        others = self._other_directions
        if len(undecided) and len(others):
            more = self._hits_from(positions[undecided], others)
            seen[undecided] |= more.reshape(len(undecided), sectors, -1).any(axis=2)
        return sectors - seen.sum(axis=1)

    def front_facing_share(self, position: np.ndarray) -> float:
        """Share of the surfaces seen all around ``position`` that face it (1 when none)."""
        return float(self.front_facing_shares(position)[0])

    def front_facing_shares(self, positions: np.ndarray) -> np.ndarray:
        """:meth:`front_facing_share` of (N, 3) points, from one cast."""
        positions = np.asarray(positions, np.float64).reshape(-1, 3)
        directions = self.facing_directions
        hits = self._cast_from(positions, directions)
        hit = hits.hit_mask.reshape(len(positions), len(directions))
        facing = np.zeros(hit.shape, bool)
        normals = self.face_normals[hits.triangle_ids.reshape(hit.shape)[hit]]
        ray_directions = np.broadcast_to(directions, hit.shape + (3,))[hit]
        facing[hit] = np.einsum("ij,ij->i", normals, ray_directions) < 0
        counts = hit.sum(axis=1)
        shares = np.ones(len(positions))
        seen = counts > 0
        shares[seen] = facing[seen].sum(axis=1) / counts[seen]
        return shares

    def evaluate(self, positions: np.ndarray) -> np.ndarray:
        """Exact support and height test of (N, 3) points (casts rays; per step use
        :meth:`contains`)."""
        positions = np.asarray(positions, np.float64).reshape(-1, 3)
        empty = self.empty_sectors(positions)
        return (empty <= self.config.max_empty_sectors) & (positions[:, 2] <= self.top_m)

    def is_inside(self, position: np.ndarray) -> bool:
        """Exact test of one point for start poses and viewpoints: supported, not above the
        scan, and not behind a surface (at least ``min_front_facing_share`` of what it sees
        faces it, which rejects points inside solids)."""
        if not self.evaluate(position)[0]:
            return False
        return self.front_facing_share(position) >= self.config.min_front_facing_share

    def is_inside_many(self, positions: np.ndarray) -> np.ndarray:
        """:meth:`is_inside` of (N, 3) points, the same answers from two ray casts (support
        of all, then the facing test of the supported ones)."""
        positions = np.asarray(positions, np.float64).reshape(-1, 3)
        inside = self.evaluate(positions)
        candidates = np.flatnonzero(inside)
        if len(candidates):
            shares = self.front_facing_shares(positions[candidates])
            inside[candidates] = shares >= self.config.min_front_facing_share
        return inside

    def outside_degree(self, position: np.ndarray) -> tuple[int, float, float]:
        """How far out ``position`` is, exactly, for comparing two points: (empty support
        sectors, share of support rays hitting nothing, distance of their nearest hit)."""
        empty, below = self.probe(position)
        return (int(empty[0]), float(below[0, 0]), float(below[0, 1]))

    # -- cached lattice ------------------------------------------------------------------
    def _corner_points(self, index: np.ndarray) -> np.ndarray:
        return np.array(self.origin) + index * self.config.voxel_m

    def _ensure(self, index: np.ndarray) -> None:
        """Evaluate the lattice corners (K, 3) not evaluated yet."""
        unknown = self._empty[tuple(index.T)] < 0
        if unknown.any():
            # Distinct corners through their flat index (np.unique over rows is much slower).
            flat = np.unique(np.ravel_multi_index(tuple(index[unknown].T), self._empty.shape))
            self._evaluate(np.stack(np.unravel_index(flat, self._empty.shape), axis=1))

    def _evaluate(self, corners: np.ndarray) -> None:
        """Evaluate the distinct lattice corners (K, 3)."""
        self._empty[tuple(corners.T)] = self.empty_sectors(self._corner_points(corners))

    def fill(self, batch: int = 4096) -> None:
        """Evaluate every lattice corner now (for maps and statistics; the env never needs it)."""
        todo = np.argwhere(self._empty < 0)
        for start in range(0, len(todo), batch):
            self._ensure(todo[start : start + batch])

    @property
    def evaluated_share(self) -> float:
        """Share of the lattice corners evaluated so far."""
        return float(np.mean(self._empty >= 0))

    def corner_support(self) -> np.ndarray:
        """(X, Y, Z) bool grid: the lattice corners evaluated and supported so far."""
        return (self._empty >= 0) & (self._empty <= self.config.max_empty_sectors)

    def contains(self, position: np.ndarray, clearance_m: float | None = None) -> bool:
        """Whether ``position`` is in the scanned space, from its lattice cell.

        The corners of its cell closer to it than its clearance (the free ball around it, so
        nothing separates them from it: never a corner inside a wall or behind it) must all
        be supported, and the point must not be above the scan. When no corner is that close
        (a point nearer to a surface than half a voxel diagonal), the point itself is
        evaluated. Casts rays only for a cell's first query.

        Args:
            position: (3,) point.
            clearance_m: its distance to the nearest surface, when the caller knows it
                (otherwise one distance query).
        """
        x, y, z = (float(value) for value in position)
        if z > self.top_m:
            return False
        if clearance_m is None:
            clearance_m = float(self.raycaster.unsigned_distance(np.array([[x, y, z]]))[0])
        # Plain Python over the eight corners: this runs at every step of the env, where
        # NumPy's per-call overhead on eight elements would cost more than the lookup.
        voxel = self.config.voxel_m
        limit = clearance_m * clearance_m
        low = []
        for value, origin, size in zip((x, y, z), self.origin, self.shape, strict=True):
            low.append(min(max(int(math.floor((value - origin) / voxel)), 0), size - 2))
        usable = []
        for di, dj, dk in _CELL_STEPS:
            i, j, k = low[0] + di, low[1] + dj, low[2] + dk
            dx = self.origin[0] + i * voxel - x
            dy = self.origin[1] + j * voxel - y
            dz = self.origin[2] + k * voxel - z
            if dx * dx + dy * dy + dz * dz < limit:
                usable.append((i, j, k))
        if not usable:
            return bool(self.evaluate(np.array([x, y, z]))[0])
        empty = self._empty
        if any(empty[corner] < 0 for corner in usable):
            self._ensure(np.array(usable, np.int64))
        allowed = self.config.max_empty_sectors
        return all(empty[corner] <= allowed for corner in usable)

    def contains_many(
        self, positions: np.ndarray, clearances_m: np.ndarray | None = None
    ) -> np.ndarray:
        """:meth:`contains` for (N, 3) points at once, with the same answers.

        The corners not evaluated yet, of all points together, are probed in one ray cast
        (a batched env asks this for all its agents every step).

        Args:
            positions: (N, 3) points.
            clearances_m: (N,) their distances to the nearest surface, when the caller knows
                them (otherwise one distance query for all).
        """
        positions = np.asarray(positions, np.float64).reshape(-1, 3)
        if len(positions) == 1:  # one agent per scene (scene streams): no array set-up
            clearance = None if clearances_m is None else float(np.ravel(clearances_m)[0])
            return np.array([self.contains(positions[0], clearance)])
        inside = positions[:, 2] <= self.top_m
        if not inside.any():
            return inside
        if clearances_m is None:
            clearances_m = np.zeros(len(positions))
            clearances_m[inside] = self.raycaster.unsigned_distance(positions[inside])
        clearances_m = np.ascontiguousarray(clearances_m, np.float64).reshape(-1)
        origin, shape, voxel = self._lattice_origin, self._lattice_shape, self.config.voxel_m
        usable, exact, unknown = usable_corners(
            positions, clearances_m, self.top_m, origin, voxel, shape, self._empty
        )
        if exact.any():
            inside[exact] = self.evaluate(positions[exact])
        if len(unknown):
            self._evaluate(unknown)  # distinct and not evaluated yet
        supported = corners_supported(
            positions, usable, origin, voxel, shape, self._empty, self.config.max_empty_sectors
        )
        return inside & supported


_CELL_STEPS = tuple((i, j, k) for i in (0, 1) for j in (0, 1) for k in (0, 1))
