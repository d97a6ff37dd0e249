"""Never stuck: how the NARUTO agent notices it makes no progress, and what it does then.

The published agent stays where it is whenever planning fails, and independent re-runs of it
report failed episodes. This agent watches three signals:

* *no progress*: over the last ``window`` frames it has neither moved (``min_motion_m``) nor
  measured new space (its observed-space grid grew by less than ``min_observed_gain``);
* *failed plans*: ``max_failed_plans`` planning requests in a row found no reachable goal
  (every goal the search offered was unreachable, or the agent's own map put it inside an
  obstacle's clearance);
* *refused moves*: the env's ``collided`` / ``collision_reason`` info, which the agent turns
  into blocked voxels of its own map (see :class:`BlockedSpace`) so it never repeats them.

and recovers in escalating steps (:class:`RecoveryKind`): a turn in place that looks all
around (refreshing the map, which is often all a stale or grazing map needs), then a move to
reachable space away from where it has been, then a retreat along its own trajectory (space
it has physically been in, so free whatever the map says).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from enum import Enum

import numpy as np

from naruto_agent.mapping.sdf_volume import SdfVolume
from naruto_gym.utils.checks import check_integer, check_number


@dataclass(frozen=True)
class RecoveryConfig:
    """Settings of stall detection and recovery.

    Attributes:
        window: frames over which progress is judged (60).
        min_motion_m: moving less than this over the window is standing still (0.1 m).
        min_observed_gain: the observed-space share must grow by at least this over the
            window (0.0005, i.e. 0.05 % of the grid's voxels).
        max_failed_plans: planning requests in a row without a plan that trigger a recovery.
        failed_goal_radius_m: candidate goals this close to a goal that failed are skipped.
        failed_goal_memory_frames: ... for this many frames.
        max_goal_holds: plans to goals within ``held_goal_radius_m`` of each other (across,
            at any height) whose moves the agent's checks held this many times within the
            memory fail, at every height and that far around: the goal search would choose
            that spot again and again while the agent stays put (docs/agent-config.md).
        held_goal_radius_m: ... how near each other those goals lie, and how far around
            each of them the goal search then skips.
        max_holds_in_place: moves held this many times while the agent stays within
            ``hold_radius_m`` of where the first was held ask for a recovery that moves (a
            wander or a retreat): a plan whose first move is held at once, every frame,
            leaves the agent standing while the env refuses nothing.
        hold_radius_m: ... how far from there the agent may have got (the stay radius).
        blocked_radius_m: a refused move blocks the agent's map this far around its target
            (0.05 m, the agent's radius; see ``docs/agent-config.md`` for the larger radius
            and what it costs).
        escape_blocked_radius_m: when the env refused the move for leaving the scanned
            space (``collision_reason`` "escape", open scans only), the refused point lies
            in an opening (a window, a floor hole, a wall's missing edge) that the scan ends
            behind: the agent then blocks a ball of this radius beyond the refused point
            (touching it, on the far side from the agent), the space behind the opening
            rather than 5 cm of it per refusal (0.5 m: half a 1 m window; 0: as a surface).
        look_around_views: headings of the turn in place.
        look_around_pitch_deg: the look-around alternates looking this much up and down (20:
            three 20-degree steps from one view to the next, 25 steps for 8 views, of which
            the stall watchdog lets the first 24 run, ``max_stay_steps``; 25 degrees needs
            four steps a view).
        wander_max_m: the farthest a move to reachable space goes (straight-line distance).
        retreat_m: how far back along its own trajectory the agent retreats.
    """

    window: int = 60
    min_motion_m: float = 0.1
    min_observed_gain: float = 0.0005
    max_failed_plans: int = 3
    failed_goal_radius_m: float = 0.3
    failed_goal_memory_frames: int = 300
    max_goal_holds: int = 3
    held_goal_radius_m: float = 0.5
    max_holds_in_place: int = 3
    hold_radius_m: float = 0.5
    blocked_radius_m: float = 0.05
    escape_blocked_radius_m: float = 0.5
    look_around_views: int = 8
    look_around_pitch_deg: float = 20.0
    wander_max_m: float = 3.0
    retreat_m: float = 1.0

    def __post_init__(self) -> None:
        check_integer("RecoveryConfig.window", self.window, low=2)
        for name in ("max_failed_plans", "look_around_views", "max_goal_holds",
                     "max_holds_in_place"):
            check_integer(f"RecoveryConfig.{name}", getattr(self, name), low=1)
        for name in ("min_motion_m", "failed_goal_radius_m", "held_goal_radius_m",
                     "hold_radius_m", "wander_max_m", "retreat_m"):
            check_number(f"RecoveryConfig.{name}", getattr(self, name), low=0.0)
        for name in ("min_observed_gain", "blocked_radius_m", "escape_blocked_radius_m"):
            check_number(f"RecoveryConfig.{name}", getattr(self, name), low=0.0, low_open=False)


class RecoveryKind(str, Enum):
    """The recovery steps, in the order they are tried."""

    LOOK_AROUND = "look_around"
    WANDER = "wander"
    RETREAT = "retreat"


class ProgressMonitor:
    """Positions and map growth over a sliding window; failed plans in a row; failed goals."""

    def __init__(self, config: RecoveryConfig) -> None:
        self.config = config
        self.reset()

    def reset(self) -> None:
        self._positions: deque[np.ndarray] = deque(maxlen=self.config.window)
        self._observed: deque[float] = deque(maxlen=self.config.window)
        self.trajectory: list[np.ndarray] = []
        self.failed_plans = 0
        # goal, frame, column, radius (None: failed_goal_radius_m)
        self.failed_goals: list[tuple[np.ndarray, int, bool, float | None]] = []
        self.held_goals: list[tuple[np.ndarray, int]] = []  # goal, frame
        self._hold_spot: np.ndarray | None = None  # where the holds in place began
        self._holds_in_place = 0
        self.frame = 0
        self.escalation = 0
        self.last_recovery_frame = -(10**9)
        self._recovery_position: np.ndarray | None = None
        #: The pending recovery was asked for by :meth:`request_recovery`.
        self.requested = False

    def record(self, position: np.ndarray, observed_fraction: float) -> None:
        """One frame: where the agent is and how much of space its map has measured."""
        position = np.asarray(position, np.float64).copy()
        self.frame += 1
        self._positions.append(position)
        self._observed.append(float(observed_fraction))
        if not self.trajectory or np.linalg.norm(position - self.trajectory[-1]) > 1e-6:
            self.trajectory.append(position)

    def stalled(self) -> bool:
        """No motion and no new measured space over a full window."""
        if len(self._positions) < self.config.window:
            return False
        if self.frame - self.last_recovery_frame < self.config.window:
            return False  # give the last recovery a window to work
        positions = np.asarray(self._positions)
        moved = float(np.max(np.linalg.norm(positions - positions[0], axis=1)))
        gained = self._observed[-1] - self._observed[0]
        return moved < self.config.min_motion_m and gained < self.config.min_observed_gain

    def plan_succeeded(self) -> None:
        self.failed_plans = 0

    def plan_failed(self) -> None:
        self.failed_plans += 1

    def needs_recovery(self) -> bool:
        return self.failed_plans >= self.config.max_failed_plans or self.stalled()

    def next_recovery(self) -> RecoveryKind:
        """The next step of the escalation (look around, wander, retreat, then again)."""
        kinds = list(RecoveryKind)
        kind = kinds[self.escalation % len(kinds)]
        self.escalation += 1
        self.last_recovery_frame = self.frame
        self._recovery_position = self._positions[-1].copy() if self._positions else None
        self.failed_plans = 0
        return kind

    def request_recovery(self) -> None:
        """A stall noticed from outside (the policy's stall watchdog): the next plan is a
        recovery, and one that moves (a wander or a retreat; a turn in place is what the
        agent was doing)."""
        self.failed_plans = self.config.max_failed_plans
        self.requested = True
        if self.escalation % len(RecoveryKind) == 0:
            self.escalation += 1

    def progress_made(self, position: np.ndarray) -> None:
        """A normal plan went through: the escalation starts over, once the agent has moved
        away from where the last recovery began (a plan whose first move never happens is
        no progress, and the next stall must escalate, not look around again)."""
        if self._recovery_position is None or np.linalg.norm(
            np.asarray(position, np.float64) - self._recovery_position
        ) >= self.config.min_motion_m:
            self.escalation = 0

    def goal_failed(self, goal: np.ndarray, column: bool = False,
                    radius_m: float | None = None) -> None:
        """``goal`` failed; ``column``: for where it lies, not for how high (past an open
        scan's edge, which no height crosses), so every goal above or below it fails too;
        ``radius_m``: how far around it goals are skipped (None: ``failed_goal_radius_m``)."""
        self.failed_goals.append(
            (np.asarray(goal, np.float64).copy(), self.frame, column, radius_m))

    def move_held(self, position: np.ndarray) -> bool:
        """A move was held (by the agent's checks or the env) with the agent at
        ``position``. At the ``max_holds_in_place``-th hold within ``hold_radius_m`` of where
        the first of them was, the next plan is a recovery that moves
        (:meth:`request_recovery`); returns whether it is."""
        position = np.asarray(position, np.float64)
        if (self._hold_spot is None
                or np.linalg.norm(position - self._hold_spot) > self.config.hold_radius_m):
            self._hold_spot, self._holds_in_place = position.copy(), 0
        self._holds_in_place += 1
        if self._holds_in_place < self.config.max_holds_in_place:
            return False
        self._holds_in_place = 0
        self.request_recovery()
        return True

    def goal_held(self, goal: np.ndarray) -> bool:
        """A move of the plan to ``goal`` was held (by the agent's checks or the env). At the
        ``max_goal_holds``-th such plan within the memory to goals within
        ``held_goal_radius_m`` of it (across), they all fail at every height; returns
        whether they did."""
        goal = np.asarray(goal, np.float64).copy()
        horizon = self.frame - self.config.failed_goal_memory_frames
        self.held_goals = [entry for entry in self.held_goals if entry[1] >= horizon]
        self.held_goals.append((goal, self.frame))
        radius = self.config.held_goal_radius_m
        near = [np.linalg.norm(held[:2] - goal[:2]) <= radius for held, _ in self.held_goals]
        if sum(near) < self.config.max_goal_holds:
            return False
        for (held, _), close in zip(self.held_goals, near, strict=True):
            if close:
                self.goal_failed(held, column=True, radius_m=radius)
        self.held_goals = [entry for entry, close in zip(self.held_goals, near, strict=True)
                           if not close]
        return True

    def recent_failed_goals(self, columns: bool = False) -> np.ndarray:
        """(F, 3) goals that failed within the memory (``columns``: only those that failed
        for where they lie)."""
        return self.recent_failed(columns)[0]

    def recent_failed(self, columns: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """The goals that failed within the memory, (F, 3), and how far around each goals
        are skipped, (F,) metres (``columns``: only those that failed for where they lie)."""
        horizon = self.frame - self.config.failed_goal_memory_frames
        self.failed_goals = [entry for entry in self.failed_goals if entry[1] >= horizon]
        kept = [(goal, self.config.failed_goal_radius_m if radius is None else radius)
                for goal, _, column, radius in self.failed_goals if column or not columns]
        if not kept:
            return np.zeros((0, 3)), np.zeros(0)
        return np.stack([goal for goal, _ in kept]), np.array([radius for _, radius in kept])

    def retreat_path(self, position: np.ndarray, step_m: float = 0.1) -> np.ndarray:
        """(K, 3) nodes from ``position`` back along the trajectory for ``retreat_m``,
        consecutive nodes at most ``step_m`` apart (just ``position`` with no history)."""
        position = np.asarray(position, np.float64)
        points = [position]
        travelled = 0.0
        for previous in reversed(self.trajectory[:-1]):
            travelled += float(np.linalg.norm(previous - points[-1]))
            points.append(previous)
            if travelled >= self.config.retreat_m:
                break
        return densify(np.asarray(points), step_m)


def densify(points: np.ndarray, step_m: float) -> np.ndarray:
    """Insert nodes so that consecutive ones are at most ``step_m`` apart."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    out = [points[0]]
    for a, b in zip(points[:-1], points[1:], strict=True):
        count = max(1, math.ceil(float(np.linalg.norm(b - a)) / step_m - 1e-9))
        out.extend(a + (b - a) * (k / count) for k in range(1, count + 1))
    return np.asarray(out)


def look_around_targets(
    position: np.ndarray, views: int = 8, pitch_deg: float = 25.0, distance_m: float = 1.0
) -> np.ndarray:
    """(views, 3) points all around ``position`` to look at in turn (a turn in place),
    alternately ``pitch_deg`` above and below the horizon."""
    azimuth = 2.0 * np.pi * np.arange(views) / views
    pitch = np.deg2rad(pitch_deg) * np.where(np.arange(views) % 2 == 0, 1.0, -1.0)
    offsets = np.stack([np.cos(pitch) * np.cos(azimuth), np.cos(pitch) * np.sin(azimuth),
                        np.sin(pitch)], axis=1)
    return np.asarray(position, np.float64) + distance_m * offsets


class BlockedSpace:
    """Points where the env refused a move; they read as obstacles in the agent's SDF.

    A real robot learns from a refused move (a bump, or a no-go boundary such as the edge of
    a scanned space) that the place it tried to reach is not for it, whatever its map says.
    """

    def __init__(self, radius_m: float = 0.05) -> None:
        self.radius_m = float(radius_m)
        self.points: list[np.ndarray] = []
        self.radii: list[float] = []
        #: Per point: blocked on the agent's own reading (its panorama or map said the move
        #: would leave the scan) rather than on a move the env refused.
        self.guessed: list[bool] = []
        #: Space above this height is blocked (the top of an open scan, learned from a
        #: refused climb); +inf: no ceiling.
        self.ceiling_z = float("inf")

    def lower_ceiling(self, z: float) -> None:
        """Block everything above height ``z`` (voxel centres higher than it)."""
        self.ceiling_z = min(self.ceiling_z, float(z))

    def add(self, point: np.ndarray, radius_m: float | None = None, guessed: bool = False) -> None:
        """Block ``point``, ``radius_m`` around it (default: the space's ``radius_m``);
        ``guessed``: on the agent's own reading, not on a move the env refused."""
        self.points.append(np.asarray(point, np.float64).copy())
        self.radii.append(self.radius_m if radius_m is None else float(radius_m))
        self.guessed.append(bool(guessed))

    def holds(self, point: np.ndarray) -> bool:
        """Whether ``point`` lies within a blocked ball's radius (a refused move's target:
        the SDF's voxels cannot say so when the agent's own voxel is blocked too)."""
        point = np.asarray(point, np.float64)
        return any(
            float(np.linalg.norm(point - centre)) <= radius
            for centre, radius in zip(self.points, self.radii, strict=True)
        )

    def forget_guesses_near(self, position: np.ndarray, reach_m: float) -> int:
        """Drop the guessed balls that come within ``reach_m`` of ``position``; returns how
        many were dropped (what the env refused stays blocked)."""
        position = np.asarray(position, np.float64)
        keep = [
            not guessed or float(np.linalg.norm(point - position)) - radius > reach_m
            for point, radius, guessed in zip(self.points, self.radii, self.guessed, strict=True)
        ]
        dropped = len(keep) - sum(keep)
        if dropped:
            self.points = [p for p, k in zip(self.points, keep, strict=True) if k]
            self.radii = [r for r, k in zip(self.radii, keep, strict=True) if k]
            self.guessed = [g for g, k in zip(self.guessed, keep, strict=True) if k]
        return dropped

    def apply(self, sdf: SdfVolume) -> SdfVolume:
        """The SDF with every voxel within a point's radius + half a voxel of it, and every
        voxel above the ceiling, set to at most minus one voxel (an obstacle the planner
        keeps its clearance from)."""
        if not self.points and not np.isfinite(self.ceiling_z):
            return sdf
        values = sdf.values.copy()
        if np.isfinite(self.ceiling_z):
            heights = sdf.origin[2] + np.arange(sdf.shape[2]) * sdf.voxel_size
            above = heights > self.ceiling_z
            values[:, :, above] = np.minimum(values[:, :, above], -sdf.voxel_size)
        for point, radius in zip(self.points, self.radii, strict=True):
            reach = radius + 0.5 * sdf.voxel_size
            span = math.ceil(reach / sdf.voxel_size)
            axis = np.arange(-span, span + 1)
            block = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
            centre = np.rint(sdf.world_to_voxel(point)).astype(np.int64)
            voxels = centre + block
            inside = np.all((voxels >= 0) & (voxels < np.asarray(sdf.shape)), axis=1)
            voxels = voxels[inside]
            near = np.linalg.norm(sdf.voxel_to_world(voxels) - point, axis=1) <= reach
            voxels = voxels[near]
            index = (voxels[:, 0], voxels[:, 1], voxels[:, 2])
            values[index] = np.minimum(values[index], -sdf.voxel_size)
        return SdfVolume(values, sdf.origin, sdf.voxel_size)
