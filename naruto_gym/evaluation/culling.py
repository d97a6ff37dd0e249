"""Mesh culling before evaluation: keep only what the trajectory could have seen.

The rule of the active-mapping literature (NARUTO, CVPR 2024, and the Co-SLAM evaluation it
follows): a reconstructed face is kept when at least one of its vertices lies inside the view
frustum of at least one pose of the trajectory (every 2nd pose by default) *and* is not
hidden, i.e. its z-depth is at most the ground-truth scene's rendered depth at its pixel plus a
margin (3 cm). Surfaces a mapper invents where the camera never looked (neural fields
extrapolate) are thereby not counted against its accuracy.

The ground-truth depth is ray-cast (Embree through :class:`~naruto_gym.sensors.pinhole.
RgbdRenderer`), not rasterised with OpenGL. For speed it is rendered at ``depth_scale`` times
the camera resolution (0.5 by default: a quarter of the rays, same field of view); a vertex
reads the depth of the low-resolution pixel it projects into. This changes the decision only
for vertices within a pixel of a depth edge, and the 3 cm margin absorbs most of those.
Pixels where the ground-truth ray hits nothing count as unoccluded.
"""

from __future__ import annotations

import numpy as np
from tqdm.auto import tqdm

from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer

DEFAULT_CULL_EVERY = 2
DEFAULT_DEPTH_MARGIN_M = 0.03
DEFAULT_CULL_DEPTH_SCALE = 0.5


def _check_poses(poses: np.ndarray) -> np.ndarray:
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


def _depth_renderer(
    scene: Scene | RgbdRenderer, camera: PinholeCamera
) -> RgbdRenderer:
    # An infinite range: the renderer marks misses (and only misses) with depth 0.
    if isinstance(scene, RgbdRenderer):
        return RgbdRenderer(scene.scene, camera, max_depth_m=np.inf, raycaster=scene.raycaster)
    if isinstance(scene, Scene):
        return RgbdRenderer(scene, camera, max_depth_m=np.inf)
    raise ValueError(
        "scene must be the ground-truth Scene or an RgbdRenderer of it, "
        f"got {type(scene).__name__}"
    )


def visible_vertex_mask(
    vertices: np.ndarray,
    poses: np.ndarray,
    camera: PinholeCamera,
    scene: Scene | RgbdRenderer,
    every: int = DEFAULT_CULL_EVERY,
    depth_margin_m: float = DEFAULT_DEPTH_MARGIN_M,
    depth_scale: float = DEFAULT_CULL_DEPTH_SCALE,
    progress: bool = False,
) -> np.ndarray:
    """Which vertices are in the frustum and unoccluded in at least one used pose.

    Args:
        vertices: (V, 3) reconstructed vertex positions, metres.
        poses: (N, 4, 4) camera-to-world poses of the trajectory (OpenCV camera axes).
        camera: intrinsics of the frames the trajectory took.
        scene: ground-truth scene (or a renderer of it) that provides the occlusion depth.
        every: use every ``every``-th pose (poses 0, every, 2 * every, ...).
        depth_margin_m: a vertex up to this far behind the rendered depth still counts.
        depth_scale: resolution factor of the occlusion depth render (see module docstring).
        progress: show a progress bar.

    Returns:
        (V,) bool mask.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"vertices must have shape (V, 3), got {vertices.shape}")
    poses = _check_poses(poses)
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    if not 0.0 < depth_scale <= 1.0:
        raise ValueError(f"depth_scale must be in (0, 1], got {depth_scale}")
    if depth_margin_m < 0.0:
        raise ValueError(f"depth_margin_m must be >= 0, got {depth_margin_m}")
    cull_camera = camera if depth_scale == 1.0 else camera.scaled(depth_scale)
    renderer = _depth_renderer(scene, cull_camera)
    width, height = cull_camera.width, cull_camera.height
    seen = np.zeros(len(vertices), dtype=bool)
    for pose in tqdm(poses[::every], desc="culling", disable=not progress, leave=False):
        # Vertices already seen cannot change the result: test only the rest.
        candidates = np.flatnonzero(~seen)
        if len(candidates) == 0:
            break
        rotation, position = pose[:3, :3], pose[:3, 3]
        points_camera = (vertices[candidates] - position) @ rotation
        pixels, z = cull_camera.project(points_camera)
        column = np.floor(pixels[:, 0] + 0.5)
        row = np.floor(pixels[:, 1] + 0.5)
        in_frustum = (z > 1e-6) & (column >= 0) & (column < width) & (row >= 0) & (row < height)
        if not in_frustum.any():
            continue
        index = np.flatnonzero(in_frustum)
        depth = renderer.render_depth(pose)
        pixel_depth = depth[row[index].astype(np.int64), column[index].astype(np.int64)]
        unoccluded = (pixel_depth <= 0.0) | (z[index] <= pixel_depth + depth_margin_m)
        seen[candidates[index[unoccluded]]] = True
    return seen


def cull_mesh(
    vertices: np.ndarray,
    faces: np.ndarray,
    poses: np.ndarray,
    camera: PinholeCamera,
    scene: Scene | RgbdRenderer,
    every: int = DEFAULT_CULL_EVERY,
    depth_margin_m: float = DEFAULT_DEPTH_MARGIN_M,
    depth_scale: float = DEFAULT_CULL_DEPTH_SCALE,
    progress: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Remove the reconstructed faces that no pose of the trajectory could have seen.

    A face survives when one of its vertices passes :func:`visible_vertex_mask`.

    Args:
        vertices: (V, 3) reconstructed vertices, metres.
        faces: (F, 3) triangle indices.
        poses: (N, 4, 4) camera-to-world poses of the trajectory.
        camera: intrinsics of the trajectory's frames.
        scene: ground-truth scene (or an ``RgbdRenderer`` of it) for the occlusion depth.
        every: use every ``every``-th pose (2 as in the literature).
        depth_margin_m: occlusion margin (3 cm as in the literature).
        depth_scale: resolution factor of the occlusion render (0.5 by default, for speed).
        progress: show a progress bar.

    Returns:
        (vertices, faces) of the kept part, unreferenced vertices dropped and faces
        re-indexed; faces may be empty when nothing was visible.
    """
    faces = np.asarray(faces, dtype=np.int64)
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"faces must have shape (F, 3), got {faces.shape}")
    vertices = np.asarray(vertices, dtype=np.float64)
    if len(faces) and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise ValueError(f"face indices out of range for {len(vertices)} vertices")
    seen = visible_vertex_mask(
        vertices, poses, camera, scene, every, depth_margin_m, depth_scale, progress
    )
    kept_faces = faces[seen[faces].any(axis=1)]
    used = np.unique(kept_faces)
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[kept_faces]
