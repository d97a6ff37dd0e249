"""Culling by one occlusion ray per (vertex, pose) pair, each along the vertex's own line of sight.

The result is the OR over pairs, so the order in which pairs are tried cannot change it, only
how many rays are cast. To keep that number low on long trajectories:

* vertices are grouped into spatial blocks and a block only visits the poses whose frustum can
  reach it, nearest first (:mod:`.blocks`, compiled loops in :mod:`.kernels`);
* coarse depth images of every used pose tell which in-frustum pairs are *likely*
  unoccluded; every vertex first tries those, a few pairs per round, with the rays of all
  vertices and poses of a round cast together, each from its own camera centre;
* only the vertices no likely pair showed go on to the unlikely pairs, which must all be cast
  before a vertex is declared hidden.

A vertex no pose sees is the costly case: it must try every pose that has it in its frustum.
The block size, guide images and batch sizes are :class:`~.settings.CullingSettings`.
"""

from __future__ import annotations

import numpy as np
from tqdm.auto import tqdm

from naruto_gym.evaluation.culling.blocks import VertexBlocks, block_reach
from naruto_gym.evaluation.culling.kernels import emit_pairs, guide_rays
from naruto_gym.evaluation.culling.rule import camera_intrinsics, unoccluded
from naruto_gym.evaluation.culling.settings import CullingSettings
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.sensors.raycaster import RayCaster


def _guide_depth(
    raycaster: RayCaster,
    rotations: np.ndarray,
    positions: np.ndarray,
    camera: PinholeCamera,
    settings: CullingSettings,
) -> np.ndarray:
    """(K, h, w) float32 coarse z-depth images of every pose (0 where nothing was hit)."""
    guide_camera = camera.scaled(min(1.0, settings.guide_width_px / camera.width))
    rows, columns = np.mgrid[0 : guide_camera.height, 0 : guide_camera.width]
    directions = np.stack(
        [
            (columns.ravel() - guide_camera.cx) / guide_camera.fx,
            (rows.ravel() - guide_camera.cy) / guide_camera.fy,
            np.ones(rows.size),
        ],
        axis=1,
    )
    guide = np.empty((len(rotations), rows.size), dtype=np.float32)
    poses_per_cast = max(settings.max_rays_per_cast // rows.size, 1)
    for first in range(0, len(rotations), poses_per_cast):
        chunk = slice(first, first + poses_per_cast)
        rays = np.empty((len(rotations[chunk]) * rows.size, 6), dtype=np.float32)
        guide_rays(rotations[chunk], positions[chunk], directions, rays)
        distance = raycaster.cast_packed(rays).distance.reshape(-1, rows.size)
        guide[chunk] = np.where(np.isfinite(distance), distance, 0.0)
    return guide.reshape(len(rotations), guide_camera.height, guide_camera.width)


def rays_mask(
    blocks: VertexBlocks,
    seen: np.ndarray,
    first_pose: np.ndarray,
    rotations: np.ndarray,
    positions: np.ndarray,
    camera: PinholeCamera,
    raycaster: RayCaster,
    depth_margin_m: float,
    progress: bool,
    settings: CullingSettings,
) -> None:
    """Per-vertex rays, pairs tried in rounds (see the module docstring); updates ``seen``
    (in ``blocks``' sorted order) in place. ``first_pose``: (V,) the first pose each vertex
    still has to try."""
    reach = block_reach(blocks, rotations, positions, camera)
    block_of_pair, pose_of_pair = np.nonzero(reach)
    block_start = np.searchsorted(block_of_pair, np.arange(len(blocks.centres) + 1))
    # Each block lists its poses nearest first: a near pose is the likeliest to be in the
    # same room (the order cannot change the result, only how soon a vertex is seen).
    if settings.order_poses_by_distance:
        distance = np.linalg.norm(blocks.centres[block_of_pair] - positions[pose_of_pair], axis=1)
        pose_of_pair = pose_of_pair[np.lexsort((distance, block_of_pair))]
    block_poses = pose_of_pair.astype(np.int64)
    list_length = np.diff(block_start)[blocks.vertex_block]
    pending = ~seen & (list_length > 0)
    if not pending.any():
        return
    guide = _guide_depth(raycaster, rotations, positions, camera, settings)
    slack = np.array([depth_margin_m, settings.guide_slack_m, settings.guide_slack_share])
    intrinsics = camera_intrinsics(camera)
    cursor = np.zeros(len(seen), dtype=np.int64)
    bar = tqdm(total=int(pending.sum()), desc="culling", disable=not progress, leave=False)
    for want_likely, per_vertex, most in (
        (True, 1, settings.max_likely_per_round),
        (False, 8, settings.max_unlikely_per_round),
    ):
        cursor[:] = 0
        active = np.flatnonzero(pending & ~seen)
        while len(active):
            per_vertex = max(1, min(per_vertex, settings.max_rays_per_cast // len(active)))
            chunk_size = max(settings.max_rays_per_cast // per_vertex, 1)
            for first in range(0, len(active), chunk_size):
                chunk = active[first : first + chunk_size]
                capacity = len(chunk) * per_vertex
                vertex = np.empty(capacity, dtype=np.int64)
                z = np.empty(capacity, dtype=np.float64)
                rays = np.empty((capacity, 6), dtype=np.float32)
                count = emit_pairs(
                    blocks.points,
                    chunk,
                    cursor,
                    first_pose,
                    blocks.vertex_block,
                    block_start,
                    block_poses,
                    rotations,
                    positions,
                    intrinsics,
                    guide,
                    slack,
                    want_likely,
                    per_vertex,
                    vertex,
                    z,
                    rays,
                )
                if count:
                    distance = raycaster.cast_packed(rays[:count]).distance
                    surface_depth = np.where(np.isfinite(distance), distance, 0.0)
                    hit = unoccluded(z[:count], surface_depth, depth_margin_m)
                    seen[vertex[:count][hit]] = True
            unseen = ~seen[active]
            left = active[unseen & (cursor[active] < list_length[active])]
            # Resolved: seen, or (after the unlikely pairs) hidden from every pose.
            bar.update(len(active) - (len(left) if not want_likely else int(unseen.sum())))
            active = left
            per_vertex = min(2 * per_vertex, most)
    bar.close()
