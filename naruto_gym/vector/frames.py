"""The batched env's frames: every agent's pinhole frame and panorama, drawn per scene.

One ray cast per scene carries the pinhole rays of all its agents (unless the frames are
rasterized), their observation panorama rays, and the first escape-check rays of the agents
whose move the published escape rule must still judge: only as many rays as can decide the
check, the rest cast only for the agents those leave undecided.

The frames are drawn into buffers that are handed out as the observations without a copy;
every reset and step draws into new buffers, so what a caller holds never changes.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from naruto_gym.envs.scene_runtime import SceneRuntime
from naruto_gym.sensors.kernels import fill_panorama_rays
from naruto_gym.sensors.panorama import EquirectangularCamera
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.vector.batch_kernels import fill_pinhole_rays, no_hit_counts
from naruto_gym.vector.scheduling import in_threads

_ESCAPE_PLANS: dict[tuple[int, int, float], tuple[int, np.ndarray]] = {}


def escape_ray_plan(checker: Any) -> tuple[int, np.ndarray]:
    """How the published escape check's panorama is cast: ``(k, directions)`` with the
    directions reordered so that any prefix spreads over the whole sphere (bit-reversed
    pixel order), and ``k`` the fewest of them whose all hitting proves the no-hit share
    cannot exceed the threshold, even if every remaining ray missed. Only undecided agents
    cast the rest. The shares are computed as the check computes them."""
    camera = checker.escape_panorama
    threshold = float(checker.escape_no_hit_threshold)
    key = (camera.height, camera.width, threshold)
    if key not in _ESCAPE_PLANS:
        total = camera.height * camera.width
        first = next(k for k in range(total + 1) if (total - k) / total <= threshold)
        bits = max(int(np.ceil(np.log2(max(total, 2)))), 1)
        keys = [int(f"{i:0{bits}b}"[::-1], 2) for i in range(total)]
        order = np.argsort(np.array(keys), kind="stable")
        _ESCAPE_PLANS[key] = (first, np.ascontiguousarray(camera.ray_directions[order]))
    return _ESCAPE_PLANS[key]


class FrameDrawer:
    """Draws agents' frames into the batch's frame buffers.

    Args:
        num_envs: the agents.
        camera: the pinhole camera.
        panorama_camera: the observation panorama's camera, None when it is off.
        max_depth_m: the sensor range (hits beyond it are misses).
        poses: (N, 4, 4) the agents' camera-to-world poses (read at each draw).

    Attributes:
        rgb: (N, H, W, 3) uint8 the current frames.
        depth: (N, H, W) float32.
        panorama: (N, h, w) float32, None when the panorama is off.
        rays_cast: rays cast so far (frames, panoramas and escape checks).
    """

    def __init__(
        self,
        num_envs: int,
        camera: PinholeCamera,
        panorama_camera: EquirectangularCamera | None,
        max_depth_m: float,
        poses: np.ndarray,
    ) -> None:
        self.camera = camera
        self.panorama_camera = panorama_camera
        self.max_depth_m = max_depth_m
        self.poses = poses
        height, width = camera.height, camera.width
        self.rgb = np.zeros((num_envs, height, width, 3), np.uint8)
        self.depth = np.zeros((num_envs, height, width), np.float32)
        self.panorama = (
            np.zeros((num_envs, panorama_camera.height, panorama_camera.width), np.float32)
            if panorama_camera is not None
            else None
        )
        self.rays_cast = 0
        self._rays_lock = threading.Lock()

    def observations(self) -> dict[str, np.ndarray]:
        """The agents' observations: the frame buffers themselves, handed out (every reset
        and step draws into new ones, :meth:`renew`, so what the caller holds never
        changes)."""
        observations = {
            "rgb": self.rgb,
            "depth": self.depth,
            "pose": self.poses.astype(np.float32),
        }
        if self.panorama is not None:
            observations["panorama"] = self.panorama
        return observations

    def renew(self, keep: np.ndarray | None = None) -> None:
        """New frame buffers (those of the last observations belong to the caller now), with
        the frames of the agents ``keep`` flags copied over."""
        buffers = [self.rgb, self.depth] + ([self.panorama] if self.panorama is not None else [])
        fresh = [np.empty_like(buffer) for buffer in buffers]
        if keep is not None:
            for old, new in zip(buffers, fresh, strict=True):
                new[keep] = old[keep]
        self.rgb, self.depth = fresh[0], fresh[1]
        if self.panorama is not None:
            self.panorama = fresh[2]

    def panorama_no_hit_shares(self) -> np.ndarray:
        """(N,) each agent's share of the panorama pixels cast that hit nothing."""
        start, stop = self.panorama_camera.cast_rows
        return np.mean(self.panorama[:, start:stop] <= 0.0, axis=(1, 2))

    def _count_rays(self, count: int) -> None:
        with self._rays_lock:  # the shares of a step count from their threads
            self.rays_cast += count

    def draw(
        self,
        runtime: SceneRuntime,
        members: np.ndarray,
        escape: np.ndarray,
        threads: int,
        part: int | None = None,
        frames_start: Callable[[], None] | None = None,
    ) -> list[int]:
        """Draw agents of one scene (``members``, in increasing order) with one cast that
        carries their pinhole rays, their observation panorama rays and the first escape-check
        rays of the agents flagged in ``escape``; returns the agents whose move the escape
        check refuses.

        With the rasterizing pinhole backend the frames are rasterized (the single env's
        renderer) and the cast carries only the panorama rays.

        Args:
            runtime: the scene's runtime.
            members: the agents, in increasing order.
            escape: (len(members),) whose move the published escape rule must judge.
            threads: threads for the compiled loops (filling rays, shading).
            part: the share of a split step this runs as (its frames are drawn in the calling
                thread with that share's rasterizer), None for a step in one piece.
            frames_start: called once, as the frames start being drawn.
        """
        camera = self.camera
        count = len(members)
        pixels = camera.width * camera.height
        raster = getattr(runtime.renderer, "frame_backend", "raycast") == "raster"
        cast_pixels = 0 if raster else pixels
        poses32 = self.poses[members].astype(np.float32)
        positions32 = np.ascontiguousarray(poses32[:, :3, 3])
        checker = runtime.collision
        escapers = members[escape]
        first, order = escape_ray_plan(checker) if len(escapers) else (0, None)
        panorama = self.panorama_camera
        panorama_rays = len(panorama.cast_directions) if panorama is not None else 0
        escape_offset = count * (cast_pixels + panorama_rays)
        rays = np.empty((escape_offset + len(escapers) * first, 6), np.float32)
        if not raster:

            def fill(part: slice) -> None:
                fill_pinhole_rays(
                    camera.ray_directions, poses32[part], rays, (part.start or 0) * pixels
                )

            in_threads(fill, count, threads)
        if panorama is not None:
            fill_panorama_rays(panorama.cast_directions, positions32, rays, count * cast_pixels)
        if len(escapers):
            fill_panorama_rays(
                order[:first], np.ascontiguousarray(positions32[escape]), rays, escape_offset
            )
        if frames_start is not None:
            frames_start()
        hits = runtime.raycaster.cast_packed(rays) if len(rays) else None
        self._count_rays(len(rays))

        # Agents with consecutive indices (one scene, or a share of a split step) get their
        # frames drawn and coloured straight into the observation rows.
        rows = slice(int(members[0]), int(members[0]) + count)
        # Members come in increasing order: consecutive when they span exactly their count.
        in_place = raster and int(members[-1]) - int(members[0]) == count - 1
        if raster:
            frames = runtime.renderer.render_hits_many(
                self.poses[members],
                worker=part,
                depth_out=self.depth[rows] if in_place else None,
                barycentric_faces=runtime.scene.faces_needing_barycentrics,
            )
            depth = frames.depth.reshape(-1)
            triangle_ids, barycentric_uv = frames.triangle_ids, frames.barycentric_uv
        else:
            frame = slice(0, count * pixels)
            depth = hits.distance[frame].copy()
            # As RgbdRenderer: hits beyond the range are misses (depth 0, black).
            depth[~(depth <= self.max_depth_m)] = 0.0
            triangle_ids = np.where(depth > 0, hits.triangle_ids[frame], -1).astype(np.int32)
            barycentric_uv = hits.barycentric_uv[frame]
        rgb = (
            self.rgb[rows].reshape(-1, 3)
            if in_place
            else np.empty((len(triangle_ids), 3), np.uint8)
        )

        def shade(part: slice) -> None:
            pixels_of = slice((part.start or 0) * pixels, part.stop * pixels)
            runtime.scene.colour_at(
                triangle_ids[pixels_of], barycentric_uv[pixels_of], out=rgb[pixels_of]
            )

        in_threads(shade, count, threads)
        if not in_place:
            self.depth[members] = depth.reshape(count, camera.height, camera.width)
            self.rgb[members] = rgb.reshape(count, camera.height, camera.width, 3)
        if panorama is not None:
            distance = hits.distance[count * cast_pixels : escape_offset]
            start, stop = panorama.cast_rows
            cast = (
                np.where(np.isfinite(distance), distance, 0.0)
                .astype(np.float32)
                .reshape(count, stop - start, panorama.width)
            )
            if (start, stop) == (0, panorama.height):
                self.panorama[members] = cast
            else:  # the rows not cast read 0, as the single env's
                band = np.zeros((count, panorama.height, panorama.width), np.float32)
                band[:, start:stop] = cast
                self.panorama[members] = band
        if not len(escapers):
            return []
        total = len(order)
        threshold = checker.escape_no_hit_threshold
        misses = no_hit_counts(hits.distance, escape_offset, first, len(escapers))
        # Undecided: the rays not cast yet could still push the no-hit share over the limit.
        undecided = (total - first + misses) / total > threshold
        if not undecided.any():
            return []
        rest = order[first:]
        extra = np.empty((int(undecided.sum()) * len(rest), 6), np.float32)
        fill_panorama_rays(rest, np.ascontiguousarray(positions32[escape][undecided]), extra, 0)
        more = no_hit_counts(
            runtime.raycaster.cast_packed(extra).distance, 0, len(rest), int(undecided.sum())
        )
        self._count_rays(len(extra))
        shares = (misses[undecided] + more) / total
        return [int(a) for a in escapers[undecided][shares > threshold]]
