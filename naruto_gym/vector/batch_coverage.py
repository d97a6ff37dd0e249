"""Every agent's coverage in one set of arrays, updated by one compiled loop per scene.

The single env's ``CoverageTracker`` keeps one agent's seen flags; here row ``i`` of each
array is agent ``i``'s, so the coverage kernel updates all agents of a scene in place
without per-agent copies, and the counts are the single env's to the bit.
"""

from __future__ import annotations

import numpy as np

from naruto_gym.coverage import COVERAGE_TOLERANCE_M, CoverageTracker
from naruto_gym.vector.batch_kernels import mark_visible_batch
from naruto_gym.vector.scheduling import in_threads


def widened(array: np.ndarray, columns: int) -> np.ndarray:
    """``array`` (a row per agent) with at least ``columns`` columns, the new ones zero: a
    stream's next scene may have more samples or cells than any before."""
    if columns <= array.shape[1]:
        return array
    wider = np.zeros((len(array), columns), array.dtype)
    wider[:, : array.shape[1]] = array
    return wider


class BatchCoverage:
    """The agents' seen flags over their scenes' surface samples.

    Args:
        num_envs: the agents.
    """

    def __init__(self, num_envs: int) -> None:
        # Seen flags of each agent's scene samples (row i, the first len(samples) columns).
        self._seen = np.zeros((num_envs, 0), bool)
        self._unseen_in_cell = np.zeros((num_envs, 0), np.int64)  # per agent and sample cell
        self._seen_counts = np.zeros(num_envs, np.int64)
        # Coverage samples of each agent's scene (set at its reset; 1 before any).
        self._sample_totals = np.ones(num_envs, np.int64)

    def coverage(self) -> np.ndarray:
        """(N,) each agent's share in [0, 1] of its scene's samples seen this episode."""
        return self._seen_counts / self._sample_totals

    def reset_agent(self, agent: int, tracker: CoverageTracker) -> None:
        """Start ``agent``'s episode with nothing seen of ``tracker``'s samples."""
        samples = len(tracker.samples_world)
        self._seen = widened(self._seen, samples)
        self._sample_totals[agent] = samples
        self._seen[agent] = False
        sizes = tracker.cell_sizes
        self._unseen_in_cell = widened(self._unseen_in_cell, len(sizes))
        self._unseen_in_cell[agent, : len(sizes)] = sizes
        self._seen_counts[agent] = 0

    def update(
        self,
        members: np.ndarray,
        tracker: CoverageTracker,
        poses: np.ndarray,
        depth: np.ndarray,
        threads: int,
    ) -> np.ndarray:
        """Mark what the agents ``members`` (all in ``tracker``'s scene) see in their frames.

        Args:
            members: the agents.
            tracker: their scene's coverage tracker (its samples and cells).
            poses: (N, 4, 4) every agent's camera-to-world pose.
            depth: (N, H, W) float32 every agent's depth frame.
            threads: threads for the compiled loop.

        Returns:
            (len(members),) each agent's coverage gain (share, not percent).
        """
        added = np.zeros(len(members), np.int64)

        def mark(part: slice) -> None:
            mark_visible_batch(
                tracker.samples_world,
                *tracker.cells,
                self._seen,
                self._unseen_in_cell,
                members[part],
                poses,
                tracker.intrinsics,
                depth,
                tracker.max_range_m,
                COVERAGE_TOLERANCE_M,
                added[part],
            )

        in_threads(mark, len(members), threads)
        total = len(tracker.samples_world)
        before = self._seen_counts[members] / total
        self._seen_counts[members] += added
        return self._seen_counts[members] / total - before
