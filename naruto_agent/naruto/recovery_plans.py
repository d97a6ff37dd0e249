"""The NARUTO agent's recovery steps as plans: look around, wander, retreat.

When the :class:`~naruto_agent.naruto.recovery.ProgressMonitor` says the agent is stuck (plans
keep failing, or it neither moves nor measures anything new), the planning step hands the
state machine a recovery plan instead of a goal search's, in escalating steps
(:class:`~naruto_agent.naruto.recovery.RecoveryKind`): a turn in place that looks all around,
a move to reachable space away from where the agent has been, a retreat along its own
trajectory. A step that finds no way falls back to the next (wander -> retreat -> look
around).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from naruto_agent.naruto.agent_map import AgentMap
from naruto_agent.naruto.config import NarutoConfig
from naruto_agent.naruto.paths import shorten_path
from naruto_agent.naruto.recovery import ProgressMonitor, RecoveryKind, look_around_targets
from naruto_agent.naruto.state_machine import Plan
from naruto_agent.planning import PlannerConfig, plan_path, reachable_voxels

#: ``inside_scan(points, position) -> (N,) bool``: which points lie inside the scan.
InsideScan = Callable[[np.ndarray, np.ndarray], np.ndarray]

#: How many of the trajectory's last points count as where the agent has been.
_HISTORY_POINTS = 300
#: How many of the most novel reachable points a wander tries to plan to.
_WANDER_TRIES = 5


def look_around_plan(position: np.ndarray, config: NarutoConfig) -> Plan:
    """A turn in place at ``position`` that looks all around."""
    return Plan(position[None].copy(), look_around_views(position, config), position.copy(),
                {"recovery": "look_around"})


def look_around_views(position: np.ndarray, config: NarutoConfig) -> np.ndarray:
    """The views of a turn in place at ``position`` (``recovery.look_around_views``)."""
    recovery = config.recovery
    return look_around_targets(position, recovery.look_around_views,
                               recovery.look_around_pitch_deg)


class RecoveryPlanner:
    """Turns the monitor's next recovery step into a plan.

    Args:
        config: the agent's settings.
        agent_map: the agent's map (the planner view the wander plans on).
        monitor: the episode's progress monitor (the escalation, the trajectory).
        rng: the agent's randomness (each wander's E-RRT seed).
        inside_scan: which points lie inside the scan (wander targets must, with
            ``stay_in_scanned_space``).
        device: where the E-RRT's nearest-neighbour search runs.
        timings: the dict the ``"rrt"`` seconds are added to.
    """

    def __init__(self, config: NarutoConfig, agent_map: AgentMap, monitor: ProgressMonitor,
                 rng: np.random.Generator, inside_scan: InsideScan, device: str = "auto",
                 timings: dict[str, float] | None = None) -> None:
        self.config = config
        self.agent_map = agent_map
        self.monitor = monitor
        self.rng = rng
        self.inside_scan = inside_scan
        self.device = device
        self.timings = timings if timings is not None else {"rrt": 0.0}

    def next_plan(self, position: np.ndarray) -> tuple[RecoveryKind, Plan]:
        """The monitor's next recovery step from ``position``.

        Returns:
            The step the monitor asked for, and the plan (of that step, or of the one it fell
            back to: ``plan.info["recovery"]`` names it).
        """
        asked = kind = self.monitor.next_recovery()
        plan = None
        if kind == RecoveryKind.WANDER:
            plan = self.wander(position)
            if plan is None:
                kind = RecoveryKind.RETREAT
        if kind == RecoveryKind.RETREAT:
            path = self.monitor.retreat_path(position)
            if len(path) > 1:
                plan = Plan(path, look_around_views(path[-1], self.config), path[-1].copy(),
                            {"recovery": "retreat", "trusted": True})
            else:
                kind = RecoveryKind.LOOK_AROUND
        if kind == RecoveryKind.LOOK_AROUND:
            plan = look_around_plan(position, self.config)
        return asked, plan

    def wander(self, position: np.ndarray) -> Plan | None:
        """A path to reachable space within ``recovery.wander_max_m``, as far as possible from
        where the agent has been; None when the agent is within a clearance or no such
        point can be reached."""
        points = self.reachable_points(position, self.config.recovery.wander_max_m)
        if points is None or len(points) == 0:
            return None
        history = np.asarray(self.monitor.trajectory[-_HISTORY_POINTS:])
        novelty = np.full(len(points), np.inf)
        for chunk in np.array_split(history, max(1, len(history) // 64)):
            novelty = np.minimum(novelty, np.min(
                np.linalg.norm(points[:, None, :] - chunk[None, :, :], axis=2), axis=1))
        for goal in points[np.argsort(-novelty, kind="stable")[:_WANDER_TRIES]]:
            plan = self.path_to(position, goal, "wander")
            if plan is not None:
                return plan
        return None

    def reachable_points(self, position: np.ndarray, max_m: float) -> np.ndarray | None:
        """The planner view's voxels the agent can reach from ``position`` within ``max_m``
        (inside the scan with ``stay_in_scanned_space``), (n, 3); None when the agent is
        within a clearance (no way from here is planned)."""
        if not self.agent_map.keeps_clearance(position):
            return None
        sdf = self.agent_map.sdf
        clock = time.perf_counter()
        try:
            reachable = reachable_voxels(sdf, position, self._planner(),
                                         iterations=self.config.reachable_iterations)
        finally:
            self.timings["rrt"] += time.perf_counter() - clock
        points = sdf.grid_points()[reachable.reshape(-1)]
        points = points[np.linalg.norm(points - position, axis=1) <= max_m]
        if self.config.stay_in_scanned_space and len(points):
            points = points[self.inside_scan(points, position)]
        return points

    def path_to(self, position: np.ndarray, goal: np.ndarray, kind: str) -> Plan | None:
        """A recovery plan of ``kind`` along an E-RRT path from ``position`` to ``goal``,
        looking around there; None when the planner finds no path."""
        sdf = self.agent_map.sdf
        clock = time.perf_counter()
        try:
            result = plan_path(sdf, position, goal, self._planner(), self.agent_map.components)
        finally:
            self.timings["rrt"] += time.perf_counter() - clock
        if not result.success:
            return None
        path = shorten_path(sdf, result.path, self.config)
        return Plan(path, look_around_views(goal, self.config), np.asarray(goal).copy(),
                    {"recovery": kind})

    def _planner(self) -> PlannerConfig:
        """The planner's settings with a fresh E-RRT seed."""
        return replace(self.config.planner, seed=int(self.rng.integers(2**31 - 1)),
                       device=str(self.device))
