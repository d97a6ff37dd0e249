"""Which parts of the free space are connected: a quick "is this goal reachable at all?".

A planner that grows a tree towards an unreachable goal only stops at its iteration or time
limit. Labelling the connected components of the free voxels once per map answers the
question in microseconds per request, and it is exact for the trilinear SDF the planner
reads: every point whose interpolated SDF exceeds the clearance connects, inside its cell,
to a free corner of that cell (along each axis the interpolant is linear, so one can walk
towards the larger corner value), and all corners of a cell are 26-neighbours. So two points
joined by a free path have cells whose free corners share a 26-connected component.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass

import numba
import numpy as np
from scipy import ndimage

from naruto_agent.mapping.sdf_volume import SdfVolume

_CELL_CORNERS = np.array(
    [[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=np.int64
)


@dataclass(eq=False)
class FreeSpaceComponents:
    """Connected components (26-connectivity) of the voxels with SDF > clearance.

    Build it once per SDF volume and clearance with :meth:`from_sdf`, then ask
    :meth:`connected` per planning request.

    Attributes:
        labels: (nx, ny, nz) int32 component id per voxel, 0 for voxels that are not free.
        count: number of components.
        origin: (3,) world position of voxel (0, 0, 0).
        voxel_size: voxel edge, metres.
        clearance_m: the SDF threshold used.
    """

    labels: np.ndarray
    count: int
    origin: np.ndarray
    voxel_size: float
    clearance_m: float

    @classmethod
    def from_sdf(cls, sdf: SdfVolume, clearance_m: float) -> FreeSpaceComponents:
        """Label the free voxels of ``sdf`` (SDF > ``clearance_m``)."""
        labels, count = ndimage.label(sdf.values > clearance_m, structure=np.ones((3, 3, 3)))
        return cls(labels.astype(np.int32), int(count), sdf.origin.copy(), sdf.voxel_size,
                   float(clearance_m))

    def free_corners(self, point: np.ndarray) -> np.ndarray:
        """(K, 3) voxel indices of the free corners of the cell holding ``point`` (K = 0
        when it lies outside the grid or no corner is free)."""
        index = (np.asarray(point, dtype=np.float64).reshape(3) - self.origin) / self.voxel_size
        upper = np.asarray(self.labels.shape) - 2
        if np.any(index < 0) or np.any(index > upper + 1):
            return np.zeros((0, 3), np.int64)
        corners = np.clip(np.floor(index).astype(np.int64), 0, upper) + _CELL_CORNERS
        return corners[self.labels[corners[:, 0], corners[:, 1], corners[:, 2]] > 0]

    def labels_near(self, point: np.ndarray) -> set[int]:
        """Component ids of the free corners of the cell holding ``point`` (empty if none)."""
        corners = self.free_corners(point)
        return {int(label) for label in self.labels[corners[:, 0], corners[:, 1], corners[:, 2]]}

    def connected(self, start: np.ndarray, goal: np.ndarray) -> bool:
        """False only when no free path (per the trilinear SDF) can join start and goal."""
        return bool(self.labels_near(start) & self.labels_near(goal))

    def travel_distances(self, start: np.ndarray) -> np.ndarray:
        """(nx, ny, nz) length of the shortest 26-connected path through free voxels from
        ``start`` to each voxel (metres; inf where no free path leads).

        Paths run from voxel centre to voxel centre (steps of 1, sqrt 2 or sqrt 3 voxels)
        and begin at the free corners of ``start``'s cell, each at its straight distance
        from ``start``. A lattice path is at most about 8 % longer than the straight line
        it follows in open space, and around walls it is the detour a planner must take,
        which the straight distance between two rooms does not show.
        """
        start = np.asarray(start, dtype=np.float64).reshape(3)
        distances = np.full(self.labels.shape, np.inf)
        corners = self.free_corners(start)
        if len(corners) == 0:
            return distances
        offsets = np.linalg.norm(corners * self.voxel_size + self.origin - start, axis=1)
        _dijkstra(self.labels > 0, corners, offsets, self.voxel_size, distances)
        return distances


_STEPS = np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)
                   if (i, j, k) != (0, 0, 0)], dtype=np.int64)


@numba.njit(cache=True, nogil=True)
def _dijkstra(free: np.ndarray, sources: np.ndarray, offsets: np.ndarray, voxel_size: float,
              distances: np.ndarray) -> None:
    """Shortest 26-connected paths over ``free`` voxels from ``sources`` (written into
    ``distances``, which holds inf elsewhere)."""
    nx, ny, nz = free.shape
    steps = _STEPS
    lengths = np.sqrt((steps * steps).sum(axis=1).astype(np.float64)) * voxel_size
    heap = [(0.0, 0, 0, 0)]
    heap.pop()
    for row in range(len(sources)):
        x, y, z = sources[row, 0], sources[row, 1], sources[row, 2]
        if offsets[row] < distances[x, y, z]:
            distances[x, y, z] = offsets[row]
            heapq.heappush(heap, (offsets[row], x, y, z))
    while len(heap) > 0:
        distance, x, y, z = heapq.heappop(heap)
        if distance > distances[x, y, z]:
            continue
        for step in range(len(steps)):
            a = x + steps[step, 0]
            b = y + steps[step, 1]
            c = z + steps[step, 2]
            if a < 0 or b < 0 or c < 0 or a >= nx or b >= ny or c >= nz or not free[a, b, c]:
                continue
            candidate = distance + lengths[step]
            if candidate < distances[a, b, c]:
                distances[a, b, c] = candidate
                heapq.heappush(heap, (candidate, a, b, c))
