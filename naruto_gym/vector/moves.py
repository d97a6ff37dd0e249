"""Moving a batch of agents: bounded pose steps, collision sweeps and escape checks.

The same rules as the single env's ``CollisionChecker.move`` (the same compiled kernels, so
the same positions to the bit), asked for many agents at once: one closest-distance query and
one segment ray cast per scene for every agent that moves, and one lattice lookup for the
scanned-space escape rule. The published escape rule's panorama rays are left to the frame
cast (see :mod:`naruto_gym.vector.frames`), which carries them in the same call.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from naruto_gym.motion.actions import MAX_DISCRETE_PITCH_RAD
from naruto_gym.motion.pose_kernels import (
    MODE_DELTA,
    MODE_DISCRETE,
    MODE_POSE,
    step_poses_kernel,
)
from naruto_gym.vector.batch_kernels import (
    PROVABLY_CLEAR_SLACK_M,
    plan_sweeps,
    sweep_distance_queries,
    sweep_stops,
)
from naruto_gym.vector.scene_pool import ScenePool

_MODES = {"pose": MODE_POSE, "delta": MODE_DELTA, "discrete": MODE_DISCRETE}


class Moves:
    """What :meth:`Mover.move` decided for the stepping agents.

    Attributes:
        agents: (K,) the agents that stepped.
        starts: (K, 3) where each started.
        collided: (K,) whether its move was blocked or refused.
        reasons: (K,) why ("", "surface", "bounds", "escape").
        check_escape: (K,) whether the frame cast must still run its escape check.
        start_clearances: (K,) float32 surface distance of each start, as the distance query
            gives it (nan: not asked).
    """

    def __init__(self, agents: np.ndarray) -> None:
        self.agents = agents
        self.starts = np.zeros((len(agents), 3))
        self.collided = np.zeros(len(agents), bool)
        self.reasons = np.full(len(agents), "", dtype=object)
        self.check_escape = np.zeros(len(agents), bool)
        self.start_clearances = np.full(len(agents), np.nan, np.float32)

    @classmethod
    def joined(cls, shares: list[Moves]) -> Moves:
        """The outcome of several shares' moves of a step, in order, as one: the agents,
        whether each collided and why (what the step reports; the shares have been
        observed already)."""
        moves = cls(np.concatenate([share.agents for share in shares]))
        moves.collided = np.concatenate([share.collided for share in shares])
        moves.reasons = np.concatenate([share.reasons for share in shares])
        return moves

    def refuse(self, k: int) -> None:
        """Mark move ``k`` refused by the escape rule."""
        self.collided[k] = True
        self.reasons[k] = "escape"


def escape_rule(checker: Any) -> str:
    """The collision checker's escape rule (checkers without rules use the published one)."""
    default = "off" if checker.escape_no_hit_threshold is None else "published"
    return getattr(checker, "escape_rule", default)


