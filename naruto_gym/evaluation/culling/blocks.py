"""Vertices in spatial blocks, and which poses' frustums can reach each block.

A vertex only has to try the poses of its block's list: a bounding-sphere test of the block
against each frustum, inflated far above rounding so that it never drops a pair the exact
per-vertex test (:mod:`.kernels`) would keep.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from naruto_gym.evaluation.culling.kernels import block_pose_reach
from naruto_gym.sensors.pinhole import PinholeCamera

# Block spheres are inflated by this much before the frustum test (metres): far above the
# rounding error of the exact per-vertex test, so no pair the exact test keeps is dropped.
_REACH_SLACK_M = 1e-4


def _frustum_planes(camera: PinholeCamera) -> np.ndarray:
    """Unit normals (camera frame) of the planes bounding the frustum: in front of the
    camera, and the four sides through the outer edges of the border pixels."""
    planes = np.array(
        [
            [0.0, 0.0, 1.0],
            [camera.fx, 0.0, camera.cx + 0.5],
            [-camera.fx, 0.0, camera.width - 0.5 - camera.cx],
            [0.0, camera.fy, camera.cy + 0.5],
            [0.0, -camera.fy, camera.height - 0.5 - camera.cy],
        ]
    )
    return planes / np.linalg.norm(planes, axis=1, keepdims=True)


@dataclass(frozen=True)
class VertexBlocks:
    """Vertices sorted into spatial blocks.

    Attributes:
        order: (V,) original index of each sorted vertex.
        points: (V, 3) the sorted vertices.
        vertex_block: (V,) block of each sorted vertex.
        vertex_start: (B + 1,) first sorted vertex of each block.
        centres, radii: (B, 3) and (B,) bounding spheres.
    """

    order: np.ndarray
    points: np.ndarray
    vertex_block: np.ndarray
    vertex_start: np.ndarray
    centres: np.ndarray
    radii: np.ndarray


def vertex_blocks(vertices: np.ndarray, size_m: float) -> VertexBlocks:
    """(V, 3) vertices sorted into cubic blocks of side ``size_m`` (metres)."""
    cells = np.floor(vertices / size_m).astype(np.int64)
    cells -= cells.min(axis=0)
    extent = cells.max(axis=0) + 1
    keys = (cells[:, 0] * extent[1] + cells[:, 1]) * extent[2] + cells[:, 2]
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    vertex_block = np.concatenate([[0], np.cumsum(sorted_keys[1:] != sorted_keys[:-1])])
    points = np.ascontiguousarray(vertices[order])
    vertex_start = np.concatenate([[0], np.cumsum(np.bincount(vertex_block))])
    lower = np.minimum.reduceat(points, vertex_start[:-1], axis=0)
    upper = np.maximum.reduceat(points, vertex_start[:-1], axis=0)
    centres = 0.5 * (lower + upper)
    distance = np.linalg.norm(points - centres[vertex_block], axis=1)
    radii = np.maximum.reduceat(distance, vertex_start[:-1])
    return VertexBlocks(order, points, vertex_block, vertex_start, centres, radii)


def block_reach(
    blocks: VertexBlocks, rotations: np.ndarray, positions: np.ndarray, camera: PinholeCamera
) -> np.ndarray:
    """(B, K) bool: which poses' frustums can hold a vertex of which block."""
    reach = np.empty((len(blocks.centres), len(rotations)), dtype=bool)
    block_pose_reach(
        blocks.centres,
        blocks.radii,
        rotations,
        positions,
        _frustum_planes(camera),
        _REACH_SLACK_M,
        reach,
    )
    return reach
