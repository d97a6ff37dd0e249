"""The NARUTO agent's own check of a move before it sends it to the env.

A move is checked on the agent's newest map (the planner view's SDF, 2 cm samples, the
planner's clearance) and then by the
:class:`~naruto_agent.naruto.scan_checks.NarutoScanChecks` (the shared scan guard: the depth
panorama and, on an open scan, the scan's edges). A move the check refuses is a
detected collision for the state machine: the agent stays and plans again.
"""

from __future__ import annotations

import math

import numpy as np

from naruto_agent.naruto.agent_map import AgentMap
from naruto_agent.naruto.config import NarutoConfig
from naruto_agent.naruto.scan_checks import NarutoScanChecks


class MoveChecker:
    """Checks moves on the agent's map and with its scan checks.

    Args:
        config: the agent's settings (``check_moves_on_map``, the planner's clearance and
            collision sample spacing).
        agent_map: the agent's map.
        scan_checks: the agent's checks of the scanned space.
    """

    def __init__(self, config: NarutoConfig, agent_map: AgentMap,
                 scan_checks: NarutoScanChecks) -> None:
        self.config = config
        self.agent_map = agent_map
        self.scan_checks = scan_checks

    def is_free(self, start: np.ndarray, end: np.ndarray) -> bool:
        """Whether the move from ``start`` to ``end`` may be sent (always, with
        ``check_moves_on_map`` off): it does not end in a blocked ball (a refused move's
        target), keeps the clearance on the newest planner view (:meth:`keeps_clearance`)
        and passes the scan checks
        (:meth:`~naruto_agent.naruto.scan_checks.NarutoScanChecks.check_move`)."""
        if not self.config.check_moves_on_map:
            return True
        self.agent_map.refresh()
        if self.agent_map.blocked.holds(end):
            return False
        if not self.keeps_clearance(start, end):
            return False
        return self.scan_checks.check_move(start, end)

    def keeps_clearance(self, start: np.ndarray, end: np.ndarray) -> bool:
        """The move's samples (every ``collision_sample_m``, the start excluded) keep the
        planner's clearance on the planner view held.

        When a sharper map has put the agent itself within a surface's clearance, the move
        only has to get no closer to the surface than the agent already is, so that it can
        move away.
        """
        sample = self.config.planner.collision_sample_m
        count = max(1, math.ceil(float(np.linalg.norm(end - start)) / sample - 1e-9))
        fractions = np.arange(0, count + 1) / count
        values = self.agent_map.sdf.sample(start + fractions[:, None] * (end - start))
        threshold = min(self.agent_map.clearance_m, float(values[0]) - 1e-3)
        return bool(np.all(values[1:] > threshold))
