"""Culling by rendered depth images, the literature's way: each vertex reads the pixel it
projects into.

Every used pose renders one ground-truth depth image (at a share of the camera resolution,
same field of view), and the vertices of the blocks its frustum can reach that are not seen
yet look up the depth there. It differs from the per-vertex rays of :mod:`.rays` only for
vertices within a pixel of a depth edge.
"""

from __future__ import annotations

import numpy as np
from tqdm.auto import tqdm

from naruto_gym.evaluation.culling.blocks import VertexBlocks, block_reach
from naruto_gym.evaluation.culling.kernels import frustum_members
from naruto_gym.evaluation.culling.rule import camera_intrinsics, unoccluded
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer


def depth_image_mask(
    blocks: VertexBlocks,
    seen: np.ndarray,
    first_pose: np.ndarray,
    poses: np.ndarray,
    camera: PinholeCamera,
    renderer: RgbdRenderer,
    depth_margin_m: float,
    progress: bool,
) -> None:
    """Rendered depth images, one pose after the other; updates ``seen`` (in ``blocks``'
    sorted order) in place. ``first_pose``: (V,) the first pose each vertex still has to
    try."""
    rotations = np.ascontiguousarray(poses[:, :3, :3])
    positions = np.ascontiguousarray(poses[:, :3, 3])
    reach = block_reach(blocks, rotations, positions, camera)
    image_camera = renderer.camera
    scale_u = image_camera.width / camera.width
    scale_v = image_camera.height / camera.height
    intrinsics = camera_intrinsics(camera)
    vertex = np.empty(len(seen), dtype=np.int64)
    z = np.empty(len(seen), dtype=np.float64)
    pixels = np.empty((len(seen), 2), dtype=np.float64)
    for k in tqdm(range(len(poses)), desc="culling", disable=not progress, leave=False):
        found = frustum_members(
            blocks.points,
            seen,
            first_pose,
            k,
            np.flatnonzero(reach[:, k]),
            blocks.vertex_start,
            rotations[k],
            positions[k],
            intrinsics,
            vertex,
            z,
            pixels,
        )
        if found == 0:
            continue
        image = renderer.render_depth(poses[k])
        column = np.floor((pixels[:found, 0] + 0.5) * scale_u).astype(np.int64)
        row = np.floor((pixels[:found, 1] + 0.5) * scale_v).astype(np.int64)
        surface_depth = image[
            row.clip(0, image_camera.height - 1), column.clip(0, image_camera.width - 1)
        ]
        seen[vertex[:found][unoccluded(z[:found], surface_depth, depth_margin_m)]] = True
