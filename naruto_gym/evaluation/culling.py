"""Mesh culling before evaluation: keep only what the trajectory could have seen.

The rule of the active-mapping literature (NARUTO, CVPR 2024, and the Co-SLAM evaluation it
follows): a reconstructed face is kept when at least one of its vertices lies inside the view
frustum of at least one pose of the trajectory (every 2nd pose by default) *and* is not
hidden, i.e. its z-depth is at most the ground-truth scene's depth along its line of sight plus
a margin (3 cm). Surfaces a mapper invents where the camera never looked (neural fields
extrapolate) are thereby not counted against its accuracy.

The ground-truth depth is ray-cast with Embree, not rasterised with OpenGL, in one of two ways:

* ``depth_scale=None`` (default): one ray per candidate vertex, from the camera centre through
  the vertex, so every vertex is compared with the ground-truth depth *exactly* along its own
  line of sight: the limit of an infinitely fine depth image. Only vertices inside the frustum
  and not yet found visible are cast, so a pose costs a few thousand rays once most of the
  mesh has been seen (measured on the Replica trajectory: a whole 2000-pose culling takes
  seconds, where rendering a full 680 x 1200 depth image per used pose took minutes).
* ``depth_scale=s`` in (0, 1]: the literature's way, a full depth image rendered by
  :class:`~naruto_gym.sensors.pinhole.RgbdRenderer` at ``s`` times the camera resolution
  (same field of view), each vertex reading the pixel it projects into. Kept for comparison;
  it differs from the per-vertex rays only for vertices within a pixel of a depth edge.

Lines of sight that hit nothing count as unoccluded.
"""

from __future__ import annotations

import numpy as np
from tqdm.auto import tqdm

from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer

DEFAULT_CULL_EVERY = 2
DEFAULT_DEPTH_MARGIN_M = 0.03
DEFAULT_CULL_DEPTH_SCALE: float | None = None


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


def _depth_renderer(scene: Scene | RgbdRenderer, camera: PinholeCamera) -> RgbdRenderer:
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
    depth_scale: float | None = DEFAULT_CULL_DEPTH_SCALE,
    progress: bool = False,
) -> np.ndarray:
    """Which vertices are in the frustum and unoccluded in at least one used pose.

    Args:
        vertices: (V, 3) reconstructed vertex positions, metres.
        poses: (N, 4, 4) camera-to-world poses of the trajectory (OpenCV camera axes).
        camera: intrinsics of the frames the trajectory took (defines the frustum).
        scene: ground-truth scene (or a renderer of it) that provides the occlusion depth.
        every: use every ``every``-th pose (poses 0, every, 2 * every, ...).
        depth_margin_m: a vertex up to this far behind the ground-truth depth still counts.
        depth_scale: None for one ray per vertex (exact, fast), or the resolution factor of
            a rendered depth image (see the module docstring).
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
    if depth_scale is not None and not 0.0 < depth_scale <= 1.0:
        raise ValueError(f"depth_scale must be None or in (0, 1], got {depth_scale}")
    if depth_margin_m < 0.0:
        raise ValueError(f"depth_margin_m must be >= 0, got {depth_margin_m}")
    image_camera = camera if depth_scale in (None, 1.0) else camera.scaled(depth_scale)
    renderer = _depth_renderer(scene, image_camera)
    width, height = camera.width, camera.height
    seen = np.zeros(len(vertices), dtype=bool)
    for pose in tqdm(poses[::every], desc="culling", disable=not progress, leave=False):
        # Vertices already seen cannot change the result: test only the rest.
        candidates = np.flatnonzero(~seen)
        if len(candidates) == 0:
            break
        rotation, position = pose[:3, :3], pose[:3, 3]
        points_camera = (vertices[candidates] - position) @ rotation
        pixels, z = camera.project(points_camera)
        # The frustum is the image's pixel area, [-0.5, W - 0.5) x [-0.5, H - 0.5).
        in_frustum = (
            (z > 1e-6)
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
            # Directions with camera z = 1: the hit distance is the surface's z-depth.
            directions = (points_camera[index] / z[:, None]) @ rotation.T
            surface_depth = renderer.raycaster.cast_distance(position, directions)
            surface_depth = np.where(np.isfinite(surface_depth), surface_depth, 0.0)
        else:
            image = renderer.render_depth(pose)
            scale_u = image_camera.width / width
            scale_v = image_camera.height / height
            column = np.floor((pixels[index, 0] + 0.5) * scale_u).astype(np.int64)
            row = np.floor((pixels[index, 1] + 0.5) * scale_v).astype(np.int64)
            surface_depth = image[
                row.clip(0, image_camera.height - 1), column.clip(0, image_camera.width - 1)
            ]
        unoccluded = (surface_depth <= 0.0) | (z <= surface_depth + depth_margin_m)
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
    depth_scale: float | None = DEFAULT_CULL_DEPTH_SCALE,
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
        depth_scale: None (default) for exact per-vertex rays, or the resolution factor of a
            rendered occlusion depth image.
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