def allclose_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise ``np.allclose(a[i], b[i])`` (same tolerances)."""
    return np.all(np.abs(a - b) <= 1e-8 + 1e-5 * np.abs(b), axis=1)


class Mover:
    """Moves agents of a batch, updating their poses, clearances and step counts in place.

    Args:
        pool: the agents' scenes.
        action_mode: ``"pose"``, ``"delta"`` or ``"discrete"``.
        max_translation_m, max_rotation_rad: the step limits.
        poses: (N, 4, 4) the agents' camera-to-world poses.
        clearances: (N,) float32 each agent's distance to the nearest surface where it stands
            (nan: not known yet), carried over from the sweep that brought it there: that
            point is one of the sweep's samples, whose distance was queried, so its next
            sweep need not ask again.
        steps: (N,) int64 steps of each agent's episode.
    """

    def __init__(
        self,
        pool: ScenePool,
        action_mode: str,
        max_translation_m: float,
        max_rotation_rad: float,
        poses: np.ndarray,
        clearances: np.ndarray,
        steps: np.ndarray,
    ) -> None:
        self.pool = pool
        self.mode = _MODES[action_mode]
        self.max_translation_m = float(max_translation_m)
        self.max_rotation_rad = float(max_rotation_rad)
        self.poses = poses
        self.clearances = clearances
        self.steps = steps

    def move(self, agents: np.ndarray, discrete: np.ndarray, continuous: np.ndarray) -> Moves:
        """Bounded pose step and collision sweep of ``agents``; their poses become the
        candidate poses. The published escape check of those that moved is left to the frame
        cast, which carries its rays (:attr:`Moves.check_escape`)."""
        moves = Moves(agents)
        if len(agents) == 0:
            return moves
        limited = np.empty((len(agents), 4, 4))
        step_poses_kernel(
            np.ascontiguousarray(self.poses[agents]),
            self.mode,
            np.ascontiguousarray(discrete[agents]),
            np.ascontiguousarray(continuous[agents]),
            self.max_translation_m,
            self.max_rotation_rad,
            float(MAX_DISCRETE_PITCH_RAD),
            limited,
        )
        moves.starts = self.poses[agents, :3, 3].copy()
        moves.start_clearances = self.clearances[agents]
        targets = limited[:, :3, 3].copy()
        positions = moves.starts.copy()
        moving = ~allclose_rows(moves.starts, targets)
        end_clearances = np.full(len(agents), np.nan)
        for group in self.pool.groups(agents, moving):
            self._sweep(agents[group], group, moves, targets, positions, end_clearances)
        moved = ~allclose_rows(positions, moves.starts)
        # Where each agent stands after the sweep: its stop's distance, else its start's.
        self.clearances[agents] = np.where(
            np.isnan(end_clearances), moves.start_clearances, end_clearances
        )
        for group in self.pool.groups(agents, moved):
            checker = self.pool[agents[group[0]]].collision
            rule = escape_rule(checker)
            if rule == "published":
                # Their panorama rays ride along with the frame's cast.
                moves.check_escape[group] = True
                continue
            if rule == "off":
                continue
            if rule == "scanned_space":
                # One lattice lookup for all: an end inside the scanned space is never
                # refused, so only the others need the exact per-move rule.
                inside = checker.scanned_space.contains_many(
                    positions[group], end_clearances[group]
                )
                group = group[~inside]
            for k in group:
                if checker.refuses_escape(moves.starts[k], positions[k]):
                    positions[k] = moves.starts[k]
                    self.clearances[agents[k]] = moves.start_clearances[k]
                    moves.refuse(k)
        limited[:, :3, 3] = positions
        self.poses[agents] = limited
        self.steps[agents] += 1
        return moves

    def undo(self, moves: Moves, k: int) -> None:
        """Put back move ``k``, refused after the frame cast: the agent stays at its start
        (with its new rotation)."""
        agent = moves.agents[k]
        self.poses[agent, :3, 3] = moves.starts[k]
        self.clearances[agent] = moves.start_clearances[k]
        moves.refuse(k)

    def _sweep(
        self,
        members: np.ndarray,
        group: np.ndarray,
        moves: Moves,
        targets: np.ndarray,
        positions: np.ndarray,
        end_clearances: np.ndarray,
    ) -> None:
        """``CollisionChecker.move``'s box clip and sphere sweep for moving agents of one
        scene (``group`` indexes ``moves``), with one distance query for all their samples
        and one cast for all their segment rays. Where each sweep stops is one of its
        samples, so its distance to the surface (for the escape rule) comes with it."""
        runtime = self.pool[members[0]]
        checker = runtime.collision
        raycaster = runtime.raycaster
        start = np.ascontiguousarray(moves.starts[group])
        start_clearances = moves.start_clearances[group]
        unknown = np.isnan(start_clearances)
        if unknown.any():
            start_clearances[unknown] = raycaster.unsigned_distance(start[unknown])
            moves.start_clearances[group] = start_clearances
        # From a start closer than the radius (an exact start pose) the sphere may move on as
        # long as it gets no closer than it already is.
        box, end, clearances, lengths, offsets, fractions, points = plan_sweeps(
            start,
            np.ascontiguousarray(targets[group]),
            checker.box_min,
            checker.box_max,
            start_clearances,
            float(checker.radius_m),
        )
        # Only samples whose distance could block are queried, and only segments that could
        # reach a surface are cast: the outcome is the full sweep's (sweep_distance_queries).
        needed, distances = sweep_distance_queries(
            start_clearances, offsets, fractions, lengths, clearances
        )
        if needed.any():
            distances[needed] = raycaster.unsigned_distance(points[needed])
        walls = np.full(len(group), np.inf)
        along = (lengths > 0) & ~(start_clearances >= lengths + clearances + PROVABLY_CLEAR_SLACK_M)
        if along.any():
            directions = (end[along] - start[along]) / lengths[along, None]
            walls[along] = raycaster.cast_distance(start[along], directions)
        stops, stop_clearances = sweep_stops(
            fractions, offsets, lengths, distances, walls, clearances
        )
        positions[group] = start + stops[:, None] * (end - start)
        # A sweep stopped before its end, at a sample only bounded: ask for that distance.
        bounded = np.isinf(stop_clearances)
        if bounded.any():
            stop_clearances[bounded] = raycaster.unsigned_distance(positions[group][bounded])
        end_clearances[group] = stop_clearances
        reasons = np.where(stops < 1.0, "surface", np.where(box < 1.0, "bounds", ""))
        moves.reasons[group] = reasons
        moves.collided[group] = reasons != ""
