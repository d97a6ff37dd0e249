"""Compiled loops of mesh culling: frustum tests of (vertex, pose) pairs and their rays.

Vertices are grouped into spatial blocks; a block keeps the list of poses whose frustum can
reach it (a bounding-sphere test with slack, so it never drops a pair the exact test would
keep), and a vertex only visits its block's poses. The exact test is the one culling always
used: camera-frame z above ``NEAR_Z`` and the projection inside the image's pixel area
``[-0.5, W - 0.5) x [-0.5, H - 0.5)``.

Serial on purpose (see :mod:`naruto_gym.sensors.kernels`): the ray casts in between use both
cores through Embree's own threads.
"""

from __future__ import annotations

import numba
import numpy as np

# A vertex must lie this far in front of the camera centre (camera-frame z, metres).
NEAR_Z = 1e-6


@numba.njit(cache=True, nogil=True, inline="always")
def _camera_point(point, rotation, position):
    dx = point[0] - position[0]
    dy = point[1] - position[1]
    dz = point[2] - position[2]
    x = dx * rotation[0, 0] + dy * rotation[1, 0] + dz * rotation[2, 0]
    y = dx * rotation[0, 1] + dy * rotation[1, 1] + dz * rotation[2, 1]
    z = dx * rotation[0, 2] + dy * rotation[1, 2] + dz * rotation[2, 2]
    return x, y, z


@numba.njit(cache=True, nogil=True, inline="always")
def _pixel(x, y, z, intrinsics):
    """Pixel (u, v) of a camera-frame point and whether it lies in the frustum."""
    fx, fy, cx, cy = intrinsics[2], intrinsics[3], intrinsics[4], intrinsics[5]
    width, height = intrinsics[0], intrinsics[1]
    if not z > NEAR_Z:
        return 0.0, 0.0, False
    u = fx * x / z + cx
    v = fy * y / z + cy
    inside = u >= -0.5 and u < width - 0.5 and v >= -0.5 and v < height - 0.5
    return u, v, inside


@numba.njit(cache=True, nogil=True)
def block_pose_reach(
    centres: np.ndarray,
    radii: np.ndarray,
    rotations: np.ndarray,
    positions: np.ndarray,
    planes: np.ndarray,
    slack: float,
    reach: np.ndarray,
) -> None:
    """``reach[b, k]``: whether pose ``k``'s frustum can hold a point of block ``b``.

    Args:
        centres: (B, 3) block bounding-sphere centres.
        radii: (B,) their radii.
        rotations: (K, 3, 3) camera-to-world rotations.
        positions: (K, 3) camera centres.
        planes: (P, 3) unit normals, in the camera frame, of the planes bounding the frustum
            (inside: normal . point >= 0).
        slack: metres added to every sphere, far above floating-point error.
        reach: (B, K) bool output.
    """
    for k in range(rotations.shape[0]):
        rotation = rotations[k]
        for b in range(centres.shape[0]):
            x, y, z = _camera_point(centres[b], rotation, positions[k])
            inside = True
            for p in range(planes.shape[0]):
                if planes[p, 0] * x + planes[p, 1] * y + planes[p, 2] * z < -(radii[b] + slack):
                    inside = False
                    break
            reach[b, k] = inside


@numba.njit(cache=True, nogil=True)
def guide_rays(
    rotations: np.ndarray, positions: np.ndarray, directions: np.ndarray, rays: np.ndarray
) -> None:
    """Rays of the guide depth images: every pixel direction (camera frame, z = 1) of every
    pose, as rows [origin, direction] of ``rays`` ((K * P, 6) float32)."""
    count = directions.shape[0]
    for k in range(rotations.shape[0]):
        rotation = rotations[k]
        for p in range(count):
            row = k * count + p
            for j in range(3):
                rays[row, j] = positions[k, j]
                rays[row, 3 + j] = (
                    directions[p, 0] * rotation[j, 0]
                    + directions[p, 1] * rotation[j, 1]
                    + directions[p, 2] * rotation[j, 2]
                )


