"""Colour of ray hits: barycentric interpolation of per-corner colours, compiled with numba.

A numpy version of this gather-and-blend costs about 50 ms for a 680 x 1200 frame on two
cores; the compiled loop costs about 3 ms, which keeps a full RGB-D frame within a few per
cent of the bare depth cast. Serial on purpose: a parallel numba threading layer would have to
coexist with torch's and with spawned env workers.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, fastmath=True, nogil=True)
def interpolate_corner_colours(
    triangle_ids: np.ndarray, barycentric_uv: np.ndarray, corner_colours: np.ndarray,
    out: np.ndarray,
) -> None:
    """Write the RGB of each hit into ``out`` ((N, 3) uint8); black where triangle id < 0.

    Args:
        triangle_ids: (N,) integer triangle index per hit, negative for a miss.
        barycentric_uv: (N, 2) float32 (u, v): point = (1 - u - v) v0 + u v1 + v v2.
        corner_colours: (F, 3, 3) float32 RGB at each triangle corner.
        out: (N, 3) uint8 output.
    """
    for i in range(triangle_ids.shape[0]):
        triangle = triangle_ids[i]
        if triangle < 0:
            out[i, 0] = 0
            out[i, 1] = 0
            out[i, 2] = 0
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
