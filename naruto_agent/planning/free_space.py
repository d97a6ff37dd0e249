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

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from naruto_agent.planning.sdf_volume import SdfVolume

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

    def labels_near(self, point: np.ndarray) -> set[int]:
        """Component ids of the free corners of the cell holding ``point`` (empty if none)."""
        index = (np.asarray(point, dtype=np.float64).reshape(3) - self.origin) / self.voxel_size
        upper = np.asarray(self.labels.shape) - 2
        if np.any(index < 0) or np.any(index > upper + 1):
            return set()
        cell = np.clip(np.floor(index).astype(np.int64), 0, upper)
        corners = cell + _CELL_CORNERS
        found = self.labels[corners[:, 0], corners[:, 1], corners[:, 2]]
        return {int(label) for label in found if label > 0}

    def connected(self, start: np.ndarray, goal: np.ndarray) -> bool:
        """False only when no free path (per the trilinear SDF) can join start and goal."""
        return bool(self.labels_near(start) & self.labels_near(goal))
