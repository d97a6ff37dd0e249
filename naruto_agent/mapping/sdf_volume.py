"""A dense regular grid of float values in the world (an SDF, or an uncertainty volume).

The planner never looks at a mesh or a neural network directly: it reads signed distances from
an :class:`SdfVolume`, a block of values on voxel centres, interpolated trilinearly. The mapper
produces one from its neural field; :meth:`SdfVolume.from_mesh` produces one from a
ground-truth mesh, so planning can be tested and benchmarked without a trained map.

Axis order is (x, y, z) everywhere: ``values[i, j, k]`` is the value at the world point
``origin + voxel_size * (i, j, k)``. (The released NARUTO code swaps x and z when sampling its
grids; this module does not.)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy import ndimage

from naruto_agent.mapping.grid_memory import check_grid_memory
from naruto_gym.utils.checks import check_number

if TYPE_CHECKING:  # pragma: no cover
    from naruto_gym.scenes.mesh_scene import Scene
    from naruto_gym.sensors.raycaster import RayCaster

# Directions of the rays that vote on the sign of the distance (see ``from_mesh``): an odd
# number of well spread directions, so a vote cannot tie and no direction is axis-aligned
# (axis-aligned rays graze the walls of box-shaped rooms).
_SIGN_VOTE_DIRECTIONS = 9


def _fibonacci_directions(count: int) -> np.ndarray:
    """``count`` unit vectors spread nearly uniformly over the sphere, none on an axis."""
    index = np.arange(count, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * index / count
    radius = np.sqrt(np.clip(1.0 - z * z, 0.0, 1.0))
    angle = index * np.pi * (3.0 - np.sqrt(5.0)) + 0.3
    directions = np.stack([radius * np.cos(angle), radius * np.sin(angle), z], axis=1)
    return directions / np.linalg.norm(directions, axis=1, keepdims=True)


@dataclass(eq=False)  # arrays make field-wise == ambiguous; volumes compare by identity
class SdfVolume:
    """Values on a regular voxel grid, read by trilinear interpolation.

    Used for the planner's signed distance field (metres, positive in free space) and, with
    the same class, for the uncertainty volume.

    Attributes:
        values: (nx, ny, nz) float32 values, axis order (x, y, z).
        origin: (3,) world position of the centre of voxel (0, 0, 0), metres.
        voxel_size: edge length of a voxel, metres.
    """

    values: np.ndarray
    origin: np.ndarray
    voxel_size: float

    def __post_init__(self) -> None:
        self.values = np.ascontiguousarray(self.values, dtype=np.float32)
        if self.values.ndim != 3 or min(self.values.shape) < 2:
            raise ValueError(
                f"values must be a 3-D (nx, ny, nz) grid with at least 2 voxels per axis, "
                f"got shape {self.values.shape}"
            )
        self.origin = np.asarray(self.origin, dtype=np.float64).reshape(-1)
        if self.origin.shape != (3,) or not np.all(np.isfinite(self.origin)):
            raise ValueError(f"origin must be a finite (3,) world point, got {self.origin}")
        self.voxel_size = check_number("voxel_size (metres)", self.voxel_size, low=0.0)

    @property
    def _upper_index(self) -> np.ndarray:
        return np.asarray(self.values.shape, dtype=np.float64) - 1.0

    # -- geometry of the grid -----------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int, int]:
        """Number of voxels along (x, y, z)."""
        return tuple(int(n) for n in self.values.shape)  # type: ignore[return-value]

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) [min, max] world box spanned by the voxel centres.

        This is where :meth:`sample` interpolates; the cells themselves reach half a voxel
        further out.
        """
        return np.stack([self.origin, self.origin + self.voxel_size * self._upper_index])

    def world_to_voxel(self, points: np.ndarray) -> np.ndarray:
        """Continuous voxel coordinates (..., 3) of world points (..., 3); integers at centres."""
        return (np.asarray(points, dtype=np.float64) - self.origin) / self.voxel_size

    def voxel_to_world(self, indices: np.ndarray) -> np.ndarray:
        """World points (..., 3) of (possibly fractional) voxel coordinates (..., 3)."""
        return self.origin + self.voxel_size * np.asarray(indices, dtype=np.float64)

    def contains(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: which points lie inside :attr:`bounds` (where :meth:`sample` is defined)."""
        index = self.world_to_voxel(np.asarray(points).reshape(-1, 3))
        return np.all((index >= 0.0) & (index <= self._upper_index), axis=1)

    def grid_points(self) -> np.ndarray:
        """(nx * ny * nz, 3) world positions of all voxel centres, in ``values.ravel()`` order."""
        axes = [np.arange(n, dtype=np.float64) for n in self.values.shape]
        index = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        return self.voxel_to_world(index)

    # -- lookup ---------------------------------------------------------------------------------
    def sample(self, points: np.ndarray, outside_value: float = -1.0) -> np.ndarray:
        """Trilinear values at world points.

        Args:
            points: (N, 3) (or (3,)) world points, metres.
            outside_value: value returned for points outside :attr:`bounds`; the default -1.0
                reads as "not free" for an SDF.

        Returns:
            (N,) float64 values.
        """
        index = (np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.origin) / (
            self.voxel_size
        )
        # scipy's order-1 spline is exactly trilinear interpolation, in C: faster than
        # numpy for the few dozen points of a collision check. Its "constant" mode
        # returns cval for every point outside [0, n - 1] on any axis and never blends it in.
        return ndimage.map_coordinates(
            self.values,
            index.T,
            order=1,
            mode="constant",
            cval=outside_value,
            prefilter=False,
            output=np.float64,
        )

    # -- construction -----------------------------------------------------------------------------
    @staticmethod
    def _grid_for_bounds(
        bounds: np.ndarray, voxel_size: float, padding: float
    ) -> tuple[np.ndarray, tuple[int, int, int]]:
        bounds = np.asarray(bounds, dtype=np.float64)
        if bounds.shape != (2, 3) or not np.all(np.isfinite(bounds)):
            raise ValueError(f"bounds must be a finite (2, 3) [min, max] box, got {bounds}")
        if np.any(bounds[1] <= bounds[0]):
            raise ValueError(f"bounds max must exceed min on every axis, got {bounds.tolist()}")
        voxel_size = check_number("voxel_size (metres)", voxel_size, low=0.0)
        padding = check_number("padding (metres)", padding, low=0.0, low_open=False)
        lower = bounds[0] - padding
        extent = bounds[1] + padding - lower
        counts = np.maximum(np.ceil(extent / voxel_size - 1e-9).astype(int) + 1, 2)
        shape = (int(counts[0]), int(counts[1]), int(counts[2]))
        # float32 values, and the float64 voxel centres ``from_function`` evaluates.
        check_grid_memory(shape, 28, voxel_size, "SDF volume")
        return lower, shape

    @classmethod
    def from_function(
        cls,
        fn: Callable[[np.ndarray], np.ndarray],
        bounds: np.ndarray,
        voxel_size: float = 0.1,
        padding: float = 0.0,
    ) -> SdfVolume:
        """Sample ``fn`` ((N, 3) world points -> (N,) values) on a grid covering ``bounds``.

        The grid's first voxel centre is at ``bounds[0] - padding`` and it extends to cover
        ``bounds[1] + padding`` (rounded up to whole voxels).
        """
        origin, shape = cls._grid_for_bounds(bounds, voxel_size, padding)
        volume = cls(np.zeros(shape, dtype=np.float32), origin, voxel_size)
        values = np.asarray(fn(volume.grid_points()), dtype=np.float32).reshape(-1)
        if values.shape[0] != volume.values.size:
            raise ValueError(
                f"fn returned {values.shape[0]} values for {volume.values.size} points; "
                "it must return one value per point"
            )
        return cls(values.reshape(shape), origin, voxel_size)

    @classmethod
    def from_mesh(
        cls,
        mesh: Scene | RayCaster | np.ndarray,
        faces: np.ndarray | None = None,
        voxel_size: float = 0.1,
        padding: float = 0.2,
        bounds: np.ndarray | None = None,
        chunk_size: int = 200_000,
    ) -> SdfVolume:
        """Signed distance field of a triangle mesh, on a grid (ground truth for planning).

        The magnitude is the exact distance to the closest triangle (Embree, through
        :meth:`RayCaster.unsigned_distance`). The sign is decided by a vote of 9 rays per
        voxel centre: a ray whose first hit is a triangle's front face (winding
        counter-clockwise seen from the ray's origin, i.e. the normal faces the point)
        votes "free"; a back face or a miss votes "occupied". The voxel is free (positive)
        on a majority. This needs triangles oriented towards free space, which holds for
        scanned rooms (normals face the sensor) and for solid objects with outward normals;
        a room built from one closed box must have its faces turned inwards. It tolerates
        holes in scans: points outside a room's walls see back faces or nothing, so they
        read as occupied, and a few rays escaping through a hole are outvoted.

        Args:
            mesh: a :class:`~naruto_gym.scenes.mesh_scene.Scene`, a
                :class:`~naruto_gym.sensors.raycaster.RayCaster`, or an (V, 3) vertex array
                (then ``faces`` is required).
            faces: (F, 3) triangle indices when ``mesh`` is a vertex array.
            voxel_size: voxel edge, metres (NARUTO plans on 0.1 m voxels).
            padding: metres added around the mesh bounds (ignored for explicit ``bounds``
                beyond being added to them too).
            bounds: (2, 3) box to cover instead of the mesh's bounds.
            chunk_size: voxel centres processed per batch (bounds memory use).

        Returns:
            The signed distance volume, metres, positive in free space.
        """
        from naruto_gym.sensors.raycaster import RayCaster

        if isinstance(mesh, RayCaster):
            caster = mesh
        elif hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
            caster = RayCaster(np.asarray(mesh.vertices), np.asarray(mesh.faces))
        else:
            if faces is None:
                raise ValueError(
                    "from_mesh got a vertex array without faces: pass faces=(F, 3) indices, "
                    "or a Scene / RayCaster"
                )
            caster = RayCaster(np.asarray(mesh), np.asarray(faces))
        if bounds is None:
            bounds = np.stack([caster.vertices.min(axis=0), caster.vertices.max(axis=0)])
        origin, shape = cls._grid_for_bounds(np.asarray(bounds, float), voxel_size, padding)
        grid = cls(np.zeros(shape, dtype=np.float32), origin, voxel_size)
        points = grid.grid_points()

        triangles = caster.vertices[caster.faces].astype(np.float64)
        normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
        directions = _fibonacci_directions(_SIGN_VOTE_DIRECTIONS)
        values = np.empty(len(points), dtype=np.float32)
        for begin in range(0, len(points), chunk_size):
            chunk = points[begin : begin + chunk_size]
            distance = caster.unsigned_distance(chunk)
            origins = np.repeat(chunk, len(directions), axis=0)
            rays = np.tile(directions, (len(chunk), 1))
            hit_ids = caster.cast(origins, rays).triangle_ids
            hit = hit_ids >= 0
            facing = np.zeros(len(rays), dtype=bool)
            facing[hit] = np.einsum("ij,ij->i", normals[hit_ids[hit]], rays[hit]) < 0.0
            free_votes = facing.reshape(len(chunk), len(directions)).sum(axis=1)
            sign = np.where(2 * free_votes > len(directions), 1.0, -1.0)
            values[begin : begin + len(chunk)] = sign * distance
        return cls(values.reshape(shape), origin, voxel_size)
