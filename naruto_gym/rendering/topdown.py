"""The picture a person wants to see: a top-down map with the trajectory and camera, next to
the current RGB and depth.

The map is made once per scene by casting rays straight down from just under the ceiling, so
furniture tops and floors show in their colours and walls (rays that start inside them) in dark
grey. Drawing the trajectory is plain numpy, cheap enough for every frame.
"""

from __future__ import annotations

import numpy as np
from matplotlib import colormaps
from PIL import Image, ImageDraw

from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.sensors.raycaster import RayCaster

WALL_RGB = np.array([60, 60, 70], dtype=np.uint8)
TRAJECTORY_RGB = (230, 40, 40)
CAMERA_RGB = (20, 120, 255)
_DEPTH_LUT = (colormaps["turbo"](np.linspace(0.0, 1.0, 256))[:, :3] * 255).astype(np.uint8)


class TopDownMap:
    """A top-down orthographic picture of a scene and the world <-> pixel mapping."""

    def __init__(self, scene: Scene, raycaster: RayCaster, resolution_px: int = 480) -> None:
        bounds = scene.bounds
        extent = bounds[1, :2] - bounds[0, :2]
        self.metres_per_pixel = float(extent.max() / resolution_px)
        self.width = max(int(np.ceil(extent[0] / self.metres_per_pixel)), 1)
        self.height = max(int(np.ceil(extent[1] / self.metres_per_pixel)), 1)
        self.origin = bounds[0, :2]
        cut_z = bounds[0, 2] + 0.8 * (bounds[1, 2] - bounds[0, 2])
        columns, rows = np.meshgrid(np.arange(self.width), np.arange(self.height))
        xy = self.pixel_to_world(np.stack([columns.ravel(), rows.ravel()], axis=1))
        origins = np.concatenate([xy, np.full((len(xy), 1), cut_z)], axis=1).astype(np.float32)
        directions = np.tile(np.array([[0.0, 0.0, -1.0]], np.float32), (len(xy), 1))
        hits = raycaster.cast(origins, directions)
        image = np.full((len(xy), 3), 255, dtype=np.uint8)
        hit = hits.hit_mask
        image[hit] = scene.colour_at(hits.triangle_ids[hit], hits.barycentric_uv[hit])
        # A downward ray that hits a face whose normal points down started inside a solid.
        normal_z = scene.face_normals[np.maximum(hits.triangle_ids, 0), 2]
        height = np.where(hit, cut_z - hits.distance, bounds[0, 2])
        # Floors of files with flipped normals stay floors.
        image[hit & (normal_z < 0) & (height > bounds[0, 2] + 0.05)] = WALL_RGB
        # Shade by height so furniture stands out from the floor.
        relative_height = (height - bounds[0, 2]) / max(cut_z - bounds[0, 2], 1e-6)
        shade = 0.65 + 0.35 * np.clip(relative_height, 0.0, 1.0)
        image = (image * shade[:, None]).astype(np.uint8)
        self.image = image.reshape(self.height, self.width, 3)

    def world_to_pixel(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) world x, y -> (N, 2) float pixel (column, row); row 0 is the largest y."""
        columns = (xy[:, 0] - self.origin[0]) / self.metres_per_pixel
        rows = self.height - 1 - (xy[:, 1] - self.origin[1]) / self.metres_per_pixel
        return np.stack([columns, rows], axis=1)

    def pixel_to_world(self, pixels: np.ndarray) -> np.ndarray:
        x = self.origin[0] + (pixels[:, 0] + 0.5) * self.metres_per_pixel
        y = self.origin[1] + (self.height - 1 - pixels[:, 1] + 0.5) * self.metres_per_pixel
        return np.stack([x, y], axis=1)

    def draw(self, positions: np.ndarray, camera_to_world: np.ndarray | None) -> np.ndarray:
        """The map with a trajectory (K, 3) and the current camera drawn on it."""
        picture = Image.fromarray(self.image.copy())
        draw = ImageDraw.Draw(picture)
        if len(positions) > 1:
            points = [tuple(p) for p in self.world_to_pixel(np.asarray(positions)[:, :2])]
            draw.line(points, fill=TRAJECTORY_RGB, width=2)
        if camera_to_world is not None:
            centre = self.world_to_pixel(camera_to_world[None, :2, 3])[0]
            forward = camera_to_world[:2, 2]
            norm = np.linalg.norm(forward)
            if norm > 1e-6:
                tip = self.world_to_pixel((camera_to_world[:2, 3] + 0.5 * forward / norm)[None])[0]
                draw.line([tuple(centre), tuple(tip)], fill=CAMERA_RGB, width=3)
            radius = 5
            draw.ellipse(
                [centre[0] - radius, centre[1] - radius, centre[0] + radius, centre[1] + radius],
                fill=CAMERA_RGB,
            )
        return np.asarray(picture)


def colourise_depth(depth: np.ndarray, max_depth_m: float) -> np.ndarray:
    """(H, W) metres -> (H, W, 3) uint8 turbo colours; no-hit pixels black."""
    index = np.clip(depth / max(max_depth_m, 1e-6) * 255.0, 0, 255).astype(np.uint8)
    image = _DEPTH_LUT[index]
    image[depth <= 0] = 0
    return image


def compose_frame(
    top_down: np.ndarray, rgb: np.ndarray, depth: np.ndarray, max_depth_m: float
) -> np.ndarray:
    """Top-down map on the left, RGB above depth on the right, all at the map's height."""
    height = top_down.shape[0]
    half = height // 2
    width = max(int(round(rgb.shape[1] * half / rgb.shape[0])), 1)
    rgb_small = np.asarray(Image.fromarray(rgb).resize((width, half), Image.BILINEAR))
    depth_small = np.asarray(
        Image.fromarray(colourise_depth(depth, max_depth_m)).resize(
            (width, height - half), Image.NEAREST
        )
    )
    right = np.concatenate([rgb_small, depth_small], axis=0)
    return np.concatenate([top_down, right], axis=1)
