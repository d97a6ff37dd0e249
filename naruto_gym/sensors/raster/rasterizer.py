"""The renderer of the rasterizing pinhole backend: one mesh's frames, one or many at a time.

:class:`PinholeRasterizer` owns what a mesh needs on every frame (its distinct vertices, the
culling clusters and closed solids of :mod:`.culling`, scratch buffers) and decides how a frame
is drawn by the compiled passes of :mod:`.kernels`: a small frame, or a batch of them, in the
calling thread by one compiled call that culls clusters first; a large frame with each pass
split between a small pool of threads (:mod:`naruto_gym.utils.threads`), as handing work to
another thread costs more than it saves on small frames.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from naruto_gym.sensors.raster.culling import closed_solids, group_spheres, triangle_clusters
from naruto_gym.sensors.raster.kernels import (
    NEAR_PLANE_M,
    RECORD_FLOATS,
    SUBCLUSTER_FACES,
    bin_records,
    draw_bands,
    render_frames,
    setup_triangles,
    vertex_outcodes,
)
from naruto_gym.utils.threads import resolve_threads, run_parallel

# Image rows drawn together: a band's z-buffer (16 x 1200 x 12 bytes) stays in the L2 cache.
BAND_ROWS = 16

# Frames drawn in one thread (render_frames) whose whole z-buffer takes at most this many bytes
# are drawn as one band: no triangle is read once per band.
SINGLE_BAND_MAX_BYTES = 256 * 1024

# Pixels plus triangles below which a frame is drawn in the calling thread alone.
PARALLEL_MIN_WORK = 150_000


class MeshClusters(NamedTuple):
    """A mesh's culling data in the order :func:`~.kernels.render_frames` takes it.

    Attributes:
        cluster_faces: (F, 3) int32 faces in cluster order (``faces[cluster_order]``).
        cluster_order: (F,) int32 mesh triangle id of each of them.
        spheres: (C, 4) float64 bounding spheres (centre, radius) of the clusters of
            ``CLUSTER_FACES`` triangles (:func:`~.culling.triangle_clusters`).
        sub_spheres: (G, 4) float64 bounding spheres of their groups of ``SUBCLUSTER_FACES``.
        cluster_vertex_starts, cluster_vertices: cluster ``c`` uses the vertices
            ``cluster_vertices[cluster_vertex_starts[c]:cluster_vertex_starts[c + 1]]``.
        cluster_face_solids: (F,) int32 closed solid of each face in cluster order (-1: none).
        solid_boxes: (S, 6) float64 the solids' grown bounding boxes
            (:func:`~.culling.closed_solids`).
    """

    cluster_faces: np.ndarray
    cluster_order: np.ndarray
    spheres: np.ndarray
    sub_spheres: np.ndarray
    cluster_vertex_starts: np.ndarray
    cluster_vertices: np.ndarray
    cluster_face_solids: np.ndarray
    solid_boxes: np.ndarray


class PinholeRasterizer:
    """Rasterizes pinhole frames of one triangle mesh into the ray caster's per-pixel hits.

    Args:
        vertices: (V, 3) positions in metres. They are rounded to float32 first, as the ray
            caster stores them, so both draw the same triangles.
        faces: (F, 3) triangle corner indices.
        width, height, fx, fy, cx, cy: the pinhole intrinsics; pixel (u, v) looks along
            ((u - cx) / fx, (v - cy) / fy, 1).
        threads: row groups drawn in parallel (default: :func:`default_thread_count`).
        cull_back_faces: drop the back faces of closed solids
            (:func:`~.culling.closed_solids`) the camera is outside of: the same frames,
            faster on scenes made of solids (half their triangles face away). False draws
            every triangle.
        cull_clusters: skip the clusters of triangles that lie wholly outside the view
            volume on frames drawn in one thread: the same frames, faster. False draws every
            cluster (to check that culling changes nothing).
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
        cull_clusters: bool = True,
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
        self.width, self.height = int(width), int(height)
        self.threads = resolve_threads(threads)
        self.intrinsics = np.array([fx, fy, cx, cy], dtype=np.float64)
        self._buffers: tuple[np.ndarray, ...] | None = None
        self._splits: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        self._cluster_arrays: MeshClusters | None = None
        self.cull_back_faces = bool(cull_back_faces)
        self.cull_clusters = bool(cull_clusters)
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

    @property
    def clusters(self) -> MeshClusters:
        """The mesh's culling clusters and closed solids in cluster order (made on first use;
        with ``cull_clusters`` off, every sphere has an infinite radius: none is culled)."""
        if self._cluster_arrays is None:
            order, spheres, starts, members = triangle_clusters(self.vertices, self.faces)
            faces = np.ascontiguousarray(self.faces[order])
            sub_spheres = group_spheres(self.vertices, faces, SUBCLUSTER_FACES)
            if not self.cull_clusters:  # spheres that reach every view volume
                spheres[:, 3] = np.inf
                sub_spheres[:, 3] = np.inf
            face_solids, boxes = self.solids
            self._cluster_arrays = MeshClusters(
                faces, order, spheres, sub_spheres, starts, members,
                np.ascontiguousarray(face_solids[order]), boxes,
            )
        return self._cluster_arrays

    @property
    def solids(self) -> tuple[np.ndarray, np.ndarray]:
        """:func:`~.culling.closed_solids` of the mesh, ``(face_solids, boxes)`` (no solid
        when ``cull_back_faces`` is off), made on first use."""
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
                np.empty((count, RECORD_FLOATS), np.float64),
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
                *self.clusters,
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

        face_solids, solid_boxes = self.solids

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
            np.ascontiguousarray(barycentric_faces, np.uint8), *self.clusters,
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
