"""The parts of the culling rule every way of applying it shares.

Validated inputs and the renderer of the ground-truth occlusion depth (:func:`checked_inputs`),
the intrinsics as the compiled loops take them (:func:`camera_intrinsics`) and the occlusion
verdict of a (vertex, pose) pair (:func:`unoccluded`): a vertex counts when nothing was hit
along its line of sight or it lies at most the margin behind the surface hit.
"""

from __future__ import annotations

import numpy as np

from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer


def _check_poses(poses: np.ndarray) -> np.ndarray:
    """(N, 4, 4) float64 camera-to-world poses (one (4, 4) pose becomes a batch of one)."""
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim == 2 and poses.shape == (4, 4):
        poses = poses[None]
    if poses.ndim != 3 or poses.shape[1:] != (4, 4) or len(poses) == 0:
        raise ValueError(
            f"poses must be a non-empty (N, 4, 4) array of camera-to-world matrices, "
            f"got shape {poses.shape}"
        )
    if not np.isfinite(poses).all():
        raise ValueError("poses contain NaN or infinite values")
    return poses


def _depth_renderer(scene: Scene | RgbdRenderer, camera: PinholeCamera) -> RgbdRenderer:
    """A renderer of the ground truth with an infinite range: it marks misses (and only
    misses) with depth 0."""
    if isinstance(scene, RgbdRenderer):
        return RgbdRenderer(scene.scene, camera, max_depth_m=np.inf, raycaster=scene.raycaster)
    if isinstance(scene, Scene):
        return RgbdRenderer(scene, camera, max_depth_m=np.inf)
    raise ValueError(
        f"scene must be the ground-truth Scene or an RgbdRenderer of it, got {type(scene).__name__}"
    )


def checked_inputs(
    vertices: np.ndarray,
    poses: np.ndarray,
    camera: PinholeCamera,
    scene: Scene | RgbdRenderer,
    every: int,
    depth_margin_m: float,
    depth_scale: float | None,
) -> tuple[np.ndarray, np.ndarray, RgbdRenderer]:
    """Validated vertices and poses, and the renderer of the occlusion depth."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"vertices must have shape (V, 3), got {vertices.shape}")
    poses = _check_poses(poses)
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    if depth_scale is not None and not 0.0 < depth_scale <= 1.0:
        raise ValueError(f"depth_scale must be None or in (0, 1], got {depth_scale}")
    if depth_margin_m < 0.0:
        raise ValueError(f"depth_margin_m must be >= 0, got {depth_margin_m}")
    if not np.isfinite(vertices).all():
        raise ValueError("vertices contain NaN or infinite coordinates; remove them first")
    image_camera = camera if depth_scale in (None, 1.0) else camera.scaled(depth_scale)
    return vertices, poses, _depth_renderer(scene, image_camera)


def camera_intrinsics(camera: PinholeCamera) -> np.ndarray:
    """(6,) float64 ``(width, height, fx, fy, cx, cy)``, as the compiled loops take them."""
    return np.array(
        [camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy], np.float64
    )


def unoccluded(z: np.ndarray, surface_depth: np.ndarray, depth_margin_m: float) -> np.ndarray:
    """The occlusion verdict of tested pairs, given the ground-truth depth (0: no hit)."""
    return (surface_depth <= 0.0) | (z <= surface_depth + depth_margin_m)
