"""The NARUTO agent as a policy: map every frame, search goals by uncertainty, move by E-RRT.

One :meth:`NarutoPolicy.act` call is one iteration of NARUTO's loop (Feng et al., NARUTO,
CVPR 2024):

1. The observation's RGB-D frame and pose go to the mapper, which applies its own schedule
   (a keyframe and a mapping step every 5 frames); see
   :class:`~naruto_agent.naruto.agent_map.AgentMap`.
2. After a mapping step the agent's planner view (an SDF volume and an uncertainty volume on
   a 0.1 m grid over the scene's bounding box) is stale and is read again when next needed.
3. The :class:`~naruto_agent.naruto.state_machine.NarutoStateMachine` picks the next pose.
   Its planning step is :class:`~naruto_agent.naruto.goal_planning.GoalPlanner` (goal search
   and E-RRT); every move is checked first by
   :class:`~naruto_agent.naruto.move_checks.MoveChecker`.

Mappers (``mapper_kind=``; ``policy.mapper`` is the mapper object of the episode):

* ``"tsdf"`` (default): :class:`~naruto_agent.mapping.TsdfUncertaintyMapper`, TSDF fusion with
  an uncertainty derived from observation counts; fast on a CPU.
* ``"neural"``: :class:`~naruto_agent.mapping.NeuralMapper`, the published system (neural
  field, NLL-trained uncertainty grid, active ray sampling); slow on a CPU, so use it with a
  GPU (``device="auto"`` picks CUDA).
* one's own: a name registered with :func:`~naruto_agent.mapping.register_mapper`, or an
  import path ``"package.module:ClassName"`` / ``"path/to/file.py:ClassName"`` of a class
  with every member of :class:`~naruto_agent.mapping.Mapper` (``docs/mappers.md``), built
  with ``mapper_settings``.

The agent never gets stuck for good: a move the env refuses (``collided`` /
``collision_reason`` in the step info) blocks its target in the agent's own map, and when
plans keep failing it recovers (:mod:`naruto_agent.naruto.recovery`); the stall watchdog
shared with the baselines (:mod:`naruto_agent.policies.watchdog`) also cuts the plan in
progress short when the agent stays on one spot, and starts a recovery that moves. On an
open scan its open-scan guard (:class:`~naruto_agent.guards.ScanGuard`, shared with the
baselines, read with its own map by
:class:`~naruto_agent.naruto.scan_checks.NarutoScanChecks`) keeps it inside the scanned
space.

What the agent knows: the observations (RGB-D, pose, panorama), the env's step info and the
scene's bounding box from the :class:`~naruto_agent.policies.EnvContext`; never the mesh.
Every setting and the reason for its default: ``docs/agent-config.md``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
import trimesh

from naruto_agent.guards import ScanGuard
from naruto_agent.mapping import Mapper, SdfVolume
from naruto_agent.mapping.registry import mapper_factory
from naruto_agent.naruto.agent_map import AgentMap, build_mapper
from naruto_agent.naruto.config import MAPPERS, NarutoConfig, build_config
from naruto_agent.naruto.goal_planning import GoalPlanner
from naruto_agent.naruto.move_checks import MoveChecker
from naruto_agent.naruto.recovery import BlockedSpace, ProgressMonitor
from naruto_agent.naruto.scan_checks import NarutoScanChecks
from naruto_agent.naruto.state_machine import MoveCheck, NarutoStateMachine, Plan, State
from naruto_agent.naruto.view_layers import naruto_layers
from naruto_agent.planning.rotation import image_view_test
from naruto_agent.policies.base import (
    EnvContext,
    Info,
    Observation,
    OwnReconstruction,
    Policy,
    clip_pose_action,
    pose_action,
)
from naruto_agent.policies.layers import Layer
from naruto_agent.policies.registry import register_policy
from naruto_agent.policies.stall_recovery import ReachablePlaces
from naruto_agent.policies.watchdog import StallEvent, StallWatchdogConfig

#: The agent's stall watchdog: the default settings, so that no stay lasts over 30 steps. A
#: look-around that still learns (8 views alternately 20 degrees up and down take 25 steps,
#: a goal's up to 10 views longer) is cut short after ``max_stay_steps`` for the next goal;
#: a stay that learns nothing is a stall after one window.
STALL_WATCHDOG = StallWatchdogConfig()

#: The phases whose seconds ``NarutoPolicy.timings`` holds.
PHASES = ("mapping", "planner_view", "goal_search", "rrt", "control")


@register_policy("naruto")
class NarutoPolicy(Policy):
    """NARUTO: uncertainty-aware goal search + E-RRT on the agent's own map ("pose" actions).

    Args:
        mapper_kind: ``"tsdf"`` (fast, default), ``"neural"`` (the published mapper; slow on
            a CPU), another registered name, or ``"package.module:ClassName"`` /
            ``"path/to/file.py:ClassName"`` of a mapper of one's own
            (:mod:`naruto_agent.mapping.registry`); one that lacks a member of
            :class:`~naruto_agent.mapping.Mapper` is refused here (a class's methods) or at
            ``reset`` (what the built mapper holds).
        mapper_settings: keyword arguments of a mapper of one's own (the shipped ones take
            the ``tsdf`` and ``neural`` sections of ``config`` instead).
        config: full settings; ``settings`` override its fields (see
            :func:`~naruto_agent.naruto.config.build_config`).
        device: device of the mapper and the planner's nearest-neighbour search ("auto":
            CUDA when present).
        **settings: :class:`~naruto_agent.naruto.config.NarutoConfig` fields, and those of
            its ``guard`` section (:class:`~naruto_agent.guards.ScanGuardConfig`) by name.

    Attributes:
        mapper_kind: the kind of mapper each episode builds (``mapper`` is the object).
        mapper_settings: the keyword arguments of a mapper of one's own.
        config: the settings.
        machine: the state machine (``machine.history`` holds the state of every action).
        monitor: progress, failed plans and goals of the episode.
        agent_map: the episode's map and planner view (None before ``reset``).
        guard: the open-scan guard (the panorama readings, held moves, whether the scan is
            open), shared with the baselines; set up again at every ``reset``.
        scan_checks: the episode's checks of moves and goals against the scanned space
            (None before ``reset``).
        move_checker: the episode's move check (None before ``reset``).
        goal_planner: the episode's planning step (None before ``reset``).
        timings: seconds spent per phase (``mapping``, ``planner_view``, ``goal_search``,
            ``rrt``, ``control``) this episode.
    """

    action_modes = ("pose",)
    required_observations = ("rgb", "depth", "pose")

    def __init__(
        self,
        mapper_kind: str = "tsdf",
        config: NarutoConfig | None = None,
        device: str = "auto",
        mapper_settings: dict[str, Any] | None = None,
        **settings: Any,
    ) -> None:
        super().__init__()
        if "mapper" in settings:
            raise ValueError(
                f"NarutoPolicy's mapper= was renamed: pass mapper_kind={settings['mapper']!r} "
                "(policy.mapper is the mapper object)"
            )
        try:
            mapper_factory(mapper_kind)
        except ValueError as error:
            raise ValueError(f"mapper_kind: {error}") from error
        if mapper_settings and mapper_kind in MAPPERS:
            raise ValueError(f"mapper_settings are for a mapper of one's own; the {mapper_kind} "
                             f"mapper's settings are its section: pass {mapper_kind}="
                             f"{dict(mapper_settings)!r}")
        self.mapper_kind = mapper_kind
        self.mapper_settings = dict(mapper_settings or {})
        self.device = device
        self.config = build_config(config, **settings)
        self.machine = NarutoStateMachine(self.config.max_rotation_step_deg,
                                          self.config.arrival_tolerance_m)
        self.timings: dict[str, float] = dict.fromkeys(PHASES, 0.0)
        self.monitor = ProgressMonitor(self.config.recovery)
        self.agent_map: AgentMap | None = None
        self.guard = ScanGuard(self.config.guard)
        self.scan_checks: NarutoScanChecks | None = None
        self.move_checker: MoveChecker | None = None
        self.goal_planner: GoalPlanner | None = None
        self._rng = np.random.default_rng(self.config.seed)
        self._move_check: MoveCheck = self.move_is_free
        self._frame_index = 0
        self._new_map = False
        self._commanded: np.ndarray | None = None
        self._stalled = False
        # The last frame's plan was cut short by a held or refused move: this frame plans again.
        self._replanning = False
        self._way_out: Plan | None = None  # the stall recovery's plan, until planned
        self.use_stall_watchdog(STALL_WATCHDOG, enabled=self.config.stall_watchdog)

    # -- the episode's state, read-only ------------------------------------------------------
    @property
    def mapper(self) -> Mapper | None:
        """The map of the current episode (None before ``reset``)."""
        return None if self.agent_map is None else self.agent_map.mapper

    @property
    def sdf(self) -> SdfVolume | None:
        """The planner view's SDF, blocked space applied (None before it is first read)."""
        return None if self.agent_map is None else self.agent_map.sdf

    @property
    def uncertainty(self) -> SdfVolume | None:
        """The planner view's uncertainty (None before it is first read)."""
        return None if self.agent_map is None else self.agent_map.uncertainty

    @property
    def blocked(self) -> BlockedSpace | None:
        """Where the agent learned not to go (None before ``reset``)."""
        return None if self.agent_map is None else self.agent_map.blocked

    @property
    def visit_looks(self) -> np.ndarray | None:
        """Looks per planner voxel counted by reached goals (``unresolved_visit_looks``),
        None before the first."""
        return None if self.agent_map is None else self.agent_map.visit_looks

    @property
    def plans(self) -> list[dict[str, Any]]:
        """One dict of diagnostics per planning request this episode."""
        return [] if self.goal_planner is None else self.goal_planner.plans

    @property
    def recoveries(self) -> list[tuple[int, str]]:
        """(frame, kind) of every recovery this episode."""
        return [] if self.goal_planner is None else self.goal_planner.recoveries

    @property
    def scan_open(self) -> bool:
        """Whether the agent knows the scan is open (an escape refusal, or the sky)."""
        return self.guard.scan_open

    @property
    def state(self) -> State:
        """The state machine's current state."""
        return self.machine.state

    # -- episode -----------------------------------------------------------------------------
    def bind(self, context: EnvContext) -> None:
        super().bind(context)
        self.guard.agent_radius_m = context.agent_radius_m
        camera = context.camera
        self.machine.in_view = (
            image_view_test(camera.width, camera.height, camera.fx, camera.fy, camera.cx,
                            camera.cy, margin=0.1)
            if self.config.skip_views_in_image else None
        )

    def reset(self, observation: Observation, info: Info, seed: int | None = None) -> None:
        super().reset(observation, info, seed)
        self._rng = np.random.default_rng(self.config.seed if seed is None else seed)
        mapper = build_mapper(self.mapper_kind, self.context, self.config, self.device,
                              self._rng, self.mapper_settings)
        if not self.config.stay_in_scanned_space:
            mapper.observed_space.configure(support_below_m=None)
        self.machine.reset()
        self.timings = dict.fromkeys(PHASES, 0.0)
        self.monitor = ProgressMonitor(self.config.recovery)
        self.agent_map = AgentMap(mapper, self.config, self.timings)
        self.guard.reset()
        self.scan_checks = NarutoScanChecks(self.config, self.guard, self.agent_map,
                                            self._fail_current_goal_past_edge)
        self.move_checker = MoveChecker(self.config, self.agent_map, self.scan_checks)
        self.goal_planner = GoalPlanner(self.config, self.agent_map, self.scan_checks,
                                        self.move_checker, self.monitor, self._rng,
                                        self.device, self.timings)
        self._frame_index = 0
        self._new_map = False
        self._commanded = None
        self._stalled = False
        self._replanning = False
        self._way_out = None
        self._integrate(observation)

    def reachable_places(self, position: np.ndarray) -> ReachablePlaces | None:
        """The planner view's voxels the agent can reach (inside the scan), the shared stall
        recovery's choice; None when the agent is within a clearance."""
        recovery = self.goal_planner.recovery
        assert self.stall_recovery is not None
        points = recovery.reachable_points(position, self.stall_recovery.config.max_path_m)
        if points is None:
            return None
        return ReachablePlaces(points, np.linalg.norm(points - position, axis=1))

    def walk_out(self, position: np.ndarray, goal: np.ndarray) -> str | None:
        """Cut the plan in progress short for an E-RRT path to ``goal`` (a straight one where
        the planner finds none and the panorama shows the way clear; None, declined, where it
        shows it blocked), moving at once; arrived, it looks on ahead and plans."""
        plan = self.goal_planner.recovery.path_to(position, goal, "way_out")
        how = "along an E-RRT path"
        if plan is None:
            panorama = self.guard.panorama_at(position)
            if panorama is not None and self.guard.way_blocked(panorama, goal - position):
                return None
            distance = float(np.linalg.norm(goal - position))
            steps = max(1, int(np.ceil(distance / self.config.planner.step_m)))
            path = position + np.outer(np.arange(steps + 1) / steps, goal - position)
            # The panorama showed the way clear (with a margin): its moves pass unchecked.
            plan = Plan(path, goal[None], goal.copy(), {"recovery": "way_out", "trusted": True})
            how = "straight"
        plan.info["move_at_once"] = True
        plan.views = (goal + (goal - position))[None]
        self.machine.interrupt()
        self._way_out = plan
        self._stalled = True
        return how

    def no_way_out(self, event: StallEvent) -> str:
        """No reachable place past the stay: cut the plan short for the agent's own recovery
        that moves (a wander, or a retreat along its trajectory)."""
        self.machine.interrupt()
        self._stalled = True
        self.monitor.request_recovery()
        return "no way out: recovery that moves"

    def act(self, observation: Observation, info: Info | None = None) -> np.ndarray:
        if self.agent_map is None:
            raise RuntimeError("call reset() with the first observation before act()")
        self._frame_index += 1
        self._integrate(observation)
        clock = time.perf_counter()
        position = np.asarray(observation["pose"], dtype=np.float64)[:3, 3]
        self._learn_from_refusal(position, info or {})
        observed = self.agent_map.observed_space.observed_fraction
        self.monitor.record(position, observed)
        self.check_stall(observation, info, progress=observed)
        inner = ("goal_search", "rrt", "planner_view")
        before = sum(self.timings[name] for name in inner)
        new_map, self._new_map = self._new_map, False
        new_map, self._stalled = new_map or self._stalled, False
        new_map = new_map or self._replanning
        cut_before, plan_before = self.machine.collisions, self.machine.plan
        pose = self.machine.step(
            np.asarray(observation["pose"], dtype=np.float64),
            new_map=new_map,
            collided=bool((info or {}).get("collided", False)),
            plan=self._plan,
            move_is_free=self._move_check,
        )
        # A move held by the agent's checks or refused by the env taught the map where not to
        # go: the next frame plans again instead of waiting for the next mapping step.
        self._replanning = self.machine.collisions - cut_before > 0
        if self._replanning:
            # A hold that ended the step standing held the plan in hand; one followed by a
            # new plan in the same step held the one before.
            self._note_hold(position, self.machine.plan if self.machine.state == State.STAYING
                            else plan_before)
        # Control is the state machine's own work; the phases it called are timed apart.
        called = sum(self.timings[name] for name in inner) - before
        self.timings["control"] += time.perf_counter() - clock - called
        moved = np.linalg.norm(pose[:3, 3] - position) > 1e-9
        self._commanded = pose[:3, 3].copy() if moved else None
        return clip_pose_action(pose_action(pose), self.context.action_space)

    def mesh(self, voxel_size: float = 0.02) -> trimesh.Trimesh:
        """The agent's reconstruction (for ``env.unwrapped.evaluate(policy.mesh())``)."""
        if self.agent_map is None:
            raise RuntimeError("the agent has no map yet: call reset() first")
        return self.mapper.extract_mesh(voxel_size)

    def reconstruction(self) -> OwnReconstruction | None:
        """The agent's map (mesh and SDF) for the benchmark harness; None before reset()."""
        if self.agent_map is None:
            return None
        return OwnReconstruction(self.mesh(), self.mapper.sdf)

    def view_layers(self) -> list[Layer]:
        """The current goal, planned path and view targets, the goals chosen, the frontier
        and the most uncertain surfaces (:mod:`naruto_agent.naruto.view_layers`)."""
        return naruto_layers(self.machine.plan, self.plans, self.agent_map)

    # -- public seams ------------------------------------------------------------------------
    def refresh_view(self) -> None:
        """Read the planner view (:attr:`sdf`, :attr:`uncertainty`) again if a mapping step
        made it stale; the agent itself reads it only when it needs it."""
        if self.agent_map is not None:
            self.agent_map.refresh()

    def move_is_free(self, start: np.ndarray, end: np.ndarray) -> bool:
        """The agent's own check of the move from ``start`` to ``end`` before it sends it
        (:meth:`~naruto_agent.naruto.move_checks.MoveChecker.is_free`); a recovery's retreat
        or climb passes unchecked (space the agent has been in, or checked already)."""
        plan = self.machine.plan
        if plan is not None and plan.info.get("trusted"):
            return True
        if self.move_checker is None:
            raise RuntimeError("call reset() with the first observation before checking moves")
        return self.move_checker.is_free(start, end)

    def learn_refusal(self, position: np.ndarray, target: np.ndarray,
                      reason: str | None = None) -> None:
        """The env refused the move from ``position`` to ``target``: block the target in the
        agent's map and fail the current plan's goal. :meth:`act` calls it from the step
        info (``collided``, ``collision_reason``).

        Args:
            position: where the agent stands.
            target: where the refused move went.
            reason: the env's ``collision_reason``; ``"escape"`` (the move left an open
                scan) marks the scan open and blocks the space past the scan's edge, or, for
                a climb refused at the open top, everything above the agent.
        """
        if self.agent_map is None:
            raise RuntimeError("call reset() with the first observation before act()")
        past_edge = False
        if reason == "escape":
            self.guard.note_escape()
            if self.scan_checks.refused_climb(position, target):
                self.agent_map.lower_ceiling(position[2])
            else:
                self.agent_map.block_past_edge(position, target)
                past_edge = True
        else:
            self.agent_map.block(target)
        self._fail_current_goal(column=past_edge)

    def wrap_move_check(self, wrapper: Callable[[MoveCheck], MoveCheck]) -> None:
        """Wrap the move check the state machine calls, e.g. to time it.

        Args:
            wrapper: takes the check in use (``check(start, end) -> bool``) and returns the
                one to use instead; it holds across episodes.
        """
        self._move_check = wrapper(self._move_check)

    # -- the loop's parts --------------------------------------------------------------------
    def _integrate(self, observation: Observation) -> None:
        """One frame into the map and the scan guard; a mapping step makes a new map for the
        state machine (read at once unless ``lazy_planner_view``)."""
        clock = time.perf_counter()
        pose = np.asarray(observation["pose"], dtype=np.float64)
        panorama = observation.get("panorama")
        new_map = self.agent_map.integrate(observation["rgb"], observation["depth"], pose,
                                           self._frame_index, panorama)
        self.guard.observe_depth(observation["depth"], pose, self.context.camera)
        self.guard.observe_panorama(panorama, pose[:3, 3])
        self.timings["mapping"] += time.perf_counter() - clock
        if new_map:
            self._new_map = True
            if not self.config.lazy_planner_view:
                self.agent_map.refresh()

    def _note_hold(self, position: np.ndarray, held: Plan | None) -> None:
        """A move of ``held`` was held or refused at ``position``: the monitor counts the
        holds per place and per goal (a spot whose plans keep being held fails); a held
        recovery is followed by a recovery that moves at once; a held way out of a stall
        failed, and the shared recovery sends the agent to the next one."""
        if held is not None and held.info.get("recovery"):
            if held.info["recovery"] == "way_out" and self.stall_recovery is not None:
                self.stall_recovery.fail()
            else:
                self.monitor.request_recovery()  # the next step of the escalation, at once
            return
        self.monitor.move_held(position)
        if held is not None:
            self.monitor.goal_held(held.goal)

    def _learn_from_refusal(self, position: np.ndarray, info: Info) -> None:
        """The step info says the env refused the move the agent commanded last: learn it
        (:meth:`learn_refusal`); a move that arrived was not refused."""
        if self._commanded is None or not info.get("collided", False):
            return
        if np.linalg.norm(self._commanded - position) <= self.config.arrival_tolerance_m:
            return
        self.learn_refusal(position, self._commanded, info.get("collision_reason"))

    def _fail_current_goal(self, column: bool = False) -> None:
        """The current plan's goal failed (a recovery's plan has no goal to fail);
        ``column``: on the way past an open scan's edge, at any height."""
        plan = self.machine.plan
        if plan is not None and not plan.info.get("recovery"):
            self.monitor.goal_failed(plan.goal, column=column)

    def _fail_current_goal_past_edge(self) -> None:
        """The scan checks held a move over the scan's edge: the goal fails at any height."""
        self._fail_current_goal(column=True)

    def _plan(self, position: np.ndarray, rotation: np.ndarray) -> Plan | None:
        """The state machine's planning step; a plan made at once after a held or refused
        move sets off without turning first (it turns on the way): each new path would
        otherwise cost a turn in place towards it. A way out of a stall
        (:meth:`walk_out`) comes first."""
        if self._way_out is not None:
            plan, self._way_out = self._way_out, None
            return plan
        plan = self.goal_planner.plan(position, self._frame_index, rotation)
        if plan is not None and self._replanning:
            plan.info["move_at_once"] = True
        return plan
