"""The NARUTO agent's parts wired together on a hand-made map, for tests without an env."""

from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

from naruto_agent.guards import ScanGuard
from naruto_agent.mapping.observed_space import ObservedSpace
from naruto_agent.mapping.sdf_volume import SdfVolume
from naruto_agent.naruto import AgentMap, GoalPlanner, MoveChecker, NarutoConfig, NarutoScanChecks
from naruto_agent.naruto.recovery import ProgressMonitor
from naruto_agent.policies import EnvContext
from naruto_gym.sensors.pinhole import PinholeCamera

BOUNDS = np.array([[0.0, 0.0, 0.0], [3.0, 3.0, 3.0]])


def context() -> EnvContext:
    """A context of a 3 m cube (agent radius 5 cm), without an env."""
    return EnvContext(action_mode="pose", action_space=None, bounds=BOUNDS.copy(),
                      camera=PinholeCamera().scaled(0.1))


def free_sdf(value: float = 0.5) -> SdfVolume:
    """A planner view free everywhere in the 3 m cube."""
    return SdfVolume(np.full((30, 30, 30), value), np.zeros(3), 0.1)


def walls_up_to(top_m: float) -> ObservedSpace:
    """Measured space holding a wall along y = 0.05 m up to ``top_m``."""
    space = ObservedSpace(BOUNDS.copy())
    space.grid.mark_occupied(np.array([[x, 0.05, z] for x in np.arange(0.05, 3.0, 0.1)
                                       for z in np.arange(0.05, top_m, 0.1)]))
    return space


@dataclass
class Parts:
    """An agent map, scan guard, scan checks, move checker and goal planner sharing one map."""

    config: NarutoConfig
    agent_map: AgentMap
    guard: ScanGuard
    checks: NarutoScanChecks
    checker: MoveChecker
    monitor: ProgressMonitor
    planner: GoalPlanner
    failed_goals: list[int] = field(default_factory=list)


def make_parts(sdf: SdfVolume | None = None, uncertainty: SdfVolume | None = None,
               observed: ObservedSpace | None = None,
               panorama: np.ndarray | None = None, where: np.ndarray | None = None,
               config: NarutoConfig | None = None, scan_open: bool = False) -> Parts:
    """The parts on the view ``sdf`` (free everywhere by default) and ``uncertainty`` (none
    by default), kept as no mapping step runs, measuring ``observed`` (an empty grid by
    default), with ``panorama`` taken at ``where``."""
    config = config or NarutoConfig()
    mapper = SimpleNamespace(observed_space=observed or ObservedSpace(BOUNDS.copy()))
    agent_map = AgentMap(mapper, config)
    sdf = free_sdf() if sdf is None else sdf
    if uncertainty is None:
        uncertainty = SdfVolume(np.zeros(sdf.shape), sdf.origin, sdf.voxel_size)
    agent_map.use_view(sdf, uncertainty)
    failed: list[int] = []
    guard = ScanGuard(config.guard, agent_radius_m=context().agent_radius_m)
    checks = NarutoScanChecks(config, guard, agent_map, lambda: failed.append(1))
    if panorama is not None:
        guard.observe_panorama(panorama, where)
    if scan_open:
        guard.note_escape()
    checker = MoveChecker(config, agent_map, checks)
    monitor = ProgressMonitor(config.recovery)
    planner = GoalPlanner(config, agent_map, checks, checker, monitor,
                          np.random.default_rng(0), device="cpu")
    return Parts(config, agent_map, guard, checks, checker, monitor, planner, failed)
