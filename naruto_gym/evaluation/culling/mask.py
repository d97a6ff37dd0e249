"""The fast culling: which vertices the trajectory could have seen, and the mesh cut to them.

:func:`visible_vertex_mask` applies the rule with one ray per (vertex, pose) pair
(:mod:`.rays`) or with rendered depth images (:mod:`.depth_image`), starting from what a
:class:`~.cache.CullingCache` learnt on the episode's earlier checkpoints;
:func:`cull_mesh` keeps the faces with a visible vertex.
"""

from __future__ import annotations

import numpy as np

from naruto_gym.evaluation.culling.blocks import vertex_blocks
from naruto_gym.evaluation.culling.cache import CullingCache
from naruto_gym.evaluation.culling.depth_image import depth_image_mask
from naruto_gym.evaluation.culling.rays import rays_mask
from naruto_gym.evaluation.culling.rule import checked_inputs
from naruto_gym.evaluation.culling.settings import (
    DEFAULT_CULL_DEPTH_SCALE,
    DEFAULT_CULL_EVERY,
    DEFAULT_DEPTH_MARGIN_M,
    DEFAULT_SETTINGS,
    CullingSettings,
)
from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer


def visible_vertex_mask(
    vertices: np.ndarray,
    poses: np.ndarray,
    camera: PinholeCamera,
    scene: Scene | RgbdRenderer,
    every: int = DEFAULT_CULL_EVERY,
    depth_margin_m: float = DEFAULT_DEPTH_MARGIN_M,
    depth_scale: float | None = DEFAULT_CULL_DEPTH_SCALE,
    progress: bool = False,
    cache: CullingCache | None = None,
    settings: CullingSettings = DEFAULT_SETTINGS,
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
            a rendered depth image (see :mod:`naruto_gym.evaluation.culling`).
        progress: show a progress bar.
        cache: a :class:`CullingCache` to reuse what an earlier call on the same episode
            learnt, and to fill for the next call.
        settings: how pairs are tried (speed only: the result is the same).

    Returns:
        (V,) bool mask.
    """
    vertices, poses, renderer = checked_inputs(
        vertices, poses, camera, scene, every, depth_margin_m, depth_scale
    )
    if len(vertices) == 0:
        return np.zeros(0, dtype=bool)
    used = np.ascontiguousarray(poses[::every])
    rule = (camera, every, float(depth_margin_m), depth_scale)
    seen, first_pose = np.zeros(len(vertices), bool), np.zeros(len(vertices), np.int64)
    if cache is not None:
        seen, first_pose = cache.prior(vertices, used, renderer.scene, rule)
    blocks = vertex_blocks(vertices, settings.block_size_m)
    seen_sorted = seen[blocks.order]
    first_sorted = first_pose[blocks.order]
    if depth_scale is None:
        rays_mask(
            blocks,
            seen_sorted,
            first_sorted,
            np.ascontiguousarray(used[:, :3, :3]),
            np.ascontiguousarray(used[:, :3, 3]),
            camera,
            renderer.raycaster,
            depth_margin_m,
            progress,
            settings,
        )
    else:
        depth_image_mask(
            blocks, seen_sorted, first_sorted, used, camera, renderer, depth_margin_m, progress
        )
    seen = np.empty(len(vertices), dtype=bool)
    seen[blocks.order] = seen_sorted
    if cache is not None:
        cache.store(vertices, used, renderer.scene, rule, seen)
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
    cache: CullingCache | None = None,
    settings: CullingSettings = DEFAULT_SETTINGS,
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
        cache: a :class:`~.cache.CullingCache` shared by the cullings of one episode.
        settings: how pairs are tried (speed only: the result is the same).

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
        vertices, poses, camera, scene, every, depth_margin_m, depth_scale, progress, cache,
        settings,
    )
    kept_faces = faces[seen[faces].any(axis=1)]
    used = np.unique(kept_faces)
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[kept_faces]
