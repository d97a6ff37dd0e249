"""Pinhole RGB-D camera: intrinsics and the renderer that ray-casts a frame."""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.sensors.kernels import fill_world_rays
from naruto_gym.sensors.raycaster import RayCaster, RayHits


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


class RgbdRenderer:
    """Ray-casts pinhole RGB-D frames of a scene.

    Depth is z-depth in metres (float32), 0 where there is no hit or the hit lies beyond
    ``max_depth_m``; RGB is uint8 (H, W, 3), black where depth is 0.
    """

    def __init__(
        self,
        scene: Scene,
        camera: PinholeCamera | None = None,
        max_depth_m: float = 10.0,
        raycaster: RayCaster | None = None,
    ) -> None:
        self.scene = scene
        self.camera = camera or PinholeCamera()
        self.max_depth_m = float(max_depth_m)
        self.raycaster = raycaster or RayCaster(scene.vertices, scene.faces)

        self._rays = np.empty((self.camera.width * self.camera.height, 6), dtype=np.float32)

    def render_depth(self, camera_to_world: np.ndarray) -> np.ndarray:
        """(H, W) float32 z-depth only (skips colour)."""
        return self._cast(camera_to_world)[0]

    def render(self, camera_to_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rgb (H, W, 3) uint8, depth (H, W) float32) at a camera-to-world pose."""
        depth, hits = self._cast(camera_to_world)
        # Pixels beyond the range are black like misses.
        triangle_ids = np.where(depth.ravel() > 0, hits.triangle_ids, -1)
        rgb = self.scene.colour_at(triangle_ids, hits.barycentric_uv)
        return rgb.reshape(self.camera.height, self.camera.width, 3), depth

    def _cast(self, camera_to_world: np.ndarray) -> tuple[np.ndarray, RayHits]:
        pose = np.asarray(camera_to_world, dtype=np.float32)
        # Directions keep camera z = 1, so the ray parameter of a hit is its z-depth.
        fill_world_rays(
            self.camera.ray_directions,
            np.ascontiguousarray(pose[:3, :3]),
            np.ascontiguousarray(pose[:3, 3]),
            self._rays,
        )
        hits = self.raycaster.cast_packed(self._rays)
        depth = hits.distance.copy()
        depth[~(depth <= self.max_depth_m)] = 0.0
        return depth.reshape(self.camera.height, self.camera.width), hits
