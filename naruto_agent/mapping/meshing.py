"""Marching-cubes meshes of an SDF given as a function, with vertex colours."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import trimesh
from skimage.measure import marching_cubes

from naruto_agent.mapping.sdf_volume import SdfVolume
from naruto_gym.utils.checks import check_number


def mesh_from_sdf_function(
    sdf_fn: Callable[[np.ndarray], np.ndarray],
    bounds: np.ndarray,
    voxel_size: float,
    colour_fn: Callable[[np.ndarray], np.ndarray] | None = None,
) -> trimesh.Trimesh:
    """Zero level set of ``sdf_fn`` on a ``voxel_size`` grid over ``bounds``.

    Args:
        sdf_fn: (N, 3) world points -> (N,) signed distances (positive in free space).
        bounds: (2, 3) world box.
        voxel_size: grid step, metres (0.02 for the final mesh, coarser for previews).
        colour_fn: (N, 3) points -> (N, 3) uint8 colours of the vertices (grey without one).

    Returns:
        The mesh (empty when the SDF has no zero crossing in the box).
    """
    check_number("voxel_size (metres)", voxel_size, low=0.0)
    volume = SdfVolume.from_function(sdf_fn, bounds, voxel_size)
    values = volume.values
    if not (values.min() < 0.0 < values.max()):
        return trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
    vertices, faces, _, _ = marching_cubes(values, level=0.0, spacing=(voxel_size,) * 3)
    vertices = vertices.astype(np.float64) + volume.origin
    # skimage's winding makes the normals point up the gradient, i.e. into free space (where
    # the SDF is positive): the orientation of a scanned room's surfaces.
    faces = faces.astype(np.int64)
    if colour_fn is None:
        colours = np.full((len(vertices), 3), 180, dtype=np.uint8)
    else:
        colours = np.asarray(colour_fn(vertices), dtype=np.uint8)
    rgba = np.concatenate([colours, np.full((len(colours), 1), 255, np.uint8)], axis=1)
    return trimesh.Trimesh(vertices, faces, vertex_colors=rgba, process=False)
