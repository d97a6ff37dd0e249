"""The compiled passes of the rasterizer: culling, vertices, triangle setup, binning, drawing.

Each pass is a numba function that releases the GIL, so that :class:`.PinholeRasterizer` can
split it between threads (:func:`vertex_outcodes`, :func:`setup_triangles`,
:func:`draw_bands` over a share of the vertices, triangles or bands, with :func:`bin_records`
in between); :func:`render_frames` runs every pass of many small frames in one call, first
skipping the clusters of :mod:`.culling` whose sphere cannot reach the view volume
(:func:`sphere_may_be_seen`). The triangle records the setup pass writes are laid out as
``RECORD_FLOATS`` float64 per triangle (see the constants below).

Every compiled function, and every constant they read, lives in this one module: numba's
on-disk cache (``cache=True``) notices a change to a function's own file only, and the
constants are frozen into the compiled code.
"""

from __future__ import annotations

import numba
import numpy as np

# Hits closer to the camera centre than this (metres) are not drawn; the ray cast starts at 0.
NEAR_PLANE_M = 1e-6

# Neighbouring triangles culled together against the view volume (pass 0), then in groups of
# SUBCLUSTER_FACES within the clusters seen: a quarter of a cluster is culled more often.
CLUSTER_FACES = 64
SUBCLUSTER_FACES = 16

# A cluster is culled only when its sphere lies this much (relative, plus 1 um) outside a
# side: the vertices' own outcodes are computed another way, and rounding must not cull a
# triangle they would keep.
_CULL_SLACK = 1e-6

# Layout of the float64 triangle records made by the setup pass, every plane in pixel units
# (a * u + b * v + c): the three edge planes (times the sign of det), the inverse-depth plane
# 1 / z, and the reciprocal of each edge plane's u slope (0 where that would overflow).
_INVERSE_DEPTH = 9
_INVERSE_SLOPES = 12
RECORD_FLOATS = 15

# Slack (pixels) on a triangle's projected bounding box before it is found to hold no pixel.
_BOX_MARGIN_PX = 1e-6


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



@numba.njit(cache=True, nogil=True, error_model="numpy")
def view_side_planes(intrinsics: np.ndarray, width: int, height: int) -> np.ndarray:
    """(4, 2) float64 unit normals, pointing into the view volume, of its left, right, top
    and bottom sides (the outcode planes of :func:`vertex_outcodes`), each as the
    (x or y, z) coefficients of a camera-frame point's signed distance (x for the first two)."""
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
    volume (the outcode planes of :func:`vertex_outcodes`): every corner of its
    triangles then has that side's bit, and the setup pass would drop every one of them."""
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
        records: (F, 15) float64 output, laid out as described at ``RECORD_FLOATS``.
        hit_planes: (F, 6) float64 output: the planes of the barycentric coordinates u and v
            divided by the z-depth (u = plane(pixel) * z), in pixel units.
        record_rows: (F, 3) int64 output: triangle id, first row, last row.
        face_solids, solid_boxes: :func:`.culling.closed_solids` of the mesh
            (``face_solids`` in the order of ``faces``): a back face of a solid whose box the
            camera is outside of is dropped.

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
            :func:`.culling.triangle_clusters` of the mesh, ``CLUSTER_FACES`` triangles per
            cluster.
        sub_spheres: :func:`.culling.group_spheres` of ``cluster_faces``,
            ``SUBCLUSTER_FACES`` each.
        cluster_face_solids, solid_boxes: :func:`.culling.closed_solids` of the mesh, the
            solid of each face in cluster order.
        scratch_*: the single-frame buffers of :class:`.PinholeRasterizer`;
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

