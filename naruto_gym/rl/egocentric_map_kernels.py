"""Compiled loops of the egocentric map (:mod:`naruto_gym.rl.egocentric_map`): projecting depth
into per-episode world grids, and resampling those grids around the agent.

A world grid is ``(4, W, W)`` uint8, one layer per :data:`LAYERS` entry, 255 where set. Every
write to a fine cell also sets the cell of a coarse grid ``factor`` times larger, so the far
view of the map is read without pooling.
"""

from __future__ import annotations

import numba
import numpy as np

from naruto_gym.geometry.egocentric import crop_cell, heading_axes

#: Layers of the world grids: obstacles at the agent's height, space the rays crossed at the
#: agent's height, surface the camera has seen (any height), cells the agent stood in.
LAYERS = ("occupied", "free", "seen_surface", "trail")
OCCUPIED, FREE, SEEN, TRAIL = 0, 1, 2, 3

#: Channels of one scale of the egocentric map observation.
MAP_CHANNELS = ("occupied", "free", "seen_surface", "frontier", "trail")
_JIT = {"cache": True, "nogil": True}


@numba.njit(**_JIT)
def _set(grid: np.ndarray, coarse: np.ndarray, factor: int, layer: int, i: int, j: int) -> None:
    if i < 0 or j < 0 or i >= grid.shape[1] or j >= grid.shape[2]:
        return
    grid[layer, i, j] = 255
    coarse[layer, i // factor, j // factor] = 255


@numba.njit(**_JIT)
def _carve(
    grid: np.ndarray,
    coarse: np.ndarray,
    factor: int,
    x0: float,
    y0: float,
    dx: float,
    dy: float,
    length: float,
) -> None:
    """Mark free every cell of the segment from (x0, y0) (cell units) along the unit (dx, dy)
    for ``length`` cells."""
    steps = int(length) + 1
    for s in range(steps + 1):
        t = min(float(s), length)
        _set(grid, coarse, factor, FREE, int(np.floor(x0 + t * dx)), int(np.floor(y0 + t * dy)))


@numba.njit(**_JIT)
def update_grid(
    grid: np.ndarray,
    coarse: np.ndarray,
    factor: int,
    origin: np.ndarray,
    cell_m: float,
    pose: np.ndarray,
    depth: np.ndarray,
    intrinsics: np.ndarray,
    depth_stride: int,
    panorama: np.ndarray,
    panorama_directions: np.ndarray,
    row_low: int,
    row_high: int,
    panorama_stride: int,
    band_m: float,
    phase: int,
) -> None:
    """Add one observation of one agent to its world grid.

    Args:
        grid, coarse: the agent's fine ``(4, W, W)`` and coarse grids.
        factor: coarse cell side in fine cells.
        origin: world (x, y) of the fine grid's corner.
        cell_m: fine cell side.
        pose: (4, 4) camera-to-world.
        depth: (h, w) pinhole depth in metres (0: no hit), or (0, 0) when absent.
        intrinsics: fx, fy, cx, cy of the depth frame.
        depth_stride: every ``depth_stride``-th depth pixel is projected.
        panorama: (H, W) radial distances of the world-aligned panorama, or (0, 0).
        panorama_directions: (H * W, 3) unit ray directions of the panorama.
        row_low, row_high: panorama rows read (those near the horizon).
        panorama_stride: every ``panorama_stride``-th panorama column is read, starting at
            ``phase % panorama_stride`` (successive steps read interleaved columns).
        band_m: hits within this height of the camera are obstacles; free space is carved only
            where the ray stays within it.
    """
    px, py, pz = pose[0, 3], pose[1, 3], pose[2, 3]
    cx0 = (px - origin[0]) / cell_m
    cy0 = (py - origin[1]) / cell_m
    ci, cj = int(np.floor(cx0)), int(np.floor(cy0))
    _set(grid, coarse, factor, TRAIL, ci, cj)
    _set(grid, coarse, factor, FREE, ci, cj)
    height, width = depth.shape
    fx, fy, ccx, ccy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    for v in range(depth_stride // 2, height, depth_stride):
        for u in range(depth_stride // 2, width, depth_stride):
            d = depth[v, u]
            if d <= 0:
                continue
            x = (u + 0.5 - ccx) / fx * d
            y = (v + 0.5 - ccy) / fy * d
            wx = pose[0, 0] * x + pose[0, 1] * y + pose[0, 2] * d + px
            wy = pose[1, 0] * x + pose[1, 1] * y + pose[1, 2] * d + py
            wz = pose[2, 0] * x + pose[2, 1] * y + pose[2, 2] * d + pz
            i = int(np.floor((wx - origin[0]) / cell_m))
            j = int(np.floor((wy - origin[1]) / cell_m))
            _set(grid, coarse, factor, SEEN, i, j)
            if abs(wz - pz) <= band_m:
                _set(grid, coarse, factor, OCCUPIED, i, j)
    pano_width = panorama.shape[1]
    for v in range(row_low, min(row_high, panorama.shape[0])):
        for u in range(phase % panorama_stride, pano_width, panorama_stride):
            r = panorama[v, u]
            if r <= 0:
                continue  # no hit: nothing is known along it (it may leave the scan)
            k = v * pano_width + u
            dx, dy, dz = (
                panorama_directions[k, 0],
                panorama_directions[k, 1],
                panorama_directions[k, 2],
            )
            horizontal = np.sqrt(dx * dx + dy * dy)
            if horizontal < 1e-6:
                continue
            if abs(r * dz) <= band_m:
                _set(
                    grid,
                    coarse,
                    factor,
                    OCCUPIED,
                    int(np.floor(cx0 + r * dx / cell_m)),
                    int(np.floor(cy0 + r * dy / cell_m)),
                )
            # Free along the ray while it stays within the band, short of the hit's cell.
            reach = r * horizontal - cell_m
            if abs(dz) > 1e-6:
                reach = min(reach, band_m / abs(dz) * horizontal)
            if reach > 0:
                _carve(
                    grid, coarse, factor, cx0, cy0, dx / horizontal, dy / horizontal, reach / cell_m
                )


@numba.njit(**_JIT)
def is_unknown(grid: np.ndarray, i: int, j: int) -> bool:
    """Cell ``(i, j)`` of a ``(channels, rows, columns)`` grid is neither free nor occupied
    (outside the grid counts as unknown)."""
    if i < 0 or j < 0 or i >= grid.shape[1] or j >= grid.shape[2]:
        return True
    return grid[FREE, i, j] == 0 and grid[OCCUPIED, i, j] == 0


@numba.njit(**_JIT)
def crop_scale(
    grid: np.ndarray, origin: np.ndarray, cell_m: float, pose: np.ndarray, out: np.ndarray
) -> None:
    """Resample ``grid`` (cells of ``cell_m``) around the agent into ``out`` (5, c, c), the
    :data:`MAP_CHANNELS`: row 0 ahead, the agent at the centre, its heading up the image."""
    cells = out.shape[1]
    axes = heading_axes(pose)
    rows, columns = grid.shape[1], grid.shape[2]
    for r in range(cells):
        for c in range(cells):
            i, j = crop_cell(pose, axes, origin[0], origin[1], cell_m, cells, r, c)
            if i < 0 or j < 0 or i >= rows or j >= columns:
                for channel in range(5):
                    out[channel, r, c] = 0
                continue
            occupied = grid[OCCUPIED, i, j]
            free = grid[FREE, i, j] if occupied == 0 else 0
            out[0, r, c] = occupied
            out[1, r, c] = free
            out[2, r, c] = grid[SEEN, i, j]
            frontier = free > 0 and (
                is_unknown(grid, i - 1, j)
                or is_unknown(grid, i + 1, j)
                or is_unknown(grid, i, j - 1)
                or is_unknown(grid, i, j + 1)
            )
            out[3, r, c] = 255 if frontier else 0
            out[4, r, c] = grid[TRAIL, i, j]


@numba.njit(**_JIT)
def update_grids(
    grids: np.ndarray,
    coarse: np.ndarray,
    factor: int,
    origins: np.ndarray,
    cell_m: float,
    poses: np.ndarray,
    depths: np.ndarray,
    intrinsics: np.ndarray,
    depth_stride: int,
    panoramas: np.ndarray,
    panorama_directions: np.ndarray,
    row_low: int,
    row_high: int,
    panorama_stride: int,
    band_m: float,
    phases: np.ndarray,
    envs: np.ndarray,
    first: int,
    last: int,
) -> None:
    """:func:`update_grid` for the rows ``first`` to ``last`` (exclusive) of a batch: row
    ``k`` is agent ``envs[k]``'s observation (``poses[k]``, ``depths[k]`` (``(n, 0, 0)``
    when absent), ``panoramas[k]``) at its step ``phases[k]``. Rows write only their own
    agent's grids, so disjoint ranges run in parallel threads."""
    for k in range(first, last):
        i = envs[k]
        update_grid(
            grids[i],
            coarse[i],
            factor,
            origins[i],
            cell_m,
            poses[k],
            depths[k],
            intrinsics,
            depth_stride,
            panoramas[k],
            panorama_directions,
            row_low,
            row_high,
            panorama_stride,
            band_m,
            phases[k],
        )


@numba.njit(**_JIT)
def crop_all(
    grids: np.ndarray,
    coarse: np.ndarray,
    origins: np.ndarray,
    cell_m: float,
    factor: int,
    poses: np.ndarray,
    envs: np.ndarray,
    out: np.ndarray,
) -> None:
    """Near (fine grid) and far (coarse grid) crops of ``envs`` into ``out`` (n, 10, c, c)."""
    for row in range(len(envs)):
        i = envs[row]
        crop_scale(grids[i], origins[i], cell_m, poses[row], out[row, :5])
        crop_scale(coarse[i], origins[i], cell_m * factor, poses[row], out[row, 5:])
