"""Compiled loops of the observable-surface test (:mod:`naruto_gym.observability`).

A point is observable when the segment from some viewpoint to it (stopped ``tolerance_m``
short of it) meets no surface. Most points of a scene are either seen from one of the first
viewpoints or seen from none (the outer faces of walls, the underside of the floor, the
bottoms of furniture), and the latter would cost one ray per viewpoint. Every blocked ray
names the triangle that blocked it; the same triangle usually blocks the point from many other
viewpoints too (the wall right in front of an outer face blocks it from everywhere inside).
So each point remembers the last few triangles that blocked it, and a viewpoint whose segment
provably crosses one of them well inside (an exact segment-triangle test with margins) needs
no ray. Only the viewpoints no remembered triangle certifies are ray-cast, one per point per
round, so what a cast teaches serves the point's next viewpoint at once.

The decision for every (point, viewpoint) pair is the ray cast's, as in the per-viewpoint
loop: a certificate only skips pairs whose segment crosses a triangle by a margin far above
float32 rounding, and a cast whose hit lies within ``AMBIGUOUS_M`` of the tolerance is cast
again exactly as the per-viewpoint loop does.
"""

from __future__ import annotations

import numba
import numpy as np

# Certificates need the crossing this far inside the triangle (barycentric) and the segment.
CERTIFICATE_MARGIN = 1e-5
# A reverse cast's hit closer than this to the tolerance's end is re-decided by a forward cast.
AMBIGUOUS_M = 1e-4


@numba.njit(cache=True, nogil=True, inline="always")
def segment_crosses_triangle(
    ox: float, oy: float, oz: float, dx: float, dy: float, dz: float,
    triangles: np.ndarray, face: int, margin: float,
) -> bool:
    """Whether the segment o + t d, t in [0, 1], crosses triangle ``face`` of ``triangles``
    ((F, 3, 3) float64 corners) with t and both barycentrics at least ``margin`` inside
    (Moller-Trumbore in float64)."""
    corner = triangles[face]
    ax, ay, az = corner[0, 0], corner[0, 1], corner[0, 2]
    e1x, e1y, e1z = corner[1, 0] - ax, corner[1, 1] - ay, corner[1, 2] - az
    e2x, e2y, e2z = corner[2, 0] - ax, corner[2, 1] - ay, corner[2, 2] - az
    px, py, pz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    if abs(det) < 1e-14:
        return False
    inverse = 1.0 / det
    sx, sy, sz = ox - ax, oy - ay, oz - az
    u = (sx * px + sy * py + sz * pz) * inverse
    if u < margin or u > 1.0 - margin:
        return False
    qx, qy, qz = sy * e1z - sz * e1y, sz * e1x - sx * e1z, sx * e1y - sy * e1x
    v = (dx * qx + dy * qy + dz * qz) * inverse
    if v < margin or u + v > 1.0 - margin:
        return False
    t = (e2x * qx + e2y * qy + e2z * qz) * inverse
    return margin < t < 1.0 - margin


