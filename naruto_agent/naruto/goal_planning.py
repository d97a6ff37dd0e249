"""The NARUTO agent's planning step: where to go next, and the path there.

One call of :meth:`GoalPlanner.plan` is the state machine's "planning" state (Feng et al.,
NARUTO, CVPR 2024): the uncertainty-aware goal search
(:func:`~naruto_agent.naruto.goal_search.uncertainty_aware_goal_search`) on the newest
planner view, then E-RRT (:func:`~naruto_agent.planning.plan_path`) to the best goal. Beyond
the published step (all switchable, see ``docs/agent-config.md``):

* the first plan of an episode is a turn in place that looks all around;
* candidate goals lie in free space connected to the agent, in measured free space, inside
  the scan, and away from goals that failed recently;
* when the best goal cannot be reached the next best are tried (``goal_attempts``);
* the path is shortcut (:func:`~naruto_agent.naruto.paths.shorten_path`);
* when the map puts the agent itself inside a surface's clearance, the path starts with a
  short straight move to the nearest free voxel (:meth:`GoalPlanner.escape`);
* a reached goal counts as a look at every target it was chosen for
  (``unresolved_visit_looks``);
* when the agent is stuck, a recovery plan (:mod:`naruto_agent.naruto.recovery_plans`), and
  a climb out of an open scan's margin when the scan checks planned one.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any

import numpy as np

from naruto_agent.naruto.agent_map import AgentMap
from naruto_agent.naruto.config import NarutoConfig
from naruto_agent.naruto.goal_search import uncertainty_aware_goal_search
from naruto_agent.naruto.move_checks import MoveChecker
from naruto_agent.naruto.paths import shorten_path
from naruto_agent.naruto.recovery import ProgressMonitor
from naruto_agent.naruto.recovery_plans import (
    RecoveryPlanner,
    look_around_plan,
    look_around_views,
)
from naruto_agent.naruto.scan_checks import NarutoScanChecks
from naruto_agent.naruto.state_machine import Plan
from naruto_agent.planning import plan_path

#: Spacing of the nodes of an escape from a surface's clearance (metres).
_ESCAPE_STEP_M = 0.1


class GoalPlanner:
    """Plans the agent's next goal and path (or a recovery) on its map.

    Args:
        config: the agent's settings.
        agent_map: the agent's map.
        scan_checks: the agent's scan checks (goals inside the scan, the margin climb).
        move_checker: the agent's move check (an escape's nodes must pass it).
        monitor: the episode's progress monitor.
        rng: the agent's randomness (the goal search, every E-RRT seed).
        device: where the E-RRT's nearest-neighbour search runs.
        timings: the dict the ``"goal_search"`` and ``"rrt"`` seconds are added to.

    Attributes:
        plans: one dict of diagnostics per planning request.
        recoveries: (frame, kind) of every recovery.
        recovery: the planner of the recovery steps.
    """

    def __init__(self, config: NarutoConfig, agent_map: AgentMap, scan_checks: NarutoScanChecks,
                 move_checker: MoveChecker, monitor: ProgressMonitor, rng: np.random.Generator,
                 device: str = "auto", timings: dict[str, float] | None = None) -> None:
        self.config = config
        self.agent_map = agent_map
        self.scan_checks = scan_checks
        self.move_checker = move_checker
        self.monitor = monitor
        self.rng = rng
        self.device = device
        self.timings = timings if timings is not None else {"goal_search": 0.0, "rrt": 0.0}
        self.plans: list[dict[str, Any]] = []
        self.recoveries: list[tuple[int, str]] = []
        self.recovery = RecoveryPlanner(config, agent_map, monitor, rng,
                                        scan_checks.inside_scan,
                                        device, self.timings)
        self._visit: tuple[np.ndarray, np.ndarray] | None = None  # (goal, targets it sees)
        self._leave: tuple[np.ndarray, float] | None = None  # (spots, radius) of leave()

    def leave(self, spots: np.ndarray, radius_m: float) -> None:
        """The next plan goes to a goal farther than ``radius_m`` from every one of ``spots``
        ((3,) or (n, 3): where the agent stayed) and moves at once, without turning towards
        its target first (a stall watchdog cut a stay there short: a goal next to it, or a
        turn in place, would only make the stay longer). Plans that find no such goal fail,
        until the recovery they lead to moves away."""
        spots = np.asarray(spots, np.float64).reshape(-1, 3).copy()
        self._leave = (spots, float(radius_m))

    def plan(self, position: np.ndarray, frame: int = 0,
             rotation: np.ndarray | None = None) -> Plan | None:
        """The next plan from ``position`` on the newest planner view.

        Args:
            position: the agent's position.
            frame: the frame's index in the episode (for the diagnostics).
            rotation: (3, 3) the camera's rotation (camera to world, OpenCV axes: z looks
                ahead), which a climb out of the scan's margin keeps; None: it looks around
                at the top.

        Returns:
            The plan, or None when no goal could be reached (the agent stays).
        """
        self.count_visit(position)
        self.agent_map.refresh()
        sdf, uncertainty = self.agent_map.sdf, self.agent_map.uncertainty
        record: dict[str, Any] = {"frame": frame, "position": position.tolist()}
        self.plans.append(record)
        if self.config.initial_look_around and len(self.plans) == 1:
            record.update(outcome="initial look-around", path_nodes=1)
            return look_around_plan(position, self.config)
        climb = self.scan_checks.take_climb(position)
        if climb is not None:
            # Checked on the panorama already; the edge test held every way from here.
            record.update(outcome="climb out of the scan's margin", path_nodes=int(len(climb)))
            self.recoveries.append((frame, "climb"))
            # It keeps facing the way it faces: a look-around up there would repeat what it
            # saw from just below, and the next plan comes right after the climb.
            views = (look_around_views(climb[-1], self.config) if rotation is None
                     else climb[-1][None] + np.asarray(rotation, np.float64)[:, 2][None])
            return Plan(climb, views, climb[-1].copy(),
                        {"recovery": "climb", "trusted": True, "move_at_once": True})
        if self.monitor.needs_recovery():
            self._leave = None  # a recovery moves away too
            return self._recover(position, record, frame)
        leave = self._leave  # kept until a plan leaves (failed plans lead to a recovery)
        prefix = position[None]
        start = position
        clearance = self.agent_map.clearance_m
        if sdf.sample(position)[0] <= clearance:
            escape = self.escape(position)
            reach = clearance + self.config.escape_radius_m
            if escape is None and self.agent_map.forget_guesses(position, reach):
                # Hemmed in by its own guesses: try again without those around it.
                sdf, uncertainty = self.agent_map.sdf, self.agent_map.uncertainty
                record["forgot_guesses"] = True
                escape = (position[None].copy() if sdf.sample(position)[0] > clearance
                          else self.escape(position))
            record["escape"] = escape is not None
            if escape is None:
                self._plan_failed(position, record, "start not free")
                return None
            prefix, start = escape, escape[-1]
        components = self.agent_map.components
        goal_mask = self.goal_mask(start)
        if leave is not None:
            points = sdf.grid_points()
            away = np.ones(len(points), bool)
            for spot in leave[0]:
                away &= np.linalg.norm(points - spot, axis=1) > leave[1]
            away = away.reshape(sdf.shape)
            goal_mask = away if goal_mask is None else goal_mask & away
            record["leaving"] = True

        clock = time.perf_counter()
        travel = (components.travel_distances(start)
                  if self.config.goal_search.discount_by_travel else None)
        search = uncertainty_aware_goal_search(
            sdf, uncertainty, start, self.rng,
            replace(self.config.goal_search, top_k=self.config.goal_attempts),
            goal_mask=goal_mask,
            planner_config=replace(self.config.planner, device=str(self.device)),
            reachable_iterations=self.config.reachable_iterations,
            travel=travel,
        )
        self.timings["goal_search"] += time.perf_counter() - clock
        record.update(
            search_ms=search.diagnostics.get("time_ms", 0.0),
            fallback=search.used_reachable_mask,
            targets=int(len(search.targets)),
            goal_scores=[round(float(s), 4) for s in search.goal_scores],
        )
        if not search.found:
            self._plan_failed(position, record, "no goal sees a target")
            return None
        clock = time.perf_counter()
        try:
            for rank, (goal, views) in enumerate(zip(search.goals, search.goal_views, strict=True)):
                planner = replace(self.config.planner, seed=int(self.rng.integers(2**31 - 1)),
                                  device=str(self.device))
                result = plan_path(sdf, start, goal, planner, components)
                if result.success:
                    path = np.vstack([prefix[:-1], shorten_path(sdf, result.path, self.config)])
                    record.update(outcome="planned", goal=goal.tolist(), rank=rank,
                                  score=float(search.goal_scores[rank]),
                                  path_nodes=int(len(path)), rrt_ms=result.time_ms)
                    self.monitor.plan_succeeded()
                    self.monitor.progress_made(position)
                    self._visit = (goal.copy(), search.goal_visible[rank])
                    if leave is not None:
                        record["move_at_once"] = True
                        self._leave = None
                    return Plan(path, views, goal.copy(), record)
                self.monitor.goal_failed(goal)
            self._plan_failed(position, record, f"no goal reachable ({result.reason})")
            return None
        finally:
            self.timings["rrt"] += time.perf_counter() - clock

    def _plan_failed(self, position: np.ndarray, record: dict[str, Any], outcome: str) -> None:
        """A plan that found no goal or no path: the monitor counts it, and the agent's own
        guesses of the scan's edge are forgotten for the next plan
        (:meth:`AgentMap.forget_guesses`)."""
        record["outcome"] = outcome
        self.monitor.plan_failed()
        if self.agent_map.forget_guesses(position):
            record["forgot_guesses"] = True

    def _recover(self, position: np.ndarray, record: dict[str, Any], frame: int) -> Plan:
        """The next recovery step (look around, wander, retreat) as a plan."""
        requested, self.monitor.requested = self.monitor.requested, False
        kind, plan = self.recovery.next_plan(position)
        if requested:
            # A stall: no turn towards the target first, and at the end one look on ahead
            # instead of a turn all around (that turn, learning little late in an episode,
            # was the next stall), then a normal plan.
            plan.info["move_at_once"] = True
            if len(plan.path) > 1:
                ahead = plan.path[-1] + (plan.path[-1] - plan.path[0])
                plan.views = ahead[None]
        self.recoveries.append((frame, kind.value))
        record.update(recovery=kind.value, outcome=f"recovery: {plan.info['recovery']}",
                      path_nodes=int(len(plan.path)))
        return plan

    def count_visit(self, position: np.ndarray) -> None:
        """The targets of the plan just finished count as looked at, if its goal was reached
        (see ``NarutoConfig.unresolved_visit_looks``); a plan is counted once."""
        visit, self._visit = self._visit, None
        if visit is None or self.config.unresolved_visit_looks <= 0:
            return
        goal, targets = visit
        if (np.linalg.norm(position - goal) > self.config.planner.step_m
                or self.agent_map.sdf is None):
            return  # stopped on the way: nothing was refuted
        self.agent_map.add_looks(targets, self.config.unresolved_visit_looks)

    def goal_mask(self, start: np.ndarray) -> np.ndarray | None:
        """The candidate goals on the planner view's grid: free space connected to
        ``start``, measured free (``goals_in_observed_space``), inside the scan
        (``stay_in_scanned_space``), away from goals that failed recently (at any height
        from those that failed past an open scan's edge); None: all."""
        sdf = self.agent_map.sdf
        components = self.agent_map.components
        labels = components.labels_near(start)
        mask = np.isin(components.labels, sorted(labels)) if labels else None
        observed = self.agent_map.observed_space
        if self.config.goals_in_observed_space:
            free = observed.sample(observed.grid.free, sdf.grid_points()).reshape(sdf.shape)
            mask = free if mask is None else mask & free
        if self.config.stay_in_scanned_space:
            inside = self.scan_checks.inside_scan(sdf.grid_points(), start).reshape(sdf.shape)
            mask = inside if mask is None else mask & inside
        failed, radii = self.monitor.recent_failed()
        if len(failed):
            points = sdf.grid_points()
            near = np.zeros(len(points), dtype=bool)
            for goal, radius in zip(failed, radii, strict=True):
                near |= np.linalg.norm(points - goal, axis=1) <= radius
            for goal, radius in zip(*self.monitor.recent_failed(columns=True), strict=True):
                near |= np.linalg.norm(points[:, :2] - goal[:2], axis=1) <= radius
            near = near.reshape(sdf.shape)
            mask = ~near if mask is None else mask & ~near
        return mask

    def escape(self, position: np.ndarray) -> np.ndarray | None:
        """Straight nodes (0.1 m apart) from ``position`` to the nearest voxel well inside
        free space (within ``escape_radius_m``) whose every node the move check accepts; None
        when there is none.

        The move check never lets the agent get deeper into a surface than it is, so a
        nearer voxel across a blocked point would be refused at every try.
        """
        sdf = self.agent_map.sdf
        radius = self.config.escape_radius_m
        if radius <= 0:
            return None
        span = math.ceil(radius / sdf.voxel_size)
        centre = np.rint(sdf.world_to_voxel(position)).astype(np.int64)
        axis = np.arange(-span, span + 1)
        block = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
        voxels = centre + block
        inside = np.all((voxels >= 0) & (voxels < np.asarray(sdf.shape)), axis=1)
        voxels = voxels[inside]
        points = sdf.voxel_to_world(voxels)
        distance = np.linalg.norm(points - position, axis=1)
        # Well inside: clearance plus one collision sample, so the planner accepts the start.
        free = (sdf.values[voxels[:, 0], voxels[:, 1], voxels[:, 2]]
                > self.agent_map.clearance_m + self.config.planner.collision_sample_m)
        candidates = np.flatnonzero(free & (distance <= radius) & (distance > 1e-9))
        keeps_clearance = self.move_checker.keeps_clearance
        # Nearest first; the first whose nodes all pass the move check.
        for index in candidates[np.lexsort((candidates, distance[candidates]))]:
            target = points[index]
            steps = max(1, math.ceil(float(np.linalg.norm(target - position)) / _ESCAPE_STEP_M
                                     - 1e-9))
            path = position + (np.arange(0, steps + 1) / steps)[:, None] * (target - position)
            if all(keeps_clearance(a, b) for a, b in zip(path[:-1], path[1:], strict=True)):
                return path
        return None
