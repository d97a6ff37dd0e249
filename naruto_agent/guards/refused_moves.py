"""Where an open scan ends, learned from the moves the env refused as escapes.

On an open scan (no ceiling, a missing wall, a floor hole) the env refuses a move that would
leave the scanned space (``info["collision_reason"] == "escape"``) while nothing in the
observations marks the place: a policy records every such refusal and reads back the flight
ceiling and the virtual walls a robot would learn by bumping into the scan's edge.
"""

from __future__ import annotations

import numpy as np

from naruto_agent.guards.panorama_clearance import sees_all_around_below


def refused_at_top(position: np.ndarray, target: np.ndarray, supported_below: bool) -> bool:
    """A move from ``position`` towards ``target`` refused as an escape met the scan's open
    top rather than its side: it climbs steeper than 45 degrees, or climbs at all (more than
    a fifth of its length) from where scanned surface is known to lie all around below
    (``supported_below``), so the floor's edge cannot be the reason."""
    move = np.asarray(target, np.float64) - np.asarray(position, np.float64)
    horizontal = float(np.linalg.norm(move[:2]))
    return bool(move[2] > horizontal
                or (move[2] > 0.2 * float(np.linalg.norm(move)) and supported_below))


class RefusedMoves:
    """Where the scan ends, learned from moves the env refused as escapes.

    On an open scan (no ceiling, a missing wall, a hole) the env refuses a move that would
    leave the scanned space (``info["collision_reason"] == "escape"``), while the panorama
    shows nothing there to avoid. A policy records every such refusal with the target it
    asked for, and reads back what a robot would learn by bumping into the scan's edge:

    * a move refused upwards (steeper than 45 degrees, or any climb when the panorama shows
      scanned surface all around below, so the floor's edge cannot be the reason) sets a
      flight ceiling at the agent's height;
    * a move refused downwards marks a patch of "floor" just under the agent (the edge of a
      floor hole);
    * a move refused sideways marks the point it aimed at as the edge of the scanned floor
      (past a missing wall or a wall hole), with a short virtual wall across the move; the
      edge between two such points less than ``join_m`` apart is drawn as a virtual wall
      through both, which gives the edge's direction.

    Args:
        join_m: two sideways refusals closer than this (at a similar height) are joined.
        spacing_m: distance between the points that make up walls and patches.
    """

    def __init__(self, join_m: float = 1.5, spacing_m: float = 0.05) -> None:
        self.join_m = join_m
        self.spacing_m = spacing_m
        self.ceiling_z = float("inf")
        self._points: list[np.ndarray] = []
        self._edges: list[np.ndarray] = []

    def reset(self) -> None:
        self.ceiling_z = float("inf")
        self._points = []
        self._edges = []

    @property
    def points(self) -> np.ndarray:
        """(K, 3) points of the virtual walls and floor patches learned so far."""
        return np.concatenate(self._points) if self._points else np.zeros((0, 3))

    def _segment(self, start: np.ndarray, end: np.ndarray, extend_m: float) -> np.ndarray:
        """Points every ``spacing_m`` from ``start`` to ``end``, extended at both ends."""
        direction = end - start
        length = float(np.linalg.norm(direction))
        direction = direction / max(length, 1e-9)
        steps = np.arange(-extend_m, length + extend_m + 1e-9, self.spacing_m)
        return start + steps[:, None] * direction

    def record(
        self,
        position: np.ndarray,
        target: np.ndarray,
        panorama: np.ndarray | None = None,
        across_half_width_m: float = 0.2,
    ) -> np.ndarray:
        """Learn from a move from ``position`` towards ``target`` refused as an escape.

        Args:
            position: where the agent is (the move did not happen).
            target: where the move aimed.
            panorama: the depth panorama at ``position``, when the policy has it.
            across_half_width_m: half width of the short wall across a sideways move (0: the
                aimed point only).

        Returns the (K, 3) points added (empty for a ceiling).
        """
        position = np.asarray(position, np.float64)
        move = np.asarray(target, np.float64) - position
        length = float(np.linalg.norm(move))
        if length < 1e-6:
            return np.zeros((0, 3))
        horizontal = float(np.linalg.norm(move[:2]))
        supported = panorama is not None and sees_all_around_below(panorama)
        if refused_at_top(position, target, supported):
            self.ceiling_z = min(self.ceiling_z, float(position[2]))
            return np.zeros((0, 3))
        if -move[2] > horizontal:  # mostly downwards: a patch under the agent
            offsets = np.arange(-0.3, 0.3 + 1e-9, 0.1)
            u, v = np.meshgrid(offsets, offsets)
            added = np.column_stack([position[0] + u.ravel(), position[1] + v.ravel(),
                                     np.full(u.size, position[2] - length)])
        else:  # sideways: the edge of the scanned floor, one step ahead
            ahead = np.append(move[:2] / horizontal, 0.0)
            across = np.array([-ahead[1], ahead[0], 0.0])
            edge = position + ahead * max(length, self.spacing_m)
            added = self._segment(
                edge - across_half_width_m * across, edge + across_half_width_m * across, 0.0
            )
            near = [
                point for point in self._edges
                if abs(point[2] - edge[2]) < 0.3
                and 0.05 < np.linalg.norm(point[:2] - edge[:2]) < self.join_m
            ]
            if near:
                closest = min(near, key=lambda point: float(np.linalg.norm(point - edge)))
                joined = self._segment(closest, edge, 0.2)
                joined[:, 2] = edge[2]
                added = np.concatenate([added, joined])
            self._edges.append(edge)
        self._points.append(added)
        return added

    def overlay(self, profile: np.ndarray, position: np.ndarray,
                max_height_offset_m: float = 0.3) -> np.ndarray:
        """``profile`` (see :func:`horizontal_profile`) with the virtual walls near the agent's
        height as obstacles."""
        points = self.points
        if len(points) == 0:
            return profile
        points = points[np.abs(points[:, 2] - position[2]) <= max_height_offset_m]
        if len(points) == 0:
            return profile
        offsets = points[:, :2] - np.asarray(position, np.float64)[:2]
        distance = np.linalg.norm(offsets, axis=1)
        width = len(profile)
        azimuth = np.arctan2(offsets[:, 1], offsets[:, 0])
        column = np.floor((azimuth + np.pi) / (2.0 * np.pi) * width).astype(np.int64) % width
        merged = np.asarray(profile, np.float64).copy()
        np.minimum.at(merged, column, distance)
        return merged
