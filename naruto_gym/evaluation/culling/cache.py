"""What one culling learnt, kept for the next culling of the same episode.

Checkpoints re-score a growing trajectory: a vertex at a bit-identical position keeps its
verdict for the poses already tried (an open-addressing table of exact positions, compiled in
:mod:`.kernels`).
"""

from __future__ import annotations

import numpy as np

from naruto_gym.evaluation.culling.kernels import build_position_table, find_positions
from naruto_gym.scenes.mesh_scene import Scene


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
    margin and the used poses. When the next call has the same rule and its used poses
    start with the ones tried before (an episode that went on), a vertex at a bit-identical
    position (TSDF meshes keep most vertices between checkpoints) is known seen, or only has
    to try the new poses. Anything else (another rule, other poses) starts from scratch.
    (:class:`~.settings.CullingSettings` never change a verdict, so they do not matter.)

    Pass one to :func:`~.mask.visible_vertex_mask` (or ``cull_cache=`` of the scoring functions);
    :class:`~naruto_gym.evaluation.scoring.EpisodeReconstruction` keeps one per episode.
    """

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """Forget everything."""
        self._rule: tuple | None = None
        self._scene: Scene | None = None
        self._poses: np.ndarray | None = None
        self._vertices: np.ndarray | None = None
        self._keys: np.ndarray | None = None
        self._table: np.ndarray | None = None
        self._bits = 0
        self._seen: np.ndarray | None = None

    def prior(
        self, vertices: np.ndarray, used_poses: np.ndarray, scene: Scene, rule: tuple
    ) -> tuple[np.ndarray, np.ndarray]:
        """(seen, first_pose): vertices known seen, and the first used pose each still has
        to try (0 for a vertex the cache knows nothing about). ``rule``: the rule's parameters
        (camera, every, margin, depth scale) the verdicts must hold for."""
        seen = np.zeros(len(vertices), dtype=bool)
        first_pose = np.zeros(len(vertices), dtype=np.int64)
        known = self._poses
        if (
            known is None
            or self._scene is not scene
            or self._rule != rule
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
        rule: tuple,
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
        self._rule = rule