@numba.njit(cache=True, nogil=True)
def emit_pairs(
    points: np.ndarray,
    active: np.ndarray,
    cursor: np.ndarray,
    first_pose: np.ndarray,
    vertex_block: np.ndarray,
    block_start: np.ndarray,
    block_poses: np.ndarray,
    rotations: np.ndarray,
    positions: np.ndarray,
    intrinsics: np.ndarray,
    guide: np.ndarray,
    guide_slack: np.ndarray,
    want_likely: bool,
    per_vertex: int,
    out_vertex: np.ndarray,
    out_z: np.ndarray,
    out_rays: np.ndarray,
) -> int:
    """The next in-frustum poses of each active vertex, as occlusion rays to cast.

    Each active vertex walks its block's pose list from ``cursor`` on, skips poses below its
    ``first_pose`` and poses whose guide verdict is not ``want_likely``, and emits up to
    ``per_vertex`` pairs; ``cursor`` is left after the last pose visited (at the list's end
    when the walk ran out). A ray starts at the camera centre and points through the vertex
    with camera-frame z = 1, so its hit distance is the surface's z-depth there.

    Args:
        points: (V, 3) float64 vertices.
        active: (A,) indices of the vertices to advance.
        cursor: (V,) int64 position of each vertex in its block's pose list (updated).
        first_pose: (V,) int64 lowest pose index a vertex still has to try.
        vertex_block: (V,) block of each vertex.
        block_start: (B + 1,) start of each block's pose list in ``block_poses``.
        block_poses: increasing pose indices, block after block.
        rotations, positions: (K, 3, 3) and (K, 3) poses.
        intrinsics: (6,) ``(width, height, fx, fy, cx, cy)``.
        guide: (K, h, w) float32 coarse z-depth images (0 where nothing was hit).
        guide_slack: (3,) ``(margin, absolute, relative)``: a pair is likely visible when the
            guide has no hit or z <= guide + margin + absolute + relative * z.
        want_likely: emit the likely pairs (True) or the unlikely ones (False).
        per_vertex: most pairs a vertex emits.
        out_vertex, out_z, out_rays: (A * per_vertex,) vertex, z-depth and (., 6) float32 ray
            of each emitted pair.

    Returns:
        The number of pairs emitted.
    """
    width, height = intrinsics[0], intrinsics[1]
    guide_rows, guide_columns = guide.shape[1], guide.shape[2]
    scale_u, scale_v = guide_columns / width, guide_rows / height
    emitted = 0
    for a in range(active.shape[0]):
        i = active[a]
        block = vertex_block[i]
        start, end = block_start[block], block_start[block + 1]
        count = 0
        j = start + cursor[i]
        while j < end:
            k = block_poses[j]
            j += 1
            if k < first_pose[i]:
                continue
            x, y, z = _camera_point(points[i], rotations[k], positions[k])
            u, v, inside = _pixel(x, y, z, intrinsics)
            if not inside:
                continue
            column = min(max(int(np.floor((u + 0.5) * scale_u)), 0), guide_columns - 1)
            row = min(max(int(np.floor((v + 0.5) * scale_v)), 0), guide_rows - 1)
            depth = guide[k, row, column]
            likely = depth <= 0.0 or z <= (
                depth + guide_slack[0] + guide_slack[1] + guide_slack[2] * z
            )
            if likely != want_likely:
                continue
            a_x, b_y = x / z, y / z
            rotation = rotations[k]
            for axis in range(3):
                out_rays[emitted, axis] = positions[k, axis]
                out_rays[emitted, 3 + axis] = (
                    a_x * rotation[axis, 0] + b_y * rotation[axis, 1] + rotation[axis, 2]
                )
            out_vertex[emitted] = i
            out_z[emitted] = z
            emitted += 1
            count += 1
            if count == per_vertex:
                break
        cursor[i] = j - start
    return emitted


@numba.njit(cache=True, nogil=True)
def frustum_members(
    points: np.ndarray,
    seen: np.ndarray,
    first_pose: np.ndarray,
    pose: int,
    blocks: np.ndarray,
    vertex_start: np.ndarray,
    rotation: np.ndarray,
    position: np.ndarray,
    intrinsics: np.ndarray,
    out_vertex: np.ndarray,
    out_z: np.ndarray,
    out_pixel: np.ndarray,
) -> int:
    """Unseen vertices of the given blocks inside the frustum of pose number ``pose`` (one
    whose ``first_pose`` is above it has tried it before and is skipped); vertices are sorted
    by block, block ``b`` holding ``vertex_start[b]:vertex_start[b + 1]``. Returns their
    count and writes their index, z-depth and pixel (u, v)."""
    found = 0
    for b in blocks:
        for i in range(vertex_start[b], vertex_start[b + 1]):
            if seen[i] or first_pose[i] > pose:
                continue
            x, y, z = _camera_point(points[i], rotation, position)
            u, v, inside = _pixel(x, y, z, intrinsics)
            if inside:
                out_vertex[found] = i
                out_z[found] = z
                out_pixel[found, 0] = u
                out_pixel[found, 1] = v
                found += 1
    return found


@numba.njit(cache=True, nogil=True)
def build_position_table(keys: np.ndarray, bits: int) -> np.ndarray:
    """Open-addressing table (``2**bits`` slots, -1 empty) of vertex indices by ``keys``,
    slotted by the keys' top bits."""
    table = np.full(1 << bits, -1, dtype=np.int64)
    mask = np.int64((1 << bits) - 1)
    shift = np.uint64(64 - bits)
    for i in range(keys.shape[0]):
        slot = np.int64(keys[i] >> shift)
        while table[slot] != -1:
            slot = (slot + 1) & mask
        table[slot] = i
    return table


@numba.njit(cache=True, nogil=True)
def find_positions(
    table: np.ndarray,
    bits: int,
    known: np.ndarray,
    known_keys: np.ndarray,
    points: np.ndarray,
    keys: np.ndarray,
    match: np.ndarray,
) -> None:
    """``match[j]``: index of a ``known`` vertex at exactly ``points[j]``, or -1."""
    mask = np.int64((1 << bits) - 1)
    shift = np.uint64(64 - bits)
    for j in range(points.shape[0]):
        match[j] = -1
        slot = np.int64(keys[j] >> shift)
        while table[slot] != -1:
            i = table[slot]
            if (
                known_keys[i] == keys[j]
                and known[i, 0] == points[j, 0]
                and known[i, 1] == points[j, 1]
                and known[i, 2] == points[j, 2]
            ):
                match[j] = i
                break
            slot = (slot + 1) & mask
