"""The per-mesh geometry a rasterized frame is culled with, made once per mesh in numpy.

The triangles in clusters of ``CLUSTER_FACES`` neighbours (Z-order of their centroids) with a
bounding sphere each (:func:`triangle_clusters`), the spheres of groups of ``SUBCLUSTER_FACES``
within them (:func:`group_spheres`), and the parts of the mesh that bound closed solids, whose
back faces a camera outside never sees (:func:`closed_solids`). Per frame, the compiled passes
(:mod:`.kernels`) skip a sphere that cannot reach the view volume, and with it every triangle
it bounds, which changes no pixel.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph

from naruto_gym.sensors.raster.kernels import CLUSTER_FACES


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
