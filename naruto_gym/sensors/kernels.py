"""Per-pixel loops of the renderer, compiled with numba: filling the ray buffer and colouring
the hits.

Numpy versions of both cost tens of milliseconds for a 680 x 1200 frame on two cores (a matmul
into the strided half of the ray buffer even falls off BLAS); the compiled loops cost a few
milliseconds, which keeps a full RGB-D frame close to the bare depth cast. Serial on purpose: a
parallel numba threading layer would have to coexist with torch's and with spawned env
workers.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, fastmath=True, nogil=True)
def interpolate_corner_colours(
    triangle_ids: np.ndarray, barycentric_uv: np.ndarray, corner_colours: np.ndarray,
    flat_colours: np.ndarray, out: np.ndarray,
) -> None:
    """Write the RGB of each hit into ``out`` ((N, 3) uint8); black where triangle id < 0.

    Args:
        triangle_ids: (N,) integer triangle index per hit, negative for a miss.
        barycentric_uv: (N, 2) float32 (u, v): point = (1 - u - v) v0 + u v1 + v v2.
        corner_colours: (F, 3, 3) float32 RGB at each triangle corner.
        flat_colours: (F, 4) uint8: a triangle's first corner colour and 1 where all three
            corners share it. Its hits get that colour as it is: the interpolation of three
            equal whole numbers lands within 1e-12 of it, which the rounding below returns.
        out: (N, 3) uint8 output.
    """
    for i in range(triangle_ids.shape[0]):
        triangle = triangle_ids[i]
        if triangle < 0:
            out[i, 0] = 0
            out[i, 1] = 0
            out[i, 2] = 0
            continue
        if flat_colours[triangle, 3]:
            out[i, 0] = flat_colours[triangle, 0]
            out[i, 1] = flat_colours[triangle, 1]
            out[i, 2] = flat_colours[triangle, 2]
            continue
        u = barycentric_uv[i, 0]
        v = barycentric_uv[i, 1]
        w = 1.0 - u - v
        for channel in range(3):
            value = (
                w * corner_colours[triangle, 0, channel]
                + u * corner_colours[triangle, 1, channel]
                + v * corner_colours[triangle, 2, channel]
            )
            out[i, channel] = np.uint8(min(max(value + 0.5, 0.0), 255.0))


@numba.njit(cache=True, fastmath=True, nogil=True)
def fill_world_rays(
    camera_directions: np.ndarray, rotation: np.ndarray, origin: np.ndarray, rays: np.ndarray
) -> None:
    """Write [origin, rotation @ direction] of every pixel into ``rays`` ((N, 6) float32).

    Args:
        camera_directions: (N, 3) float32 camera-frame directions.
        rotation: (3, 3) float32 camera-to-world rotation.
        origin: (3,) float32 camera centre in the world.
        rays: (N, 6) float32 output buffer.
    """
    for i in range(camera_directions.shape[0]):
        x = camera_directions[i, 0]
        y = camera_directions[i, 1]
        z = camera_directions[i, 2]
        rays[i, 0] = origin[0]
        rays[i, 1] = origin[1]
        rays[i, 2] = origin[2]
        for row in range(3):
            rays[i, 3 + row] = rotation[row, 0] * x + rotation[row, 1] * y + rotation[row, 2] * z


@numba.njit(cache=True, nogil=True)
def fill_panorama_rays(
    directions: np.ndarray, positions: np.ndarray, rays: np.ndarray, offset: int
) -> None:
    """Write the same world directions from every position into ``rays[offset:]`` (an
    agent's panorama, a lattice corner's support cone).

    Args:
        directions: (P, 3) float32 unit world directions.
        positions: (N, 3) float32 ray origins.
        rays: float32 ray buffer, position ``i`` at ``offset + i * P``.
        offset: first row of the block.
    """
    count = directions.shape[0]
    for i in range(positions.shape[0]):
        start = offset + i * count
        for k in range(count):
            rays[start + k, 0] = positions[i, 0]
            rays[start + k, 1] = positions[i, 1]
            rays[start + k, 2] = positions[i, 2]
            rays[start + k, 3] = directions[k, 0]
            rays[start + k, 4] = directions[k, 1]
            rays[start + k, 5] = directions[k, 2]
