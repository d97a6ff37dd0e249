"""Mesh culling before evaluation: keep only what the trajectory could have seen.

The rule of the active-mapping literature (NARUTO, CVPR 2024, and the Co-SLAM evaluation it
follows): a reconstructed face is kept when at least one of its vertices lies inside the view
frustum of at least one pose of the trajectory (every 2nd pose by default) *and* is not
hidden, i.e. its z-depth is at most the ground-truth scene's depth along its line of sight plus
a margin (3 cm). Surfaces a mapper invents where the camera never looked (neural fields
extrapolate) are thereby not counted against its accuracy.

The ground-truth depth is ray-cast with Embree, not rasterised with OpenGL, in one of two ways:

* ``depth_scale=None`` (default): one ray per tested (vertex, pose) pair, from the camera
  centre through the vertex, so every vertex is compared with the ground-truth depth
  *exactly* along its own line of sight: the limit of an infinitely fine depth image.
* ``depth_scale=s`` in (0, 1]: the literature's way, a full depth image rendered by
  :class:`~naruto_gym.sensors.pinhole.RgbdRenderer` at ``s`` times the camera resolution
  (same field of view), each vertex reading the pixel it projects into. Kept for comparison;
  it differs from the per-vertex rays only for vertices within a pixel of a depth edge.

Lines of sight that hit nothing count as unoccluded.

How the per-vertex rays stay cheap on long trajectories (the result is the OR over pairs, so
the order in which pairs are tried cannot change it, only how many rays are cast):

* vertices are grouped into 50 cm blocks and a block only visits the poses whose frustum can
  reach it, nearest first (compiled loops in :mod:`.culling_kernels`);
* coarse depth images of every used pose (48 pixels wide) tell which in-frustum pairs are
  *likely* unoccluded; every vertex first tries those, a few pairs per round, with the rays
  of all vertices and poses of a round cast together, each from its own camera centre;
* only the vertices no likely pair showed go on to the unlikely pairs, which must all be cast
  before a vertex is declared hidden.

On a 2000-step frontier episode on the apartment (1.5 M vertices, 1001 used poses) this casts
11 M rays (1.3 M of them for the coarse images, 5 M for the 33 k vertices no pose sees, which
must try every pose that has them in its frustum) where trying every in-frustum pose in pose
order casts 115 M. A :class:`CullingCache` carries what one call learnt to the next call on a
longer trajectory (the benchmark's checkpoints): a vertex at a bit-identical position keeps
its verdict for the poses already tried.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from tqdm.auto import tqdm

from naruto_gym.evaluation.culling_kernels import (
    NEAR_Z,
    block_pose_reach,
    build_position_table,
    emit_pairs,
    find_positions,
    frustum_members,
    guide_rays,
)
from naruto_gym.scenes.mesh_scene import Scene
from naruto_gym.sensors.pinhole import PinholeCamera, RgbdRenderer
from naruto_gym.sensors.raycaster import RayCaster

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


# Side of the spatial blocks that share one list of reachable poses (metres).
BLOCK_SIZE_M = 0.5
# Width of the coarse guide depth images, pixels (never more than the camera's).
GUIDE_WIDTH_PX = 48
# A pair is likely unoccluded when z <= guide depth + margin + 5 cm + 5 % of z.
GUIDE_SLACK_M = 0.05
GUIDE_SLACK_SHARE = 0.05
ORDER_POSES_BY_DISTANCE = True
# Rays cast together at most (48 MiB of float32 rays).
MAX_RAYS_PER_CAST = 1 << 21
# Pairs a vertex may emit per round: the likely ones double from 1 up to the first number,
# the unlikely ones (hidden vertices have to try them all) from 8 up to the second.
MAX_LIKELY_PER_ROUND = 8
MAX_UNLIKELY_PER_ROUND = 512
# Block spheres are inflated by this much before the frustum test (metres): far above the
# rounding error of the exact per-vertex test, so no pair the exact test keeps is dropped.
_REACH_SLACK_M = 1e-4


def _depth_renderer(scene: Scene | RgbdRenderer, camera: PinholeCamera) -> RgbdRenderer:
    # An infinite range: the renderer marks misses (and only misses) with depth 0.
    if isinstance(scene, RgbdRenderer):
        return RgbdRenderer(scene.scene, camera, max_depth_m=np.inf, raycaster=scene.raycaster)
    if isinstance(scene, Scene):
        return RgbdRenderer(scene, camera, max_depth_m=np.inf)
    raise ValueError(
        f"scene must be the ground-truth Scene or an RgbdRenderer of it, got {type(scene).__name__}"
    )


def _checked(
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


def _intrinsics(camera: PinholeCamera) -> np.ndarray:
    return np.array(
        [camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy], np.float64
    )


def _frustum_planes(camera: PinholeCamera) -> np.ndarray:
    """Unit normals (camera frame) of the planes bounding the frustum: in front of the
    camera, and the four sides through the outer edges of the border pixels."""
    planes = np.array(
        [
            [0.0, 0.0, 1.0],
            [camera.fx, 0.0, camera.cx + 0.5],
            [-camera.fx, 0.0, camera.width - 0.5 - camera.cx],
            [0.0, camera.fy, camera.cy + 0.5],
            [0.0, -camera.fy, camera.height - 0.5 - camera.cy],
        ]
    )
    return planes / np.linalg.norm(planes, axis=1, keepdims=True)


@dataclass(frozen=True)
class _Blocks:
    """Vertices sorted into spatial blocks.

    Attributes:
        order: (V,) original index of each sorted vertex.
        points: (V, 3) the sorted vertices.
        vertex_block: (V,) block of each sorted vertex.
        vertex_start: (B + 1,) first sorted vertex of each block.
        centres, radii: (B, 3) and (B,) bounding spheres.
    """

    order: np.ndarray
    points: np.ndarray
    vertex_block: np.ndarray
    vertex_start: np.ndarray
    centres: np.ndarray
    radii: np.ndarray


def _blocks(vertices: np.ndarray, size_m: float = BLOCK_SIZE_M) -> _Blocks:
    cells = np.floor(vertices / size_m).astype(np.int64)
    cells -= cells.min(axis=0)
    extent = cells.max(axis=0) + 1
    keys = (cells[:, 0] * extent[1] + cells[:, 1]) * extent[2] + cells[:, 2]
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    vertex_block = np.concatenate([[0], np.cumsum(sorted_keys[1:] != sorted_keys[:-1])])
    points = np.ascontiguousarray(vertices[order])
    vertex_start = np.concatenate([[0], np.cumsum(np.bincount(vertex_block))])
    lower = np.minimum.reduceat(points, vertex_start[:-1], axis=0)
    upper = np.maximum.reduceat(points, vertex_start[:-1], axis=0)
    centres = 0.5 * (lower + upper)
    distance = np.linalg.norm(points - centres[vertex_block], axis=1)
    radii = np.maximum.reduceat(distance, vertex_start[:-1])
    return _Blocks(order, points, vertex_block, vertex_start, centres, radii)


def _block_reach(
    blocks: _Blocks, rotations: np.ndarray, positions: np.ndarray, camera: PinholeCamera
) -> np.ndarray:
    """(B, K) bool: which poses' frustums can hold a vertex of which block."""
    reach = np.empty((len(blocks.centres), len(rotations)), dtype=bool)
    block_pose_reach(
        blocks.centres,
        blocks.radii,
        rotations,
        positions,
        _frustum_planes(camera),
        _REACH_SLACK_M,
        reach,
    )
    return reach