@numba.njit(cache=True, nogil=True)
def emit_rays(
    points: np.ndarray,
    pending: np.ndarray,
    pending_count: int,
    viewpoints: np.ndarray,
    tolerance_m: float,
    max_range_m: float,
    triangles: np.ndarray,
    blockers: np.ndarray,
    cursor: np.ndarray,
    forward: np.ndarray,
    visible: np.ndarray,
    rays: np.ndarray,
    ray_point: np.ndarray,
    ray_reach: np.ndarray,
) -> tuple[int, int]:
    """One round: per pending point, skip the viewpoints a remembered blocker certifies and
    write one ray for the first viewpoint it does not.

    Args:
        points: (N, 3) float64 points.
        pending: (>= pending_count,) int indices of the points still undecided; compacted in
            place to those that got a ray.
        viewpoints: (V, 3) float64.
        triangles: (F, 3, 3) float64 triangle corners.
        blockers: (N, K) int32 remembered blocking triangles per point (-1: none), most
            recent first.
        cursor: (N,) int64 next viewpoint of each point.
        forward: (N,) bool, the point's next ray is cast forward from the viewpoint (the
            per-viewpoint loop's exact ray) instead of back from the point.
        visible: (N,) bool result.
        rays: (N, 6) float32 ray buffer; ray_point, ray_reach: its point and the distance
            from the viewpoint at which the segment stops.

    Returns:
        rays written, points still pending.
    """
    slots = blockers.shape[1]
    count = 0
    kept = 0
    for j in range(pending_count):
        i = pending[j]
        if visible[i]:
            continue
        c = cursor[i]
        while c < viewpoints.shape[0]:
            vx, vy, vz = viewpoints[c, 0], viewpoints[c, 1], viewpoints[c, 2]
            # The same float64 arithmetic as the per-viewpoint loop (same float32 rays).
            dx, dy, dz = points[i, 0] - vx, points[i, 1] - vy, points[i, 2] - vz
            distance = np.sqrt(dx * dx + dy * dy + dz * dz)
            if distance <= 1e-6 or distance > max_range_m:
                c += 1
                continue
            ux, uy, uz = dx / distance, dy / distance, dz / distance
            reach = distance - tolerance_m
            certified = False
            for k in range(slots):
                face = blockers[i, k]
                if face < 0:
                    break
                if segment_crosses_triangle(
                    vx, vy, vz, ux * reach, uy * reach, uz * reach, triangles, face,
                    CERTIFICATE_MARGIN,
                ):
                    certified = True
                    for m in range(k, 0, -1):  # most useful blocker first
                        blockers[i, m] = blockers[i, m - 1]
                    blockers[i, 0] = face
                    break
            if certified:
                c += 1
                continue
            if forward[i]:
                rays[count, 0], rays[count, 1], rays[count, 2] = vx, vy, vz
                rays[count, 3], rays[count, 4], rays[count, 5] = ux, uy, uz
            else:
                # Back from just past the segment's end: the first hit is the blocker nearest
                # the point, the one most likely to block it from other viewpoints too.
                length = reach + AMBIGUOUS_M
                rays[count, 0] = vx + ux * length
                rays[count, 1] = vy + uy * length
                rays[count, 2] = vz + uz * length
                rays[count, 3], rays[count, 4], rays[count, 5] = (
                    -ux * length, -uy * length, -uz * length
                )
            ray_point[count] = i
            ray_reach[count] = reach
            count += 1
            pending[kept] = i
            kept += 1
            break
        cursor[i] = c
    return count, kept


@numba.njit(cache=True, nogil=True)
def absorb_hits(
    ray_point: np.ndarray,
    ray_reach: np.ndarray,
    count: int,
    distance: np.ndarray,
    triangle_ids: np.ndarray,
    blockers: np.ndarray,
    cursor: np.ndarray,
    forward: np.ndarray,
    visible: np.ndarray,
) -> None:
    """Decide the pairs of one round from their casts (see :func:`emit_rays`)."""
    slots = blockers.shape[1]
    for j in range(count):
        i = ray_point[j]
        reach = ray_reach[j]
        if forward[i]:
            # The per-viewpoint loop's own test.
            forward[i] = False
            if distance[j] >= reach:
                visible[i] = True
                continue
        else:
            if distance[j] >= 1.0:
                visible[i] = True
                continue
            from_viewpoint = (1.0 - distance[j]) * (reach + AMBIGUOUS_M)
            if from_viewpoint > reach - AMBIGUOUS_M:
                forward[i] = True  # too close to the tolerance to tell: cast it forward
                continue
        cursor[i] += 1
        for m in range(slots - 1, 0, -1):
            blockers[i, m] = blockers[i, m - 1]
        blockers[i, 0] = triangle_ids[j]
