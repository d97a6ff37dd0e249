"""Pinhole RGB-D camera: intrinsics and the renderer that makes a frame.

The renderer finds the first hit of every pixel ray either by Embree ray casting (the
reference, and this class's default) or by rasterizing (:mod:`naruto_gym.sensors.raster`),
which yields the same per-pixel hits several times faster on full frames; both feed the same
colour lookup. The envs default to the ray cast
(:data:`naruto_gym.envs.settings.PINHOLE_BACKEND`); ``"auto"`` picks the rasterizer wherever
it is the faster.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from typing import Literal

import numpy as np

from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.sensors.kernels import fill_world_rays
from naruto_gym.sensors.raster import PinholeRasterizer
from naruto_gym.sensors.raycaster import RayCaster, RayHits
from naruto_gym.utils.threads import resolve_threads, run_parallel

PinholeBackend = Literal["raycast", "raster", "auto"]
PINHOLE_BACKENDS: tuple[str, ...] = ("raycast", "raster", "auto")

# "auto" rasterizes when the mesh has at most this many triangles per pixel of the frame:
# rasterizing pays a per-triangle setup on every frame, the ray cast a per-pixel cost.
# benchmarks/render_speed.py finds the rasterizer faster at 3.2 triangles per pixel and the
# ray cast faster from 12 up (docs/benchmarks/rendering.md).
AUTO_RASTER_MAX_TRIANGLES_PER_PIXEL = 4.0
# The same for frames drawn many at a time (a batched env's agents): each thread draws whole
# frames in one call, and on the Replica sample at 64 x 64 (12 triangles per pixel) the
# rasterizer made 1.43x the ray cast's steps with 64 agents (about even with one).
AUTO_RASTER_MAX_TRIANGLES_PER_PIXEL_BATCHED = 16.0

# Pixels per thread below which the colour lookup stays in the calling thread.
_PARALLEL_SHADING_MIN_PIXELS = 65_536


@dataclass(frozen=True)
class PinholeCamera:
    """Pinhole intrinsics; defaults are the published system's 680 x 1200 camera.

    Pixel (u, v) looks along ((u - cx) / fx, (v - cy) / fy, 1) in the OpenCV camera frame.
    """

    width: int = 1200
    height: int = 680
    fx: float = 600.0
    fy: float = 600.0
    cx: float = 599.5
    cy: float = 339.5

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"camera size must be positive, got {self.width} x {self.height}")
        if self.fx <= 0 or self.fy <= 0:
            raise ValueError(f"focal lengths must be positive, got fx={self.fx}, fy={self.fy}")

    @property
    def matrix(self) -> np.ndarray:
        """3x3 intrinsic matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def scaled(self, factor: float) -> PinholeCamera:
        """The same field of view at ``factor`` times the resolution (pixel-centre aligned)."""
        width = max(int(round(self.width * factor)), 1)
        height = max(int(round(self.height * factor)), 1)
        sx, sy = width / self.width, height / self.height
        return replace(
            self,
            width=width,
            height=height,
            fx=self.fx * sx,
            fy=self.fy * sy,
            cx=(self.cx + 0.5) * sx - 0.5,
            cy=(self.cy + 0.5) * sy - 0.5,
        )

    def as_dict(self) -> dict[str, float]:
        return {
            "width": self.width,
            "height": self.height,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
        }

    @cached_property
    def ray_directions(self) -> np.ndarray:
        """(H * W, 3) float32 camera-frame directions with z = 1, row-major over (v, u)."""
        u, v = np.meshgrid(
            np.arange(self.width, dtype=np.float32), np.arange(self.height, dtype=np.float32)
        )
        directions = np.stack(
            [(u - self.cx) / self.fx, (v - self.cy) / self.fy, np.ones_like(u)], axis=-1
        )
        return directions.reshape(-1, 3)

    def project(self, points_camera: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (N, 2) and z-depth (N,) of camera-frame points."""
        z = points_camera[:, 2]
        safe_z = np.where(np.abs(z) < 1e-9, 1e-9, z)
        u = self.fx * points_camera[:, 0] / safe_z + self.cx
        v = self.fy * points_camera[:, 1] / safe_z + self.cy
        return np.stack([u, v], axis=1), z


@dataclass(frozen=True)
class PixelHits:
    """The first hit of every pixel ray of a frame.

    Attributes:
        depth: (H, W) float32 z-depth in metres, 0 where there is no hit or the hit lies
            beyond the renderer's range.
        triangle_ids: (H * W,) int32 index of the hit triangle, -1 where the depth is 0.
        barycentric_uv: (H * W, 2) float32 barycentric (u, v) of the hit inside its triangle:
            point = (1 - u - v) * v0 + u * v1 + v * v2.
    """

    depth: np.ndarray
    triangle_ids: np.ndarray
    barycentric_uv: np.ndarray


class RgbdRenderer:
    """Renders pinhole RGB-D frames of a scene.

    Depth is z-depth in metres (float32), 0 where there is no hit or the hit lies beyond
    ``max_depth_m``; RGB is uint8 (H, W, 3), black where depth is 0.

    Args:
        scene: the scene to render.
        camera: intrinsics (default :class:`PinholeCamera`).
        max_depth_m: sensor range.
        raycaster: an existing ray caster of ``scene`` to share (built if None).
        backend: how pixel hits are found. ``"raycast"`` (default, the reference): Embree
            casts every pixel ray. ``"raster"``: the pinhole rasterizer, several times
            faster on full frames: the same hits (triangle, barycentrics, z-depth of the exact
            pixel ray) up to exact edge ties and float rounding (Embree's depths are float32
            sums, the rasterizer's float64). ``"auto"``: the rasterizer when the mesh has at most
            ``auto_max_triangles_per_pixel`` triangles per pixel, else the ray cast.
        threads: threads for the rasterizer and the colour lookup (default:
            :func:`~naruto_gym.utils.threads.default_thread_count`, the CPUs this process
            may use).

    ``auto_max_triangles_per_pixel`` (default ``AUTO_RASTER_MAX_TRIANGLES_PER_PIXEL``, for
    frames drawn one at a time) is where ``"auto"`` turns to the ray cast; a batched env sets
    ``AUTO_RASTER_MAX_TRIANGLES_PER_PIXEL_BATCHED`` on its renderers.
    """

    def __init__(
        self,
        scene: Scene,
        camera: PinholeCamera | None = None,
        max_depth_m: float = 10.0,
        raycaster: RayCaster | None = None,
        backend: PinholeBackend = "raycast",
        threads: int | None = None,
    ) -> None:
        if backend not in PINHOLE_BACKENDS:
            raise ValueError(
                f"unknown pinhole backend {backend!r}; use one of {PINHOLE_BACKENDS} "
                "('raycast' is the reference, 'raster' the fast rasterizer)"
            )
        self.scene = scene
        self.camera = camera or PinholeCamera()
        self.max_depth_m = float(max_depth_m)
        self.raycaster = raycaster or RayCaster(scene.vertices, scene.faces)
        self.backend: PinholeBackend = backend
        self.threads = resolve_threads(threads)
        self.auto_max_triangles_per_pixel = AUTO_RASTER_MAX_TRIANGLES_PER_PIXEL
        self._rasterizer: PinholeRasterizer | None = None
        self._workers: list[PinholeRasterizer] = []  # per-thread rasterizers of batches
        self._rays: np.ndarray | None = None  # the ray cast's buffer, made on first use

    @property
    def frame_backend(self) -> Literal["raycast", "raster"]:
        """The method this renderer's frames use ("auto" resolved for its mesh and camera)."""
        if self.backend != "auto":
            return self.backend
        pixels = self.camera.width * self.camera.height
        triangles = len(self.raycaster.faces)
        return "raster" if triangles <= self.auto_max_triangles_per_pixel * pixels else "raycast"

    @property
    def rasterizer(self) -> PinholeRasterizer:
        """The pinhole rasterizer of the ray caster's triangles (built on first use)."""
        if self._rasterizer is None:
            self._rasterizer = self._new_rasterizer(self.threads)
        return self._rasterizer

    def render_depth(self, camera_to_world: np.ndarray) -> np.ndarray:
        """(H, W) float32 z-depth only (skips colour)."""
        if self.frame_backend == "raster":
            return self.rasterizer.render(camera_to_world, self.max_depth_m, False)[0]
        return self._cast(camera_to_world)[0].reshape(self.camera.height, self.camera.width)

    def render(self, camera_to_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rgb (H, W, 3) uint8, depth (H, W) float32) at a camera-to-world pose."""
        hits = self.render_hits(camera_to_world)
        rgb = self.shade(hits.triangle_ids, hits.barycentric_uv)
        return rgb.reshape(self.camera.height, self.camera.width, 3), hits.depth

    def render_hits(self, camera_to_world: np.ndarray) -> PixelHits:
        """Depth, hit triangle and barycentrics of every pixel at a camera-to-world pose."""
        if self.frame_backend == "raster":
            return PixelHits(*self.rasterizer.render(camera_to_world, self.max_depth_m))
        return self._cast_hits(camera_to_world, (self.camera.height, self.camera.width))

    def render_hits_many(
        self,
        camera_to_world: np.ndarray,
        worker: int | None = None,
        depth_out: np.ndarray | None = None,
        barycentric_faces: np.ndarray | None = None,
    ) -> PixelHits:
        """:meth:`render_hits` of K poses (K, 4, 4) at once, the same hits frame by frame.

        The rasterizer draws whole frames in parallel (each thread a contiguous share of the
        frames in one compiled call, with its own single-threaded rasterizer): small frames
        are too small to split, but a batched env has many. The ray cast casts all frames'
        rays in one call.

        ``worker``: draw every frame in the calling thread with the frame rasterizer of
        that index (made beforehand by :meth:`prepare_workers`): for callers that split
        their work between threads themselves, each thread with its own index.

        ``depth_out``: a C-contiguous (K, H, W) float32 array the rasterized depth is drawn
        into (a batched env's observation rows) and returned as ``depth``.

        ``barycentric_faces``: (F,) flags of the triangles whose rasterized hits need their
        barycentric (u, v) (the others get (0, 0); default every triangle, and every hit of
        ray-cast frames): a batched env shading a scene flat per triangle skips the rest.

        Returns:
            ``depth`` (K, H, W), ``triangle_ids`` (K * H * W,), ``barycentric_uv``
            (K * H * W, 2), frame after frame.
        """
        poses = np.asarray(camera_to_world, np.float64).reshape(-1, 4, 4)
        count, pixels = len(poses), self.camera.width * self.camera.height
        if self.frame_backend != "raster":
            return self._cast_hits(poses, (count, self.camera.height, self.camera.width))
        shape = (count, self.camera.height, self.camera.width)
        if depth_out is None:
            depth = np.empty(shape, np.float32)
        elif (
            depth_out.shape != shape
            or depth_out.dtype != np.float32
            or not (depth_out.flags.c_contiguous)
        ):
            raise ValueError(
                f"depth_out must be a C-contiguous {shape} float32 array, got "
                f"{depth_out.dtype} {depth_out.shape}"
            )
        else:
            depth = depth_out
        triangle_ids = np.empty(count * pixels, np.int32)
        barycentric_uv = np.empty((count * pixels, 2), np.float32)
        if worker is not None:
            self._workers[worker].render_many_into(
                poses, self.max_depth_m, depth, triangle_ids, barycentric_uv, barycentric_faces
            )
            return PixelHits(depth, triangle_ids, barycentric_uv)
        workers = self._frame_rasterizers(min(self.threads, count))
        bounds = np.linspace(0, count, len(workers) + 1).astype(np.int64)

        def draw(part: int) -> None:
            first, stop = bounds[part], bounds[part + 1]
            workers[part].render_many_into(
                poses[first:stop],
                self.max_depth_m,
                depth[first:stop],
                triangle_ids[first * pixels : stop * pixels],
                barycentric_uv[first * pixels : stop * pixels],
                barycentric_faces,
            )

        run_parallel(draw, len(workers))
        return PixelHits(depth, triangle_ids, barycentric_uv)

    def prepare_workers(self, count: int) -> None:
        """Make the frame rasterizers ``0 .. count - 1`` that :meth:`render_hits_many`'s
        ``worker`` picks (from one thread, before the threads that use them start)."""
        if self.frame_backend == "raster":
            self._frame_rasterizers(count)

    def _new_rasterizer(self, threads: int) -> PinholeRasterizer:
        """A rasterizer of the ray caster's triangles for this renderer's camera."""
        camera = self.camera
        return PinholeRasterizer(
            self.raycaster.vertices,
            self.raycaster.faces,
            camera.width,
            camera.height,
            camera.fx,
            camera.fy,
            camera.cx,
            camera.cy,
            threads=threads,
        )

    def _frame_rasterizers(self, count: int) -> list[PinholeRasterizer]:
        """``count`` single-threaded rasterizers of this renderer's mesh (scratch space is per
        rasterizer, so each thread needs its own), built on first use."""
        while len(self._workers) < count:
            self._workers.append(self._new_rasterizer(1))
        return self._workers[:count]

    def shade(self, triangle_ids: np.ndarray, barycentric_uv: np.ndarray) -> np.ndarray:
        """(N, 3) uint8 colours of hits (black for id -1): the scene's colour lookup, split
        between the renderer's threads on large frames."""
        pixels = len(triangle_ids)
        parts = min(self.threads, max(pixels // _PARALLEL_SHADING_MIN_PIXELS, 1))
        if parts == 1:
            return self.scene.colour_at(triangle_ids, barycentric_uv)
        rgb = np.empty((pixels, 3), np.uint8)
        bounds = np.linspace(0, pixels, parts + 1).astype(np.int64)

        def shade_part(part: int) -> None:
            chunk = slice(bounds[part], bounds[part + 1])
            rgb[chunk] = self.scene.colour_at(triangle_ids[chunk], barycentric_uv[chunk])

        run_parallel(shade_part, parts)
        return rgb

    def _cast(self, camera_to_world: np.ndarray) -> tuple[np.ndarray, RayHits]:
        """Cast the pixel rays of one pose (4, 4) or of K poses (K, 4, 4) in one call: the
        flat z-depths, cut to the range (0 beyond it), and the hits, frame after frame."""
        poses = np.asarray(camera_to_world, dtype=np.float32).reshape(-1, 4, 4)
        pixels = self.camera.width * self.camera.height
        if self._rays is None or len(self._rays) < len(poses) * pixels:
            self._rays = np.empty((len(poses) * pixels, 6), np.float32)
        rays = self._rays[: len(poses) * pixels]
        # Directions keep camera z = 1, so the ray parameter of a hit is its z-depth.
        for k, pose in enumerate(poses):
            fill_world_rays(
                self.camera.ray_directions,
                np.ascontiguousarray(pose[:3, :3]),
                np.ascontiguousarray(pose[:3, 3]),
                rays[k * pixels : (k + 1) * pixels],
            )
        hits = self.raycaster.cast_packed(rays)
        depth = hits.distance.copy()
        depth[~(depth <= self.max_depth_m)] = 0.0
        return depth, hits

    def _cast_hits(self, camera_to_world: np.ndarray, shape: tuple[int, ...]) -> PixelHits:
        """:meth:`_cast` as pixel hits, depth in ``shape``; pixels beyond the range are black
        like misses."""
        depth, hits = self._cast(camera_to_world)
        triangle_ids = np.where(depth > 0, hits.triangle_ids, np.int32(-1))
        return PixelHits(depth.reshape(shape), triangle_ids, hits.barycentric_uv)