def _guide_depth(
    raycaster: RayCaster, rotations: np.ndarray, positions: np.ndarray, camera: PinholeCamera
) -> np.ndarray:
    """(K, h, w) float32 coarse z-depth images of every pose (0 where nothing was hit)."""
    guide_camera = camera.scaled(min(1.0, GUIDE_WIDTH_PX / camera.width))
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
    poses_per_cast = max(MAX_RAYS_PER_CAST // rows.size, 1)
    for first in range(0, len(rotations), poses_per_cast):
        chunk = slice(first, first + poses_per_cast)
        rays = np.empty((len(rotations[chunk]) * rows.size, 6), dtype=np.float32)
        guide_rays(rotations[chunk], positions[chunk], directions, rays)
        distance = raycaster.cast_packed(rays).distance.reshape(-1, rows.size)
        guide[chunk] = np.where(np.isfinite(distance), distance, 0.0)
    return guide.reshape(len(rotations), guide_camera.height, guide_camera.width)


def _unoccluded(z: np.ndarray, surface_depth: np.ndarray, depth_margin_m: float) -> np.ndarray:
    """The occlusion verdict of tested pairs, given the ground-truth depth (0: no hit)."""
    return (surface_depth <= 0.0) | (z <= surface_depth + depth_margin_m)


def _rays_mask(
    blocks: _Blocks,
    seen: np.ndarray,
    first_pose: np.ndarray,
    rotations: np.ndarray,
    positions: np.ndarray,
    camera: PinholeCamera,
    raycaster: RayCaster,
    depth_margin_m: float,
    progress: bool,
) -> None:
    """Per-vertex rays, pairs tried in rounds (see the module docstring); updates ``seen``
    (sorted order) in place."""
    reach = _block_reach(blocks, rotations, positions, camera)
    block_of_pair, pose_of_pair = np.nonzero(reach)
    block_start = np.searchsorted(block_of_pair, np.arange(len(blocks.centres) + 1))
    # Each block lists its poses nearest first: a near pose is the likeliest to be in the
    # same room (the order cannot change the result, only how soon a vertex is seen).
    if ORDER_POSES_BY_DISTANCE:
        distance = np.linalg.norm(blocks.centres[block_of_pair] - positions[pose_of_pair], axis=1)
        pose_of_pair = pose_of_pair[np.lexsort((distance, block_of_pair))]
    block_poses = pose_of_pair.astype(np.int64)
    list_length = np.diff(block_start)[blocks.vertex_block]
    pending = ~seen & (list_length > 0)
    if not pending.any():
        return
    guide = _guide_depth(raycaster, rotations, positions, camera)
    slack = np.array([depth_margin_m, GUIDE_SLACK_M, GUIDE_SLACK_SHARE])
    intrinsics = _intrinsics(camera)
    cursor = np.zeros(len(seen), dtype=np.int64)
    bar = tqdm(total=int(pending.sum()), desc="culling", disable=not progress, leave=False)
    for want_likely, per_vertex, most in (
        (True, 1, MAX_LIKELY_PER_ROUND),
        (False, 8, MAX_UNLIKELY_PER_ROUND),
    ):
        cursor[:] = 0
        active = np.flatnonzero(pending & ~seen)
        while len(active):
            per_vertex = max(1, min(per_vertex, MAX_RAYS_PER_CAST // len(active)))
            chunk_size = max(MAX_RAYS_PER_CAST // per_vertex, 1)
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
                    hit = _unoccluded(z[:count], surface_depth, depth_margin_m)
                    seen[vertex[:count][hit]] = True
            unseen = ~seen[active]
            left = active[unseen & (cursor[active] < list_length[active])]
            # Resolved: seen, or (after the unlikely pairs) hidden from every pose.
            bar.update(len(active) - (len(left) if not want_likely else int(unseen.sum())))
            active = left
            per_vertex = min(2 * per_vertex, most)
    bar.close()


def _depth_image_mask(
    blocks: _Blocks,
    seen: np.ndarray,
    first_pose: np.ndarray,
    poses: np.ndarray,
    camera: PinholeCamera,
    renderer: RgbdRenderer,
    depth_margin_m: float,
    progress: bool,
) -> None:
    """Rendered depth images, one pose after the other; updates ``seen`` (sorted order)."""
    rotations = np.ascontiguousarray(poses[:, :3, :3])
    positions = np.ascontiguousarray(poses[:, :3, 3])
    reach = _block_reach(blocks, rotations, positions, camera)
    image_camera = renderer.camera
    scale_u = image_camera.width / camera.width
    scale_v = image_camera.height / camera.height
    intrinsics = _intrinsics(camera)
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
        seen[vertex[:found][_unoccluded(z[:found], surface_depth, depth_margin_m)]] = True


def _coordinate_hash(vertices: np.ndarray) -> np.ndarray:
    """(V,) uint64 hash of each vertex's exact float64 coordinates."""
    bits = np.ascontiguousarray(vertices, dtype=np.float64).view(np.uint64)
    # Wrapping multiplications by large odd constants mix the three coordinates' bits.
    return (
        bits[:, 0] * np.uint64(0x9E3779B97F4A7C15)
        ^ bits[:, 1] * np.uint64(0xC2B2AE3D27D4EB4F)
        ^ bits[:, 2] * np.uint64(0x165667B19E3779F9)
    )


class CullingCache:
    """What one culling learnt, for the next culling along a longer trajectory.

    The verdict of a vertex depends only on its position, the ground truth, the camera, the
    margin and the used poses. When the next call has the same settings and its used poses
    start with the ones tried before (an episode that went on), a vertex at a bit-identical
    position (TSDF meshes keep most vertices between checkpoints) is known seen, or only has
    to try the new poses. Anything else (other settings, other poses) starts from scratch.

    Pass one to :func:`visible_vertex_mask` (or ``cull_cache=`` of the scoring functions);
    :class:`~naruto_gym.evaluation.scoring.EpisodeReconstruction` keeps one per episode.
    """

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """Forget everything."""
        self._settings: tuple | None = None
        self._scene: Scene | None = None
        self._poses: np.ndarray | None = None
        self._vertices: np.ndarray | None = None
        self._keys: np.ndarray | None = None
        self._table: np.ndarray | None = None
        self._bits = 0
        self._seen: np.ndarray | None = None

    def prior(
        self, vertices: np.ndarray, used_poses: np.ndarray, scene: Scene, settings: tuple
    ) -> tuple[np.ndarray, np.ndarray]:
        """(seen, first_pose): vertices known seen, and the first used pose each still has
        to try (0 for a vertex the cache knows nothing about)."""
        seen = np.zeros(len(vertices), dtype=bool)
        first_pose = np.zeros(len(vertices), dtype=np.int64)
        known = self._poses
        if (
            known is None
            or self._scene is not scene
            or self._settings != settings
            or len(known) > len(used_poses)
            or not np.array_equal(used_poses[: len(known)], known)
            or len(self._vertices) == 0
        ):
            return seen, first_pose
        keys = _coordinate_hash(vertices)
        match = np.empty(len(vertices), dtype=np.int64)
        find_positions(self._table, self._bits, self._vertices, self._keys, vertices, keys, match)
        same = match >= 0
        seen[same] = self._seen[match[same]]
        first_pose[same & ~seen] = len(known)
        return seen, first_pose

    def store(
        self,
        vertices: np.ndarray,
        used_poses: np.ndarray,
        scene: Scene,
        settings: tuple,
        seen: np.ndarray,
    ) -> None:
        """Remember the verdicts of one call."""
        self._keys = _coordinate_hash(vertices)
        # A table at most half full keeps the probe sequences short.
        self._bits = max(int(np.ceil(np.log2(2 * len(vertices) + 1))), 4)
        self._table = build_position_table(self._keys, self._bits)
        self._vertices = vertices.copy()
        self._seen = seen.copy()
        self._poses = used_poses.copy()
        self._scene = scene
        self._settings = settings


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
        cache: a :class:`CullingCache` to reuse what an earlier call on the same episode
            learnt, and to fill for the next call.

    Returns:
        (V,) bool mask.
    """
    vertices, poses, renderer = _checked(
        vertices, poses, camera, scene, every, depth_margin_m, depth_scale
    )
    if len(vertices) == 0:
        return np.zeros(0, dtype=bool)
    used = np.ascontiguousarray(poses[::every])
    settings = (camera, every, float(depth_margin_m), depth_scale)
    seen, first_pose = np.zeros(len(vertices), bool), np.zeros(len(vertices), np.int64)
    if cache is not None:
        seen, first_pose = cache.prior(vertices, used, renderer.scene, settings)
    blocks = _blocks(vertices)
    seen_sorted = seen[blocks.order]
    first_sorted = first_pose[blocks.order]
    if depth_scale is None:
        _rays_mask(
            blocks,
            seen_sorted,
            first_sorted,
            np.ascontiguousarray(used[:, :3, :3]),
            np.ascontiguousarray(used[:, :3, 3]),
            camera,
            renderer.raycaster,
            depth_margin_m,
            progress,
        )
    else:
        _depth_image_mask(
            blocks, seen_sorted, first_sorted, used, camera, renderer, depth_margin_m, progress
        )
    seen = np.empty(len(vertices), dtype=bool)
    seen[blocks.order] = seen_sorted
    if cache is not None:
        cache.store(vertices, used, renderer.scene, settings, seen)
    return seen


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
    vertices, poses, renderer = _checked(
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
        seen[candidates[index[_unoccluded(z, surface_depth, depth_margin_m)]]] = True
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
        cache: a :class:`CullingCache` shared by the cullings of one episode.

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
        vertices, poses, camera, scene, every, depth_margin_m, depth_scale, progress, cache
    )
    kept_faces = faces[seen[faces].any(axis=1)]
    used = np.unique(kept_faces)
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[kept_faces]
