"""Shortening a planned path: skip the nodes a straight free segment can jump over.

An RRT path is the chain of tree nodes that first reached the goal: it zigzags, and where
the tree grew around a room before finding the door it can be many times longer than the
way it could take (a path of 44 m to a goal 2.2 m away, measured on the apartment). The
published agent follows the chain as it is; :func:`shortcut_path` keeps the path's
topology (the same sequence of free regions) and replaces every stretch that a straight,
free segment can cover by that segment.
"""

from __future__ import annotations

import numpy as np

from naruto_agent.mapping.sdf_volume import SdfVolume
from naruto_agent.planning.collision import segment_is_free


def shortcut_path(
    sdf: SdfVolume, path: np.ndarray, clearance_m: float, sample_m: float = 0.02
) -> np.ndarray:
    """The path with every stretch a free straight segment covers replaced by it.

    Greedy from the start: from each kept node, jump to the farthest later node whose
    straight segment keeps ``clearance_m`` at samples ``sample_m`` apart (the check the
    planner itself uses), found by doubling the jump and then bisecting. Freeness is not
    monotonic along a path, so the jump found is a far one, not always the farthest; every
    segment returned is checked free.

    Args:
        sdf: the SDF the path was planned on.
        path: (K, 3) waypoints, start first, goal last.
        clearance_m: the SDF a sample needs to be free.
        sample_m: spacing of the samples along a segment.

    Returns:
        (K', 3) waypoints, K' <= K, the same start and goal.
    """
    path = np.asarray(path, dtype=np.float64).reshape(-1, 3)
    if len(path) <= 2:
        return path.copy()

    def free(a: int, b: int) -> bool:
        return b == a + 1 or segment_is_free(sdf, path[a], path[b], sample_m, clearance_m)

    kept = [0]
    anchor, last = 0, len(path) - 1
    while anchor < last:
        if free(anchor, last):
            kept.append(last)
            break
        reach, jump = anchor + 1, 2  # reach: a node known to be joined to the anchor
        while anchor + jump < last and free(anchor, anchor + jump):
            reach = anchor + jump
            jump *= 2
        low, high = reach, min(anchor + jump, last)  # high is blocked (or the blocked end)
        while high - low > 1:
            middle = (low + high) // 2
            if free(anchor, middle):
                low = middle
            else:
                high = middle
        kept.append(low)
        anchor = low
    return path[kept].copy()
