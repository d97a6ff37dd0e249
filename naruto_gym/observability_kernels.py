"""Compiled loops of the observable-surface test (:mod:`naruto_gym.observability`).

A point is observable when the segment from some viewpoint to it (stopped ``tolerance_m``
short of it) meets no surface. Most points of a scene are either seen from one of the first
viewpoints or seen from none (the outer faces of walls, the underside of the floor, the
bottoms of furniture), and the latter would cost one ray per viewpoint. Every blocked ray
names the triangle that blocked it; the same triangle usually blocks the point from many other
viewpoints too (the wall right in front of an outer face blocks it from everywhere inside).
So each point remembers the last few triangles that blocked it, and a viewpoint whose segment
provably crosses one of them well inside (an exact segment-triangle test with margins) needs
no ray. The front blocker's shadow cone from the point is precomputed, so most viewpoints
are answered in a few products; a ball of neighbouring viewpoints inside the cone is skipped
whole. Only the viewpoints no remembered triangle certifies are ray-cast,
one per point per round, so what a cast teaches serves the point's next viewpoint at once.

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
# Ball certificates: distance kept from the triangle's plane, angle kept from the cone's sides.
BALL_MARGIN_M = 1e-4
BALL_MARGIN_RAD = 1e-3
# Remembered blockers tried on a whole ball of viewpoints before testing them one by one.
BALL_BLOCKERS = 1
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


@numba.njit(cache=True, nogil=True, inline="always")
def _edge_side_plane(
    px: float, py: float, pz: float, triangles: np.ndarray, face: int, edge: int
) -> tuple[float, float, float, float]:
    """The plane through p and edge ``edge`` of triangle ``face``: its normal (not unit),
    turned towards the triangle's third corner, and the normal's squared length."""
    a = triangles[face, edge]
    b = triangles[face, (edge + 1) % 3]
    c = triangles[face, (edge + 2) % 3]
    ax, ay, az = a[0] - px, a[1] - py, a[2] - pz
    bx, by, bz = b[0] - px, b[1] - py, b[2] - pz
    mx, my, mz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    squared = mx * mx + my * my + mz * mz
    if mx * (c[0] - px) + my * (c[1] - py) + mz * (c[2] - pz) < 0.0:
        mx, my, mz = -mx, -my, -mz
    return mx, my, mz, squared


@numba.njit(cache=True, nogil=True, inline="always")
def shadow_holds_ball(
    px: float, py: float, pz: float,
    triangles: np.ndarray, plane_normals: np.ndarray, plane_offsets: np.ndarray, face: int,
    cx: float, cy: float, cz: float, radius: float, tolerance_m: float,
) -> bool:
    """Whether triangle ``face`` hides point p from every point of the ball (c, radius):
    the ball lies beyond the triangle's plane and inside the cone from p through the
    triangle, with margins (``BALL_MARGIN_M`` off the plane, an angle of ``BALL_MARGIN_RAD``
    off the cone's sides), and p lies farther than ``tolerance_m`` from the plane. Every
    segment from the ball to p then crosses the triangle well inside it and more than the
    tolerance before p."""
    nx, ny, nz = plane_normals[face, 0], plane_normals[face, 1], plane_normals[face, 2]
    height = nx * px + ny * py + nz * pz - plane_offsets[face]
    if abs(height) < tolerance_m + BALL_MARGIN_M:
        return False
    beyond = nx * cx + ny * cy + nz * cz - plane_offsets[face]
    if (beyond if height < 0.0 else -beyond) < radius + BALL_MARGIN_M:
        return False
    sx, sy, sz = cx - px, cy - py, cz - pz
    reach = np.sqrt(sx * sx + sy * sy + sz * sz)
    for edge in range(3):
        mx, my, mz, squared = _edge_side_plane(px, py, pz, triangles, face, edge)
        norm = np.sqrt(squared)
        if norm < 1e-12:
            return False
        if (mx * sx + my * sy + mz * sz) / norm < radius + BALL_MARGIN_RAD * reach:
            return False
    return True


@numba.njit(cache=True, nogil=True, inline="always")
def shadow_cone(
    px: float, py: float, pz: float,
    triangles: np.ndarray, plane_normals: np.ndarray, plane_offsets: np.ndarray, face: int,
    tolerance_m: float, cone: np.ndarray,
) -> bool:
    """The shadow of triangle ``face`` seen from p, for :func:`cone_hides`, into ``cone``
    ((4, 4) float64): row 0 the triangle's plane (normal, offset) turned so that p lies on
    its negative side, rows 1-3 the side planes through p and each edge (normal towards the
    triangle, squared norm). False when p lies within the tolerance (plus margin) of the
    plane: then nothing is certified."""
    nx, ny, nz = plane_normals[face, 0], plane_normals[face, 1], plane_normals[face, 2]
    offset = plane_offsets[face]
    height = nx * px + ny * py + nz * pz - offset
    if abs(height) < tolerance_m + BALL_MARGIN_M:
        return False
    if height > 0.0:
        nx, ny, nz, offset = -nx, -ny, -nz, -offset
    cone[0, 0], cone[0, 1], cone[0, 2], cone[0, 3] = nx, ny, nz, offset
    for edge in range(3):
        mx, my, mz, squared = _edge_side_plane(px, py, pz, triangles, face, edge)
        if squared < 1e-24:
            return False
        cone[edge + 1, 0], cone[edge + 1, 1], cone[edge + 1, 2] = mx, my, mz
        cone[edge + 1, 3] = squared
    return True


@numba.njit(cache=True, nogil=True, inline="always")
def cone_hides(
    cone: np.ndarray, px: float, py: float, pz: float, vx: float, vy: float, vz: float
) -> bool:
    """Whether the shadow ``cone`` (:func:`shadow_cone`) hides p from viewpoint v: v lies
    ``BALL_MARGIN_M`` beyond the triangle's plane and ``BALL_MARGIN_RAD`` inside the cone's
    sides (:func:`shadow_holds_ball` for a ball of radius 0, without a square root)."""
    if cone[0, 0] * vx + cone[0, 1] * vy + cone[0, 2] * vz - cone[0, 3] < BALL_MARGIN_M:
        return False
    wx, wy, wz = vx - px, vy - py, vz - pz
    limit = BALL_MARGIN_RAD * BALL_MARGIN_RAD * (wx * wx + wy * wy + wz * wz)
    for side in range(1, 4):
        along = cone[side, 0] * wx + cone[side, 1] * wy + cone[side, 2] * wz
        if along <= 0.0 or along * along < limit * cone[side, 3]:
            return False
    return True


@numba.njit(cache=True, nogil=True)
def emit_rays(
    points: np.ndarray,
    pending: np.ndarray,
    pending_count: int,
    viewpoints: np.ndarray,
    tolerance_m: float,
    max_range_m: float,
    triangles: np.ndarray,
    plane_normals: np.ndarray,
    plane_offsets: np.ndarray,
    ball_of: np.ndarray,
    ball_end: np.ndarray,
    balls: np.ndarray,
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
        viewpoints: (V, 3) float64, grouped into balls of neighbours.
        triangles: (F, 3, 3) float64 triangle corners; plane_normals (F, 3) and
            plane_offsets (F,) their planes (unit normal n, n . x = offset).
        ball_of: (V,) the ball of each viewpoint; ball_end: (B,) one past its last viewpoint;
            balls: (B, 4) centre and radius (viewpoints of a ball are consecutive).
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
    cone = np.empty((4, 4))
    for j in range(pending_count):
        i = pending[j]
        if visible[i]:
            continue
        c = cursor[i]
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        cone_face = -1  # the front blocker whose shadow ``cone`` holds, -1 for none
        cone_usable = False
        while c < viewpoints.shape[0]:
            ball = ball_of[c]
            if c == 0 or ball_of[c - 1] != ball:
                # At a ball's first viewpoint: one remembered blocker may hide the whole ball.
                hidden = False
                for k in range(min(slots, BALL_BLOCKERS)):
                    face = blockers[i, k]
                    if face < 0:
                        break
                    if shadow_holds_ball(
                        px, py, pz, triangles, plane_normals, plane_offsets, face,
                        balls[ball, 0], balls[ball, 1], balls[ball, 2], balls[ball, 3],
                        tolerance_m,
                    ):
                        hidden = True
                        break
                if hidden:
                    c = ball_end[ball]
                    continue
            vx, vy, vz = viewpoints[c, 0], viewpoints[c, 1], viewpoints[c, 2]
            # The front blocker's shadow, precomputed once per point and blocker, answers most
            # viewpoints in a few products.
            front = blockers[i, 0]
            if front >= 0:
                if front != cone_face:
                    cone_face = front
                    cone_usable = shadow_cone(
                        px, py, pz, triangles, plane_normals, plane_offsets, front,
                        tolerance_m, cone,
                    )
                if cone_usable and cone_hides(cone, px, py, pz, vx, vy, vz):
                    c += 1
                    continue
            # The same float64 arithmetic as the per-viewpoint loop (same float32 rays).
            dx, dy, dz = px - vx, py - vy, pz - vz
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
