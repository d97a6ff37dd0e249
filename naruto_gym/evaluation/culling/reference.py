"""The culling rule applied the straightforward way: the oracle of the fast culling.

Every used pose in turn projects every vertex not seen yet and casts a ray (or reads a depth
image) for those in its frustum: the same result as :func:`~.mask.visible_vertex_mask`, far
slower on long trajectories. The tests compare the two, and ``benchmarks/metrics_speed.py``
times them side by side.
"""

from __future__ import annotations

import numpy as np

from naruto_gym.evaluation.culling.kernels import NEAR_Z
from naruto_gym.evaluation.culling.rule import checked_inputs, unoccluded
from naruto_gym.evaluation.culling.settings import (
    DEFAULT_CULL_DEPTH_SCALE,
    DEFAULT_CULL_EVERY,
    DEFAULT_DEPTH_MARGIN_M,
)
from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer


def visible_vertex_mask_reference(
    vertices: np.ndarray,
    poses: np.ndarray,
    camera: PinholeCamera,
    scene: Scene | RgbdRenderer,
    every: int = DEFAULT_CULL_EVERY,
    depth_margin_m: float = DEFAULT_DEPTH_MARGIN_M,
    depth_scale: float | None = DEFAULT_CULL_DEPTH_SCALE,
) -> np.ndarray:
    """:func:`visible_vertex_mask` the straightforward way: every used pose in turn projects
    every vertex not seen yet and casts a ray (or reads a depth image) for those in its
    frustum. Same result, far slower on long trajectories; kept as the oracle of the tests
    and the reference of ``benchmarks/metrics_speed.py``."""
    vertices, poses, renderer = checked_inputs(
        vertices, poses, camera, scene, every, depth_margin_m, depth_scale
    )
    image_camera = renderer.camera
    width, height = camera.width, camera.height
    seen = np.zeros(len(vertices), dtype=bool)
    for pose in poses[::every]:
        candidates = np.flatnonzero(~seen)
        if len(candidates) == 0:
            break
        rotation, position = pose[:3, :3], pose[:3, 3]
        points_camera = (vertices[candidates] - position) @ rotation
        pixels, z = camera.project(points_camera)
        in_frustum = (
            (z > NEAR_Z)
            & (pixels[:, 0] >= -0.5)
            & (pixels[:, 0] < width - 0.5)
            & (pixels[:, 1] >= -0.5)
            & (pixels[:, 1] < height - 0.5)
        )
        index = np.flatnonzero(in_frustum)
        if len(index) == 0:
            continue
        z = z[index]
        if depth_scale is None:
            directions = (points_camera[index] / z[:, None]) @ rotation.T
            surface_depth = renderer.raycaster.cast_distance(position, directions)
            surface_depth = np.where(np.isfinite(surface_depth), surface_depth, 0.0)
        else:
            image = renderer.render_depth(pose)
            scale_u, scale_v = image_camera.width / width, image_camera.height / height
            column = np.floor((pixels[index, 0] + 0.5) * scale_u).astype(np.int64)
            row = np.floor((pixels[index, 1] + 0.5) * scale_v).astype(np.int64)
            surface_depth = image[
                row.clip(0, image_camera.height - 1), column.clip(0, image_camera.width - 1)
            ]
        seen[candidates[index[unoccluded(z, surface_depth, depth_margin_m)]]] = True
    return seen
