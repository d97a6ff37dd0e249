"""Pinhole frames by rasterizing: the same per-pixel hits as the ray cast, without casting rays.

For a pinhole camera every pixel ray starts at the camera centre, so whether the ray of pixel
(u, v) crosses a triangle is decided by three planes through the centre and the triangle's
edges: with camera-frame corners ``p0, p1, p2`` and the pixel ray ``d = ((u - cx) / fx,
(v - cy) / fy, 1)``, the ray hits the triangle in front of the camera exactly when the three
triple products ``d . (p1 x p2)``, ``d . (p2 x p0)``, ``d . (p0 x p1)`` share the sign of
``det = p0 . ((p1 - p0) x (p2 - p0))``. Their shares of the sum are the hit's barycentric
coordinates, and ``det / (d . n)`` with ``n = (p1 - p0) x (p2 - p0)`` its z-depth: the ray
parameter of the exact pixel ray, as the ray caster reports it. Nothing is interpolated in screen
space, so triangles that cross the camera plane need no geometric clipping (points behind the
camera fail the sign test), and the depth is that of the ray-plane intersection in float64.

A frame is made in these passes:

0. culling (small frames, drawn in one thread): triangles are grouped in clusters of
   ``CLUSTER_FACES`` neighbours (Z-order of their centroids, :func:`triangle_clusters`) with a
   bounding sphere each, and a cluster whose sphere lies wholly
   outside a side of the view volume is skipped, vertices and triangles: every corner of its
   triangles would get that side's outcode bit, so the frame is the same (only a share of
   a room is in view of a 90-degree camera, and the passes below cost per vertex and per
   triangle); within a cluster seen, each group of ``SUBCLUSTER_FACES`` is tested alike
   before its triangles are set up (64 x 64 frames of generated rooms 1.1x faster);
1. vertices (split between the threads; small frames: all of them in vectorized loops, or
   those of the clusters in view one at a time when they are under a quarter): the
   camera-frame position, the image position and an outcode per vertex, one bit per side of
   the view volume it lies outside of;
2. setup (triangles split between the threads): triangles whose corners share an outcode bit
   (behind the camera, outside the image, entirely beyond the depth range) are dropped, and
   so are back faces of closed solids the camera is outside of (:func:`closed_solids`: a
   front face of the same solid is always nearer); the others take their corners' camera-frame
   positions (float64) from pass 1 and from them get their edge planes,
   inverse-depth plane and barycentric planes, all in pixel units, and the image rows they
   can cover (corners clipped to ``z >= NEAR_PLANE_M`` and projected), packed into a list;
3. binning: which packed triangles touch each band of ``BAND_ROWS`` image rows (a small
   frame drawn in one thread is one band, ``SINGLE_BAND_MAX_BYTES``);
4. drawing (bands dealt out to the threads in turn): per row of a triangle, the span of
   columns where all three edge planes are non-negative (a bound per edge, from its plane),
   each pixel of it kept when its inverse depth beats the band's z-buffer; then, per pixel of
   the band, the winner's z-depth (as float32, with the range cut), triangle id and
   barycentric (u, v), or depth 0 and id -1.

The kernels release the GIL and run in a small pool of Python threads, not numba's threading
layer, which would have to coexist with torch's and with spawned env workers. Triangles share
edge planes exactly (the cross product of two corners only changes sign when they swap), so a
ray through a shared edge is claimed by both neighbours and the image has no cracks; which of
the two wins such an exact tie can differ from Embree.
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse
import scipy.sparse.csgraph

from naruto_gym.utils.threads import default_thread_count, run_parallel

# Hits closer to the camera centre than this (metres) are not drawn; the ray cast starts at 0.
NEAR_PLANE_M = 1e-6

# Layout of the float64 triangle records made by the setup pass, every plane in pixel units
# (a * u + b * v + c): the three edge planes (times the sign of det), the inverse-depth plane
# 1 / z, and the reciprocal of each edge plane's u slope (0 where that would overflow).
_INVERSE_DEPTH = 9
_INVERSE_SLOPES = 12
_RECORD_FLOATS = 15

# Slack (pixels) on a triangle's projected bounding box before it is found to hold no pixel.
_BOX_MARGIN_PX = 1e-6

# Image rows drawn together: a band's z-buffer (16 x 1200 x 12 bytes) stays in the L2 cache.
BAND_ROWS = 16

# Frames drawn in one thread (render_frames) whose whole z-buffer takes at most this many bytes
# are drawn as one band: no triangle is read once per band (64 x 64 frames 1.03x, 128 x 128
# 1.07x faster than in bands of 16 rows).
SINGLE_BAND_MAX_BYTES = 256 * 1024

# Neighbouring triangles culled together against the view volume (pass 0), then in groups of
# SUBCLUSTER_FACES within the clusters seen: a quarter of a cluster is culled more often.
CLUSTER_FACES = 64
SUBCLUSTER_FACES = 16

# A cluster is culled only when its sphere lies this much (relative, plus 1 um) outside a
# side: the vertices' own outcodes are computed another way, and rounding must not cull a
# triangle they would keep.
_CULL_SLACK = 1e-6


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _store_plane(records, slot, offset, x, y, z, inverse_fx, inverse_fy, cx, cy):
    """Store the plane x * X + y * Y + z (X = (u - cx) / fx, Y = (v - cy) / fy) in pixel units.

    Negating (x, y, z) negates the stored plane exactly, which keeps shared edges watertight.
    """
    a = x * inverse_fx
    b = y * inverse_fy
    records[slot, offset] = a
    records[slot, offset + 1] = b
    records[slot, offset + 2] = z - a * cx - b * cy


@numba.njit(cache=True, nogil=True, error_model="numpy")
def vertex_outcodes(
    columns: np.ndarray,
    first: int,
    stop: int,
    rotation: np.ndarray,
    origin: np.ndarray,
    intrinsics: np.ndarray,
    width: int,
    height: int,
    far_cut: float,
    outcodes: np.ndarray,
    projections: np.ndarray,
) -> None:
    """View-volume outcodes, image and camera-frame positions of vertices ``first .. stop - 1``.

    In loops over the columns that the compiler vectorizes: a few times faster per vertex than
    one at a time, which a range of one vertex gives.

    Args:
        columns: (3, V) float32 world positions, a row per axis.
        first, stop: the range of vertices.
        rotation: (3, 3) float64 camera-to-world rotation; origin: (3,) float64 camera centre.
        intrinsics: float64 (fx, fy, cx, cy).
        width, height: image size in pixels.
        far_cut: the farthest z worth drawing.
        outcodes: (V,) uint8 output, one bit per side of the view volume the vertex lies
            outside of (left, right, top, bottom of the image with a pixel of margin, near
            plane, far cut). A triangle whose three corners share a bit cannot be seen.
        projections: (5, V) float64 output: the pixel u and v of each vertex in front of the
            near plane (anything for the others), then its camera-frame x, y, z.
    """
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    r00, r01, r02 = rotation[0, 0], rotation[0, 1], rotation[0, 2]
    r10, r11, r12 = rotation[1, 0], rotation[1, 1], rotation[1, 2]
    r20, r21, r22 = rotation[2, 0], rotation[2, 1], rotation[2, 2]
    ox, oy, oz = origin[0], origin[1], origin[2]
    for index in range(first, stop):
        dx = np.float64(columns[0, index]) - ox
        dy = np.float64(columns[1, index]) - oy
        dz = np.float64(columns[2, index]) - oz
        projections[2, index] = r00 * dx + r10 * dy + r20 * dz
        projections[3, index] = r01 * dx + r11 * dy + r21 * dz
        projections[4, index] = r02 * dx + r12 * dy + r22 * dz
    for index in range(first, stop):
        x, y, z = projections[2, index], projections[3, index], projections[4, index]
        scale = 1.0 / max(z, NEAR_PLANE_M)
        projections[0, index] = fx * x * scale + cx
        projections[1, index] = fy * y * scale + cy
    for index in range(first, stop):
        x, y, z = projections[2, index], projections[3, index], projections[4, index]
        # Planes through the camera centre bounding u in [-1, width], v in [-1, height]; their
        # intersection lies in front of the camera, so sharing a bit means unseen.
        outcodes[index] = (
            (fx * x + (cx + 1.0) * z < 0.0) * 1
            + ((width - cx) * z - fx * x < 0.0) * 2
            + (fy * y + (cy + 1.0) * z < 0.0) * 4
            + ((height - cy) * z - fy * y < 0.0) * 8
            + (z < NEAR_PLANE_M) * 16
            + (z > far_cut) * 32
        )


def morton_order(points: np.ndarray, bits: int = 10) -> np.ndarray:
    """Indices that sort (N, 3) points along a Z-order curve over their bounding box
    (``bits`` per axis): points close in the order lie close in space."""
    points = np.asarray(points, np.float64)
    low, high = points.min(axis=0), points.max(axis=0)
    scale = (2**bits - 1) / np.maximum(high - low, 1e-12)
    cells = np.clip(np.rint((points - low) * scale), 0, 2**bits - 1).astype(np.int64)
    codes = np.zeros(len(points), np.int64)
    for bit in range(bits):
        for axis in range(3):
            codes |= ((cells[:, axis] >> bit) & 1) << (3 * bit + axis)
    return np.argsort(codes, kind="stable")


def triangle_clusters(
    vertices: np.ndarray, faces: np.ndarray, size: int = CLUSTER_FACES
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Triangles in clusters of ``size`` neighbours (Z-order of their centroids), with a
    bounding sphere and the distinct vertices of each.

    Args:
        vertices: (V, 3) positions; faces: (F, 3) corner indices.
        size: triangles per cluster (the last may hold fewer).

    Returns:
        ``order`` ((F,) int32: cluster ``c`` holds triangles
        ``order[c * size:(c + 1) * size]``), ``spheres`` ((C, 4) float64: centre, radius),
        ``vertex_starts`` ((C + 1,) int64) and ``vertex_list`` (int32): cluster ``c`` uses
        the vertices ``vertex_list[vertex_starts[c]:vertex_starts[c + 1]]``.
    """
    points = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    order = morton_order(points[faces].mean(axis=1)).astype(np.int32)
    count = -(-len(faces) // size)
    # The distinct corners of each cluster, in vertex order: (cluster, vertex) pairs made
    # distinct in one pass (a scene streamed per episode builds these at its first frame).
    clusters_of_corners = np.repeat(np.arange(len(faces)) // size, 3)
    pairs = np.unique(clusters_of_corners * len(points) + faces[order].reshape(-1))
    cluster_of, used = np.divmod(pairs, len(points))
    starts = np.searchsorted(cluster_of, np.arange(count + 1)).astype(np.int64)
    return order, box_spheres(points[used], starts[:-1]), starts, used.astype(np.int32)


def box_spheres(points: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """(G, 4) float64 bounding spheres (centre, radius) of consecutive groups of (N, 3)
    ``points``, group ``g`` starting at ``starts[g]``, each centred on its points' box."""
    centres = 0.5 * (np.minimum.reduceat(points, starts) + np.maximum.reduceat(points, starts))
    reach = ((points - np.repeat(centres, np.diff(np.r_[starts, len(points)]), axis=0)) ** 2).sum(
        axis=1
    )
    spheres = np.empty((len(starts), 4))
    spheres[:, :3] = centres
    spheres[:, 3] = np.sqrt(np.maximum.reduceat(reach, starts))
    return spheres


def group_spheres(vertices: np.ndarray, faces: np.ndarray, size: int) -> np.ndarray:
    """(G, 4) float64 bounding spheres of the consecutive groups of ``size`` triangles of
    ``faces`` (the last may hold fewer), centred on their corners' box (:func:`box_spheres`)."""
    corners = np.asarray(vertices, np.float64)[np.asarray(faces)].reshape(-1, 3)
    return box_spheres(corners, np.arange(0, len(corners), 3 * size))


def closed_solids(
    vertices: np.ndarray, faces: np.ndarray, margin_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """The parts of a mesh that bound solids, whose back faces a camera outside them never sees.

    A part (triangles joined through the edges no third triangle uses) bounds a solid when it
    is closed and consistently oriented, every edge used by exactly two of its triangles in
    opposite directions, and encloses a positive volume (normals by the right-hand rule point
    out). A ray from a camera outside such a solid enters it through a front face before it
    can leave through a back face, so the back face never wins a pixel and need not be drawn.
    A camera inside (or closer than ``margin_m`` to the solid's box) draws every face. As parts
    join only through edges used twice in the whole mesh, two boxes touching along an edge
    stay two solids. Open parts (scans), parts with an edge used once or more than twice in
    them, and inside-out or flat parts are left out: they are always drawn whole. A closed
    part that passes through itself is assumed not to turn inside out anywhere (primitives and
    furniture models do not; scans are open).

    Args:
        vertices: (V, 3) positions; faces: (F, 3) corner indices.
        margin_m: how far outside a solid's bounding box a camera must be for its back faces
            to be dropped.

    Returns:
        ``face_solids`` ((F,) int32: the solid of each face, -1 for none) and ``boxes``
        ((S, 6) float64: each solid's bounding box grown by ``margin_m``, min then max corner).
    """
    points = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    count = len(faces)
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    keys = directed.min(axis=1) * len(points) + directed.max(axis=1)
    order = np.argsort(keys)
    sorted_keys = keys[order]
    shared = sorted_keys[1:] == sorted_keys[:-1]  # consecutive uses of one edge
    edge_of = np.empty(len(keys), np.int64)
    edge_of[order] = np.cumsum(np.r_[True, ~shared]) - 1
    forward = directed[:, 0] < directed[:, 1]
    uses = np.bincount(edge_of)
    manifold = (uses == 2) & (np.bincount(edge_of, weights=forward) == 1)
    # Triangles joined through the edges used twice, once each way (two boxes touching along
    # an edge stay two parts).
    face_of = np.repeat(np.arange(count), 3)
    joins = shared & manifold[edge_of[order[1:]]]
    first, second = face_of[order[:-1]][joins], face_of[order[1:]][joins]
    graph = scipy.sparse.coo_matrix((np.ones(len(first)), (first, second)), shape=(count, count))
    parts, label = scipy.sparse.csgraph.connected_components(graph, directed=False)
    # A part is closed when each of its edges is used twice in it, once each way.
    part_edges, part_edge_of = np.unique(
        label[face_of] * len(uses) + edge_of, return_inverse=True
    )
    part_edge_of = part_edge_of.reshape(-1)
    closed_edge = (np.bincount(part_edge_of) == 2) & (
        np.bincount(part_edge_of, weights=forward) == 1
    )
    spoiled = np.zeros(parts, bool)
    spoiled[part_edges[~closed_edge] // len(uses)] = True
    corners = points[faces]
    volume = np.bincount(label, minlength=parts, weights=np.einsum(
        "ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])) / 6.0)
    candidates = np.flatnonzero(~spoiled & (volume > 0.0))
    # Bounding boxes of the candidates only (a scan has many open fragments and few solids).
    members = np.flatnonzero(np.isin(label, candidates))
    by_part = members[np.argsort(label[members], kind="stable")]
    starts = np.flatnonzero(np.r_[True, np.diff(label[by_part]) != 0])
    low = np.minimum.reduceat(corners[by_part].min(axis=1), starts) if len(by_part) else (
        np.empty((0, 3)))
    high = np.maximum.reduceat(corners[by_part].max(axis=1), starts) if len(by_part) else (
        np.empty((0, 3)))
    # Flat parts (two coincident sheets, zero volume up to rounding) have no inside.
    solid = volume[candidates] > 1e-9 * np.linalg.norm(high - low, axis=1) ** 3
    index = np.full(parts, -1, np.int32)
    index[candidates[solid]] = np.arange(int(solid.sum()), dtype=np.int32)
    boxes = np.concatenate([low[solid] - margin_m, high[solid] + margin_m], axis=1)
    return index[label], np.ascontiguousarray(boxes)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def view_side_planes(intrinsics: np.ndarray, width: int, height: int) -> np.ndarray:
    """(4, 2) float64 unit normals, pointing into the view volume, of its left, right, top
    and bottom sides (the outcode planes of :func:`vertex_outcodes`), each as the (x or y, z)
    coefficients of a camera-frame point's signed distance (x for the first two)."""
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    sides = np.array([
        [fx, cx + 1.0], [-fx, width - cx], [fy, cy + 1.0], [-fy, height - cy],
    ])
    for side in range(4):
        norm = np.sqrt(sides[side, 0] ** 2 + sides[side, 1] ** 2)
        sides[side, 0] /= norm
        sides[side, 1] /= norm
    return sides


@numba.njit(cache=True, nogil=True, error_model="numpy")
def cluster_may_be_seen(
    spheres: np.ndarray, cluster: int, rotation: np.ndarray, origin: np.ndarray,
    intrinsics: np.ndarray, width: int, height: int, far_cut: float,
) -> bool:
    """False when the cluster's bounding sphere lies wholly outside one side of the view
    volume (the outcode planes of :func:`vertex_outcodes`): every corner of its triangles
    then has that side's bit, and the setup pass would drop every one of them."""
    return sphere_may_be_seen(
        spheres, cluster, rotation, origin, view_side_planes(intrinsics, width, height),
        far_cut,
    )


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def sphere_may_be_seen(
    spheres: np.ndarray, cluster: int, rotation: np.ndarray, origin: np.ndarray,
    sides: np.ndarray, far_cut: float,
) -> bool:
    """:func:`cluster_may_be_seen` with the frame's :func:`view_side_planes` given."""
    dx = spheres[cluster, 0] - origin[0]
    dy = spheres[cluster, 1] - origin[1]
    dz = spheres[cluster, 2] - origin[2]
    x = rotation[0, 0] * dx + rotation[1, 0] * dy + rotation[2, 0] * dz
    y = rotation[0, 1] * dx + rotation[1, 1] * dy + rotation[2, 1] * dz
    z = rotation[0, 2] * dx + rotation[1, 2] * dy + rotation[2, 2] * dz
    reach = spheres[cluster, 3] * (1.0 + _CULL_SLACK) + _CULL_SLACK
    if z + reach < NEAR_PLANE_M or z - reach > far_cut:
        return False
    # Signed distances to the side planes (unit normals pointing into the view volume).
    left = sides[0, 0] * x + sides[0, 1] * z
    right = sides[1, 0] * x + sides[1, 1] * z
    top = sides[2, 0] * y + sides[2, 1] * z
    bottom = sides[3, 0] * y + sides[3, 1] * z
    return min(min(left, right), min(top, bottom)) >= -reach


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _holds_no_pixel(u_min, u_max, v_min, v_max, width, height):
    """Whether an image box holds no pixel (pixels sit at integer (u, v)): so it is with most
    triangles of a dense mesh in a small frame. The margin covers rounding."""
    column_first = max(np.ceil(max(u_min - _BOX_MARGIN_PX, -1.0)), 0.0)
    column_last = min(np.floor(min(u_max + _BOX_MARGIN_PX, float(width))), width - 1.0)
    row_first = max(np.ceil(max(v_min - _BOX_MARGIN_PX, -1.0)), 0.0)
    row_last = min(np.floor(min(v_max + _BOX_MARGIN_PX, float(height))), height - 1.0)
    return column_first > column_last or row_first > row_last


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _clipped_box(xs, ys, zs, fx, fy, cx, cy):
    """Image bounding box (u_min, u_max, v_min, v_max) of the part of a camera-frame triangle
    in front of the near plane: its corners there and the points where edges cross it."""
    u_min, u_max, v_min, v_max = np.inf, -np.inf, np.inf, -np.inf
    for corner in range(3):
        following = (corner + 1) % 3
        if zs[corner] >= NEAR_PLANE_M:
            scale = 1.0 / zs[corner]
            u = fx * xs[corner] * scale + cx
            v = fy * ys[corner] * scale + cy
            u_min, u_max = min(u_min, u), max(u_max, u)
            v_min, v_max = min(v_min, v), max(v_max, v)
        if (zs[corner] >= NEAR_PLANE_M) != (zs[following] >= NEAR_PLANE_M):
            share = (NEAR_PLANE_M - zs[corner]) / (zs[following] - zs[corner])
            u = fx * (xs[corner] + share * (xs[following] - xs[corner])) / NEAR_PLANE_M + cx
            v = fy * (ys[corner] + share * (ys[following] - ys[corner])) / NEAR_PLANE_M + cy
            u_min, u_max = min(u_min, u), max(u_max, u)
            v_min, v_max = min(v_min, v), max(v_max, v)
    return u_min, u_max, v_min, v_max


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _outside_solid(solid: int, boxes: np.ndarray, origin: np.ndarray) -> bool:
    """Whether the camera lies outside the (grown) box of ``solid`` (-1: no solid)."""
    if solid < 0:
        return False
    return (
        origin[0] < boxes[solid, 0] or origin[1] < boxes[solid, 1]
        or origin[2] < boxes[solid, 2] or origin[0] > boxes[solid, 3]
        or origin[1] > boxes[solid, 4] or origin[2] > boxes[solid, 5]
    )


@numba.njit(cache=True, nogil=True, error_model="numpy")
def setup_triangles(
    outcodes: np.ndarray,
    projections: np.ndarray,
    faces: np.ndarray,
    ranges: np.ndarray,
    origin: np.ndarray,
    intrinsics: np.ndarray,
    width: int,
    height: int,
    records: np.ndarray,
    hit_planes: np.ndarray,
    record_rows: np.ndarray,
    slot_base: int,
    face_solids: np.ndarray,
    solid_boxes: np.ndarray,
) -> int:
    """Set up the triangles of ``ranges``; pack the drawable ones from ``records[slot_base]``.

    Args:
        outcodes, projections: :func:`vertex_outcodes`'s output (image and camera-frame
            positions of the vertices).
        faces: (F, 3) int32 corner indices.
        ranges: (R, 2) int64 ranges of triangles to set up, ``[first, stop)`` each (one call
            for a frame's many groups: every call of a compiled function with array
            arguments costs two atomic reference counts per array).
        origin: (3,) float64 camera centre.
        intrinsics: float64 (fx, fy, cx, cy).
        width, height: image size in pixels.
        records: (F, 15) float64 output, laid out as described at ``_RECORD_FLOATS``.
        hit_planes: (F, 6) float64 output: the planes of the barycentric coordinates u and v
            divided by the z-depth (u = plane(pixel) * z), in pixel units.
        record_rows: (F, 3) int64 output: triangle id, first row, last row.
        face_solids, solid_boxes: :func:`closed_solids` of the mesh (``face_solids`` in the
            order of ``faces``): a back face of a solid whose box the camera is outside of is
            dropped.

    Returns:
        The number of records written from index ``slot_base``.
    """
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    inverse_fx, inverse_fy = 1.0 / fx, 1.0 / fy
    count = 0
    for entry in range(ranges.shape[0]):
        for triangle in range(ranges[entry, 0], ranges[entry, 1]):
            i0, i1, i2 = faces[triangle, 0], faces[triangle, 1], faces[triangle, 2]
            if outcodes[i0] & outcodes[i1] & outcodes[i2]:
                continue
            crosses_near_plane = (outcodes[i0] | outcodes[i1] | outcodes[i2]) & 16
            if not crosses_near_plane:
                u_min = min(projections[0, i0], min(projections[0, i1], projections[0, i2]))
                u_max = max(projections[0, i0], max(projections[0, i1], projections[0, i2]))
                v_min = min(projections[1, i0], min(projections[1, i1], projections[1, i2]))
                v_max = max(projections[1, i0], max(projections[1, i1], projections[1, i2]))
                if _holds_no_pixel(u_min, u_max, v_min, v_max, width, height):
                    continue
            # Tuples, not arrays: views of a scratch array cost two atomic reference counts each.
            xs = (projections[2, i0], projections[2, i1], projections[2, i2])
            ys = (projections[3, i0], projections[3, i1], projections[3, i2])
            zs = (projections[4, i0], projections[4, i1], projections[4, i2])
            if crosses_near_plane:
                u_min, u_max, v_min, v_max = _clipped_box(xs, ys, zs, fx, fy, cx, cy)
                if _holds_no_pixel(u_min, u_max, v_min, v_max, width, height):
                    continue
            row_first = max(np.ceil(max(v_min - _BOX_MARGIN_PX, -1.0)), 0.0)
            row_last = min(np.floor(min(v_max + _BOX_MARGIN_PX, float(height))), height - 1.0)
            nx, ny, nz = _cross(
                xs[1] - xs[0], ys[1] - ys[0], zs[1] - zs[0],
                xs[2] - xs[0], ys[2] - ys[0], zs[2] - zs[0],
            )
            det = xs[0] * nx + ys[0] * ny + zs[0] * nz
            if det == 0.0:
                continue  # the plane passes through the camera centre: seen edge-on
            if det > 0.0 and _outside_solid(face_solids[triangle], solid_boxes, origin):
                continue  # a back face of a solid seen from outside: a front face hides it
            sign = 1.0 if det > 0.0 else -1.0
            slot = slot_base + count
            for edge in range(3):
                a, b = (edge + 1) % 3, (edge + 2) % 3
                px, py, pz = _cross(xs[a], ys[a], zs[a], xs[b], ys[b], zs[b])
                _store_plane(
                    records, slot, 3 * edge, sign * px, sign * py, sign * pz, inverse_fx,
                    inverse_fy, cx, cy,
                )
                slope = records[slot, 3 * edge]
                # 0 marks an edge plane that is constant along a row (its 1 / slope would overflow).
                records[slot, _INVERSE_SLOPES + edge] = 1.0 / slope if abs(slope) > 1e-290 else 0.0
            inverse_det = 1.0 / det
            _store_plane(
                records, slot, _INVERSE_DEPTH, nx * inverse_det, ny * inverse_det, nz * inverse_det,
                inverse_fx, inverse_fy, cx, cy,
            )
            # u = e1 / (e0 + e1 + e2) with e0 + e1 + e2 = sign * det / z, so u = e1 * z / |det|.
            scale = abs(inverse_det)
            for coefficient in range(3):
                hit_planes[slot, coefficient] = records[slot, 3 + coefficient] * scale
                hit_planes[slot, 3 + coefficient] = records[slot, 6 + coefficient] * scale
            record_rows[slot, 0] = triangle
            record_rows[slot, 1] = int(row_first)
            record_rows[slot, 2] = int(row_last)
            count += 1
    return count


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _edge_bounds(
    inverse_slope: float, offset: float, low: float, high: float
) -> tuple[float, float]:
    """Narrow [low, high] to where u / inverse_slope + offset >= 0 (empty: low > high); an
    ``inverse_slope`` of 0 means the plane is constant along the row."""
    if inverse_slope > 0.0:
        return max(low, -offset * inverse_slope), high
    if inverse_slope < 0.0:
        return low, min(high, -offset * inverse_slope)
    if offset < 0.0:
        return np.inf, -np.inf
    return low, high


@numba.njit(cache=True, nogil=True, error_model="numpy")
def bin_records(
    record_rows: np.ndarray, segments: np.ndarray, band_rows: int, band_count: int
) -> tuple[np.ndarray, np.ndarray]:
    """Which records touch which band of ``band_rows`` image rows.

    Returns:
        ``band_starts`` ((band_count + 1,) int64) and ``entries`` (int32 record indices):
        band ``b`` holds ``entries[band_starts[b]:band_starts[b + 1]]``, in record order.
    """
    band_starts = np.zeros(band_count + 1, np.int64)
    for segment in range(segments.shape[0]):
        for record in range(segments[segment, 0], segments[segment, 1]):
            for band in range(record_rows[record, 1] // band_rows,
                              record_rows[record, 2] // band_rows + 1):
                band_starts[band + 1] += 1
    for band in range(band_count):
        band_starts[band + 1] += band_starts[band]
    entries = np.empty(band_starts[band_count], np.int32)
    filled = band_starts[:band_count].copy()
    for segment in range(segments.shape[0]):
        for record in range(segments[segment, 0], segments[segment, 1]):
            for band in range(record_rows[record, 1] // band_rows,
                              record_rows[record, 2] // band_rows + 1):
                entries[filled[band]] = record
                filled[band] += 1
    return band_starts, entries


@numba.njit(cache=True, nogil=True, error_model="numpy")
def rasterize_band(
    records: np.ndarray,
    record_rows: np.ndarray,
    entries: np.ndarray,
    row_first_band: int,
    nearest: float,
    inverse_depth: np.ndarray,
    winners: np.ndarray,
) -> None:
    """Z-buffer the records ``entries`` over the band of rows starting at ``row_first_band``.

    Args:
        records, record_rows: the setup pass's output.
        entries: record indices of the triangles that touch the band.
        row_first_band: the image row of the band's first row.
        nearest: 1 / the farthest depth worth drawing (0 for no limit).
        inverse_depth: (band rows, W) float64 1 / z-depth of the nearest hit (reset here).
        winners: (band rows, W) int32 record index of the nearest hit, -1 for none (reset here).
    """
    band_height, width = inverse_depth.shape
    inverse_depth[:, :] = nearest
    winners[:, :] = -1
    row_last_band = row_first_band + band_height - 1
    for entry in range(entries.shape[0]):
        record = entries[entry]
        b0, c0 = records[record, 1], records[record, 2]
        b1, c1 = records[record, 4], records[record, 5]
        b2, c2 = records[record, 7], records[record, 8]
        qa, qb, qc = records[record, 9], records[record, 10], records[record, 11]
        i0, i1, i2 = records[record, 12], records[record, 13], records[record, 14]
        for row in range(max(record_rows[record, 1], row_first_band),
                         min(record_rows[record, 2], row_last_band) + 1):
            v = float(row)
            k0 = b0 * v + c0
            k1 = b1 * v + c1
            k2 = b2 * v + c2
            low, high = _edge_bounds(i0, k0, -np.inf, np.inf)
            low, high = _edge_bounds(i1, k1, low, high)
            low, high = _edge_bounds(i2, k2, low, high)
            # The columns with all three edge planes >= 0. Two triangles sharing an edge compute
            # its bound from exactly negated planes, so they get the same number: a pixel on
            # it goes to both (an exact tie), never to neither.
            first_column = max(int(np.ceil(max(low, -1.0))), 0)
            last_column = min(int(np.floor(min(high, float(width)))), width - 1)
            kq = qb * v + qc
            line = row - row_first_band
            for column in range(first_column, last_column + 1):
                q = qa * column + kq
                current = inverse_depth[line, column]
                # An exact tie goes to the lower triangle id, whatever the records' order
                # (culling clusters draws them in spatial order).
                if q > current or (
                    q == current and winners[line, column] >= 0
                    and record_rows[record, 0] < record_rows[winners[line, column], 0]
                ):
                    inverse_depth[line, column] = q
                    winners[line, column] = record


@numba.njit(cache=True, nogil=True, error_model="numpy")
def resolve_band(
    hit_planes: np.ndarray,
    record_rows: np.ndarray,
    row_first_band: int,
    inverse_depth: np.ndarray,
    winners: np.ndarray,
    max_depth: float,
    want_barycentrics: bool,
    barycentric_faces: np.ndarray,
    depth: np.ndarray,
    triangle_ids: np.ndarray,
    barycentric_uv: np.ndarray,
) -> None:
    """Turn a band's z-buffer into the ray caster's outputs for its rows.

    Writes ``depth`` ((H, W) float32 z-depth, 0 for no hit or beyond ``max_depth``),
    ``triangle_ids`` ((H * W,) int32, -1 where the depth is 0) and, when asked,
    ``barycentric_uv`` ((H * W, 2) float32, Embree's (u, v) of the hit) on the triangles
    ``barycentric_faces`` ((F,) uint8, by triangle id) flags, (0, 0) on the others.
    """
    band_height, width = inverse_depth.shape
    for line in range(min(band_height, depth.shape[0] - row_first_band)):
        row = row_first_band + line
        v = float(row)
        for column in range(width):
            pixel = row * width + column
            record = winners[line, column]
            z = 1.0 / inverse_depth[line, column]
            value = np.float32(z)
            if record < 0 or not value <= max_depth:
                depth[row, column] = 0.0
                triangle_ids[pixel] = -1
                if want_barycentrics:
                    barycentric_uv[pixel, 0] = 0.0
                    barycentric_uv[pixel, 1] = 0.0
                continue
            depth[row, column] = value
            triangle = record_rows[record, 0]
            triangle_ids[pixel] = triangle
            if want_barycentrics and not barycentric_faces[triangle]:
                barycentric_uv[pixel, 0] = 0.0
                barycentric_uv[pixel, 1] = 0.0
            elif want_barycentrics:
                u = float(column)
                barycentric_uv[pixel, 0] = (
                    hit_planes[record, 0] * u + hit_planes[record, 1] * v + hit_planes[record, 2]
                ) * z
                barycentric_uv[pixel, 1] = (
                    hit_planes[record, 3] * u + hit_planes[record, 4] * v + hit_planes[record, 5]
                ) * z


@numba.njit(cache=True, nogil=True, error_model="numpy")
def draw_bands(
    records: np.ndarray,
    hit_planes: np.ndarray,
    record_rows: np.ndarray,
    band_starts: np.ndarray,
    entries: np.ndarray,
    group: int,
    groups: int,
    nearest: float,
    max_depth: float,
    want_barycentrics: bool,
    barycentric_faces: np.ndarray,
    inverse_depth: np.ndarray,
    winners: np.ndarray,
    depth: np.ndarray,
    triangle_ids: np.ndarray,
    barycentric_uv: np.ndarray,
) -> None:
    """Rasterize and resolve bands ``group, group + groups, ...`` (one thread's share).

    ``inverse_depth`` and ``winners`` are this thread's band-sized z-buffer;
    ``barycentric_faces`` as for :func:`resolve_band`.
    """
    band_height = inverse_depth.shape[0]
    for band in range(group, band_starts.shape[0] - 1, groups):
        row_first_band = band * band_height
        rasterize_band(
            records, record_rows, entries[band_starts[band]:band_starts[band + 1]],
            row_first_band, nearest, inverse_depth, winners,
        )
        resolve_band(
            hit_planes, record_rows, row_first_band, inverse_depth, winners, max_depth,
            want_barycentrics, barycentric_faces, depth, triangle_ids, barycentric_uv,
        )


@numba.njit(cache=True, nogil=True, error_model="numpy")
def render_frames(
    columns: np.ndarray,
    poses: np.ndarray,
    intrinsics: np.ndarray,
    width: int,
    height: int,
    far_cut: float,
    nearest: float,
    max_depth: float,
    want_barycentrics: bool,
    barycentric_faces: np.ndarray,
    cluster_faces: np.ndarray,
    cluster_order: np.ndarray,
    spheres: np.ndarray,
    sub_spheres: np.ndarray,
    cluster_vertex_starts: np.ndarray,
    cluster_vertices: np.ndarray,
    cluster_face_solids: np.ndarray,
    solid_boxes: np.ndarray,
    scratch_outcodes: np.ndarray,
    scratch_projections: np.ndarray,
    scratch_records: np.ndarray,
    scratch_hit_planes: np.ndarray,
    scratch_record_rows: np.ndarray,
    scratch_stamps: np.ndarray,
    inverse_depth: np.ndarray,
    winners: np.ndarray,
    depth: np.ndarray,
    triangle_ids: np.ndarray,
    barycentric_uv: np.ndarray,
) -> None:
    """All passes of frames ``0 .. K - 1`` in one thread, frame after frame.

    A batch of small frames is drawn a whole frame per thread: calling the passes from Python
    once per frame costs about as much as a 64 x 64 frame's drawing.

    Args:
        columns: (3, V) float32 vertex positions, a row per axis.
        poses: (K, 4, 4) float64 camera-to-world poses (already rounded to float32).
        cluster_faces: ``faces[cluster_order]``, the triangles cluster after cluster.
        cluster_order, spheres, cluster_vertex_starts, cluster_vertices:
            :func:`triangle_clusters` of the mesh, ``CLUSTER_FACES`` triangles per cluster.
        sub_spheres: :func:`group_spheres` of ``cluster_faces``, ``SUBCLUSTER_FACES`` each.
        cluster_face_solids, solid_boxes: :func:`closed_solids` of the mesh, the solid of
            each face in cluster order.
        scratch_*: the single-frame buffers of :class:`PinholeRasterizer`;
            ``scratch_stamps``: (V + 1,) int64, the frame mark each vertex was last
            classified for, the last mark at the end.
        inverse_depth, winners: one band's z-buffer.
        depth: (K, H, W) float32; triangle_ids: (K * H * W,) int32; barycentric_uv:
            (K * H * W, 2) float32 outputs, frame after frame.
    """
    pixels = width * height
    band_rows = inverse_depth.shape[0]
    band_count = (height + band_rows - 1) // band_rows
    clusters = spheres.shape[0]
    vertex_count = columns.shape[1]
    segments = np.zeros((1, 2), np.int64)
    whole_band = np.zeros(2, np.int64)
    every_record = np.arange(cluster_faces.shape[0], dtype=np.int32)
    seen = np.empty(clusters, np.int64)
    sides = view_side_planes(intrinsics, width, height)
    group_ranges = np.empty((sub_spheres.shape[0], 2), np.int64)
    for frame in range(poses.shape[0]):
        rotation = np.ascontiguousarray(poses[frame, :3, :3])
        origin = np.ascontiguousarray(poses[frame, :3, 3])
        seen_count = 0
        corners = 0
        for cluster in range(clusters):
            if sphere_may_be_seen(spheres, cluster, rotation, origin, sides, far_cut):
                seen[seen_count] = cluster
                seen_count += 1
                corners += cluster_vertex_starts[cluster + 1] - cluster_vertex_starts[cluster]
        if 4 * corners >= vertex_count:
            # Classifying every vertex in vectorized loops costs less than a quarter of them
            # one at a time.
            vertex_outcodes(columns, 0, vertex_count, rotation, origin, intrinsics, width,
                            height, far_cut, scratch_outcodes, scratch_projections)
        else:
            # Neighbouring clusters share vertices: each is classified once per frame, when
            # its stamp is not this frame's mark (the stamps' last entry keeps the last mark).
            scratch_stamps[-1] += 1
            mark = scratch_stamps[-1]
            for rank in range(seen_count):
                cluster = seen[rank]
                for entry in range(cluster_vertex_starts[cluster],
                                   cluster_vertex_starts[cluster + 1]):
                    vertex = cluster_vertices[entry]
                    if scratch_stamps[vertex] != mark:
                        scratch_stamps[vertex] = mark
                        vertex_outcodes(columns, vertex, vertex + 1, rotation, origin,
                                        intrinsics, width, height, far_cut, scratch_outcodes,
                                        scratch_projections)
        # Records packed from slot 0 (a frame touches only as much scratch as it draws: with
        # a batched env's many scenes the scratch of each stays small in the cache).
        groups = 0
        for rank in range(seen_count):
            cluster = seen[rank]
            stop = min((cluster + 1) * CLUSTER_FACES, cluster_faces.shape[0])
            for first in range(cluster * CLUSTER_FACES, stop, SUBCLUSTER_FACES):
                if sphere_may_be_seen(sub_spheres, first // SUBCLUSTER_FACES, rotation,
                                      origin, sides, far_cut):
                    group_ranges[groups, 0] = first
                    group_ranges[groups, 1] = min(first + SUBCLUSTER_FACES, stop)
                    groups += 1
        used = setup_triangles(
            scratch_outcodes, scratch_projections, cluster_faces, group_ranges[:groups],
            origin, intrinsics, width, height, scratch_records, scratch_hit_planes,
            scratch_record_rows, 0, cluster_face_solids, solid_boxes,
        )
        for slot in range(used):  # the mesh's own triangle ids
            scratch_record_rows[slot, 0] = cluster_order[scratch_record_rows[slot, 0]]
        if band_count == 1:  # one band holds every record, in order
            whole_band[1] = used
            band_starts, entries = whole_band, every_record[:used]
        else:
            segments[0, 1] = used
            band_starts, entries = bin_records(
                scratch_record_rows, segments, band_rows, band_count
            )
        first = frame * pixels
        draw_bands(
            scratch_records, scratch_hit_planes, scratch_record_rows, band_starts, entries, 0, 1,
            nearest, max_depth, want_barycentrics, barycentric_faces, inverse_depth, winners,
            depth[frame],
            triangle_ids[first:first + pixels], barycentric_uv[first:first + pixels],
        )


# -- thread pool ---------------------------------------------------------------------------
# Pixels plus triangles below which a frame is drawn in the calling thread alone.
PARALLEL_MIN_WORK = 150_000


# -- renderer --------------------------------------------------------------------------------
class PinholeRasterizer:
    """Rasterizes pinhole frames of one triangle mesh into the ray caster's per-pixel hits.

    Args:
        vertices: (V, 3) positions in metres. They are rounded to float32 first, as the ray
            caster stores them, so both draw the same triangles.
        faces: (F, 3) triangle corner indices.
        width, height, fx, fy, cx, cy: the pinhole intrinsics; pixel (u, v) looks along
            ((u - cx) / fx, (v - cy) / fy, 1).
        threads: row groups drawn in parallel (default: :func:`default_thread_count`).
        cull_back_faces: drop the back faces of closed solids (:func:`closed_solids`) the
            camera is outside of: the same frames, 1.1-1.2x faster on generated rooms (half
            their triangles face away). False draws every triangle.
    """

    def __init__(
        self,
        vertices: np.ndarray,
        faces: np.ndarray,
        width: int,
        height: int,
        fx: float,
        fy: float,
        cx: float,
        cy: float,
        threads: int | None = None,
        cull_back_faces: bool = True,
    ) -> None:
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float32)
        faces = np.asarray(faces)
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3:
            raise ValueError(f"vertices must have shape (V, 3), got {self.vertices.shape}")
        if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
            raise ValueError(f"faces must have shape (F, 3) with F > 0, got {faces.shape}")
        if faces.min() < 0 or faces.max() >= len(self.vertices):
            raise ValueError(
                f"faces index vertices 0 .. {len(self.vertices) - 1}, got indices from "
                f"{faces.min()} to {faces.max()}"
            )
        if not np.isfinite(self.vertices).all():
            raise ValueError("vertices must be finite (found NaN or inf coordinates)")
        # Meshes with per-face colours repeat each corner once per face (3x on the generated
        # scenes): every frame projects each distinct position once.
        unique, inverse = np.unique(self.vertices, axis=0, return_inverse=True)
        if len(unique) < len(self.vertices):
            self.vertices = np.ascontiguousarray(unique)
            faces = inverse.reshape(-1)[faces]
        # A row per axis: the vertex pass reads them in vectorized loops.
        self.vertex_columns = np.ascontiguousarray(self.vertices.T)
        self.faces = np.ascontiguousarray(faces, dtype=np.int32)
        if width <= 0 or height <= 0 or fx <= 0 or fy <= 0:
            raise ValueError(
                f"need a positive image size and focal lengths, got {width} x {height}, "
                f"fx={fx}, fy={fy}"
            )
        if threads is not None and threads < 1:
            raise ValueError(f"threads must be at least 1 (or None for the default), got {threads}")
        self.width, self.height = int(width), int(height)
        self.threads = int(threads) if threads is not None else default_thread_count()
        self.intrinsics = np.array([fx, fy, cx, cy], dtype=np.float64)
        self._buffers: tuple[np.ndarray, ...] | None = None
        self._splits: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        self._cluster_arrays: tuple[np.ndarray, ...] | None = None
        self.cull_back_faces = bool(cull_back_faces)
        self._every_face = np.ones(len(self.faces), np.uint8)  # barycentrics of every hit
        self._solid_arrays: tuple[np.ndarray, np.ndarray] | None = None

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_buffers"] = None  # scratch space, rebuilt on first use
        return state

    def _split(self, groups: int, vertex_groups: int) -> tuple[np.ndarray, np.ndarray]:
        """Triangle and vertex ranges of the threads (fixed per mesh: computed once, as
        small frames are drawn in a fraction of a millisecond)."""
        key = (groups, vertex_groups)
        if key not in self._splits:
            self._splits[key] = (
                np.linspace(0, len(self.faces), groups + 1).astype(np.int64),
                np.linspace(0, len(self.vertices), vertex_groups + 1).astype(np.int64),
            )
        return self._splits[key]

    def _clusters(self) -> tuple[np.ndarray, ...]:
        """The faces in cluster order, the mesh's culling clusters (:func:`triangle_clusters`:
        order, spheres, vertex starts and list) with the spheres of their groups of
        ``SUBCLUSTER_FACES`` after the clusters' own, and the solid of each face in that order
        with the solids' boxes, made on first use."""
        if self._cluster_arrays is None:
            order, spheres, starts, members = triangle_clusters(self.vertices, self.faces)
            faces = np.ascontiguousarray(self.faces[order])
            face_solids, boxes = self._solids()
            self._cluster_arrays = (
                faces, order, spheres, group_spheres(self.vertices, faces, SUBCLUSTER_FACES),
                starts, members, np.ascontiguousarray(face_solids[order]), boxes,
            )
        return self._cluster_arrays

    def _solids(self) -> tuple[np.ndarray, np.ndarray]:
        """:func:`closed_solids` of the mesh (none when ``cull_back_faces`` is off)."""
        if self._solid_arrays is None:
            if self.cull_back_faces:
                self._solid_arrays = closed_solids(self.vertices, self.faces, self._solid_margin())
            else:
                self._solid_arrays = (np.full(len(self.faces), -1, np.int32), np.empty((0, 6)))
        return self._solid_arrays

    def _solid_margin(self) -> float:
        """How far outside a solid's box a camera must be for its back faces to be dropped.

        The front face a ray enters a solid through lies in the box, so at least this far from
        the camera; the near plane cuts only points within ``NEAR_PLANE_M`` times the longest
        pixel ray (z = 1) of the camera, which the margin keeps ten times clear of."""
        fx, fy, cx, cy = self.intrinsics
        wide = max(cx + 1.0, self.width - cx) / fx
        tall = max(cy + 1.0, self.height - cy) / fy
        return max(1e-3, 10.0 * NEAR_PLANE_M * float(np.sqrt(1.0 + wide**2 + tall**2)))

    @property
    def _frame_band_rows(self) -> int:
        """Rows per band of the frames :func:`render_frames` draws: the whole frame when its
        z-buffer is small (``SINGLE_BAND_MAX_BYTES``)."""
        whole = self.width * self.height * 12 <= SINGLE_BAND_MAX_BYTES
        return self.height if whole else BAND_ROWS

    def _scratch(self) -> tuple[np.ndarray, ...]:
        if self._buffers is None:
            count = len(self.faces)
            self._buffers = (
                np.empty(len(self.vertices), np.uint8),
                np.empty((5, len(self.vertices)), np.float64),
                np.empty((count, _RECORD_FLOATS), np.float64),
                np.empty((count, 6), np.float64),
                np.empty((count, 3), np.int64),
                np.empty((self.threads, max(BAND_ROWS, self._frame_band_rows), self.width),
                         np.float64),
                np.empty((self.threads, max(BAND_ROWS, self._frame_band_rows), self.width),
                         np.int32),
                np.zeros(len(self.vertices) + 1, np.int64),
            )
        return self._buffers

    def render(
        self, camera_to_world: np.ndarray, max_depth_m: float = np.inf, barycentrics: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Depth, triangle ids and barycentrics of the first hit of every pixel ray.

        Args:
            camera_to_world: 4x4 pose (OpenCV camera axes); rounded to float32 like the ray
                caster's rays.
            max_depth_m: z-depths beyond this become 0, as in the ray-cast renderer.
            barycentrics: also return the barycentric (u, v) of each hit.

        Returns:
            ``depth`` (H, W) float32 z-depth (0: no hit or beyond the range),
            ``triangle_ids`` (H * W,) int32 (-1 where the depth is 0) and
            ``barycentric_uv`` (H * W, 2) float32 with point = (1 - u - v) v0 + u v1 + v v2,
            or None when not asked for.
        """
        pose = _checked_poses(camera_to_world, (4, 4))
        rotation = np.ascontiguousarray(pose[:3, :3])
        origin = np.ascontiguousarray(pose[:3, 3])
        (
            outcodes, projections, records, hit_planes, record_rows, inverse_depth, winners,
            stamps,
        ) = self._scratch()
        max_depth, far_cut, nearest = _depth_limits(max_depth_m)
        # Handing work to another thread costs more than it saves on small frames: those are
        # drawn in this thread, with the clusters culled (pass 0).
        if self.width * self.height + len(self.faces) < PARALLEL_MIN_WORK:
            depth = np.empty((1, self.height, self.width), np.float32)
            triangle_ids = np.empty(self.height * self.width, np.int32)
            uv = np.empty((self.height * self.width, 2), np.float32)
            render_frames(
                self.vertex_columns, pose[None], self.intrinsics, self.width,
                self.height, far_cut, nearest, max_depth, barycentrics, self._every_face,
                *self._clusters(),
                outcodes, projections, records, hit_planes, record_rows, stamps,
                inverse_depth[0, :self._frame_band_rows], winners[0, :self._frame_band_rows],
                depth, triangle_ids, uv,
            )
            return depth[0], triangle_ids, (uv if barycentrics else None)
        groups = self.threads
        # Classifying a vertex is cheap: split only long vertex lists between the threads.
        vertex_groups = groups if len(self.vertices) >= PARALLEL_MIN_WORK else 1
        bounds, vertex_bounds = self._split(groups, vertex_groups)

        def classify(group: int) -> None:
            vertex_outcodes(
                self.vertex_columns, vertex_bounds[group], vertex_bounds[group + 1], rotation,
                origin, self.intrinsics, self.width, self.height, far_cut, outcodes, projections,
            )

        face_solids, solid_boxes = self._solids()

        def setup(group: int) -> int:
            return setup_triangles(
                outcodes, projections, self.faces, bounds[group:group + 2][None], origin,
                self.intrinsics, self.width, self.height, records, hit_planes, record_rows,
                bounds[group], face_solids, solid_boxes,
            )

        run_parallel(classify, vertex_groups)
        counts = run_parallel(setup, groups)
        segments = np.stack([bounds[:-1], bounds[:-1] + np.asarray(counts, np.int64)], axis=1)
        band_count = -(-self.height // BAND_ROWS)
        band_starts, entries = bin_records(record_rows, segments, BAND_ROWS, band_count)

        depth = np.empty((self.height, self.width), np.float32)
        triangle_ids = np.empty(self.height * self.width, np.int32)
        uv = np.empty((self.height * self.width, 2), np.float32)

        def draw(group: int) -> None:
            draw_bands(
                records, hit_planes, record_rows, band_starts, entries, group, groups, nearest,
                max_depth, barycentrics, self._every_face, inverse_depth[group, :BAND_ROWS],
                winners[group, :BAND_ROWS], depth,
                triangle_ids, uv,
            )

        run_parallel(draw, groups)
        return depth, triangle_ids, (uv if barycentrics else None)

    def render_many_into(
        self,
        camera_to_world: np.ndarray,
        max_depth_m: float,
        depth: np.ndarray,
        triangle_ids: np.ndarray,
        barycentric_uv: np.ndarray,
        barycentric_faces: np.ndarray | None = None,
    ) -> None:
        """:meth:`render` of K poses (K, 4, 4) in the calling thread, into given arrays.

        The frames are the same as :meth:`render`'s, frame after frame: ``depth`` (K, H, W)
        float32, ``triangle_ids`` (K * H * W,) int32, ``barycentric_uv`` (K * H * W, 2)
        float32. One compiled call draws them all, which is what makes many small frames
        cheap (a batched env's 64 x 64 frames); threads each call this on their own
        rasterizer (the scratch space is per rasterizer).

        ``barycentric_faces``: (F,) bool or uint8 flags of the triangles whose hits need
        their barycentric (u, v), the others' being (0, 0): a scene coloured flat per
        triangle needs none (default: every triangle's).
        """
        poses = _checked_poses(camera_to_world, (len(camera_to_world), 4, 4))
        count, pixels = len(poses), self.width * self.height
        if (
            depth.shape != (count, self.height, self.width)
            or triangle_ids.shape != (count * pixels,)
            or barycentric_uv.shape != (count * pixels, 2)
        ):
            raise ValueError(
                f"output arrays must hold {count} frames of {self.height} x {self.width}, got "
                f"{depth.shape}, {triangle_ids.shape}, {barycentric_uv.shape}"
            )
        if barycentric_faces is None:
            barycentric_faces = self._every_face
        elif barycentric_faces.shape != (len(self.faces),):
            raise ValueError(f"barycentric_faces must flag the {len(self.faces)} triangles, got "
                             f"shape {barycentric_faces.shape}")
        max_depth, far_cut, nearest = _depth_limits(max_depth_m)
        (
            outcodes, projections, records, hit_planes, record_rows, inverse_depth, winners,
            stamps,
        ) = self._scratch()
        render_frames(
            self.vertex_columns, poses, self.intrinsics, self.width, self.height,
            far_cut, nearest, max_depth, True,
            np.ascontiguousarray(barycentric_faces, np.uint8), *self._clusters(),
            outcodes, projections,
            records, hit_planes, record_rows, stamps, inverse_depth[0, :self._frame_band_rows],
            winners[0, :self._frame_band_rows], depth,
            triangle_ids, barycentric_uv,
        )


def _checked_poses(camera_to_world: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Camera-to-world pose(s) rounded to float32 like the ray caster's rays, as float64."""
    poses = np.asarray(camera_to_world, dtype=np.float32).astype(np.float64)
    if poses.shape != shape or not np.isfinite(poses).all():
        raise ValueError(
            f"camera_to_world must be finite {' x '.join(map(str, shape))} matrices, got "
            f"shape {poses.shape}" + ("" if poses.shape != shape else " with non-finite entries")
        )
    return poses


def _depth_limits(max_depth_m: float) -> tuple[float, float, float]:
    """(range, far cut, 1 / far cut) of a frame: a triangle whose every corner lies beyond
    the far cut can only give depth-0 pixels."""
    max_depth = float(max_depth_m)
    far_cut = max_depth * (1.0 + 1e-6) + 1e-6 if np.isfinite(max_depth) else np.inf
    return max_depth, far_cut, 1.0 / far_cut
