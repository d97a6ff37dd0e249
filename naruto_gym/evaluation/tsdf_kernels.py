"""Numba kernels over the TSDF's block buffers (see :class:`TsdfFusionMapper`)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def behind_surface_bounds(
    centres: np.ndarray,
    half_extent: float,
    table: np.ndarray,
    low: np.ndarray,
    tsdf: np.ndarray,
    weight: np.ndarray,
    resolution: int,
    voxel: float,
    truncation: float,
    min_weight: float,
) -> np.ndarray:
    """(N,) min of ``s(p) + |p - c|`` over the observed voxels ``p`` with ``s(p) < 0`` within
    ``half_extent`` of each centre ``c`` along every axis; +inf where there is none.

    Voxel ``g`` (global integer index) lies at ``g * voxel``; its block is ``g // resolution``
    and its slot ``table[block - low]`` (-1: not allocated); Open3D stores a block as [z, y, x].
    """
    out = np.full(centres.shape[0], np.inf)
    shape = table.shape
    for i in range(centres.shape[0]):
        cx, cy, cz = centres[i, 0], centres[i, 1], centres[i, 2]
        x0 = math.ceil((cx - half_extent) / voxel)
        x1 = math.floor((cx + half_extent) / voxel)
        y0 = math.ceil((cy - half_extent) / voxel)
        y1 = math.floor((cy + half_extent) / voxel)
        z0 = math.ceil((cz - half_extent) / voxel)
        z1 = math.floor((cz + half_extent) / voxel)
        best = np.inf
        for gx in range(x0, x1 + 1):
            bx = gx // resolution
            tx = bx - low[0]
            if tx < 0 or tx >= shape[0]:
                continue
            lx = gx - bx * resolution
            dx = gx * voxel - cx
            for gy in range(y0, y1 + 1):
                by = gy // resolution
                ty = by - low[1]
                if ty < 0 or ty >= shape[1]:
                    continue
                ly = gy - by * resolution
                dy = gy * voxel - cy
                for gz in range(z0, z1 + 1):
                    bz = gz // resolution
                    tz = bz - low[2]
                    if tz < 0 or tz >= shape[2]:
                        continue
                    slot = table[tx, ty, tz]
                    if slot < 0:
                        continue
                    lz = gz - bz * resolution
                    if weight[slot, lz, ly, lx] < min_weight:
                        continue
                    value = tsdf[slot, lz, ly, lx] * truncation
                    if value >= 0.0:
                        continue
                    dz = gz * voxel - cz
                    bound = value + math.sqrt(dx * dx + dy * dy + dz * dz)
                    if bound < best:
                        best = bound
        out[i] = best
    return out
